//! The software renderer: a plant seen from the gripper camera.
//!
//! [`render_plant`] turns a [`Plant`] into primitives (round-cone berries
//! with sepals, capsule stems, masked leaflet patches, the tray box),
//! ray-casts them into a depth-tested G-buffer ([`raster`]), shades every
//! pixel with a random key light, ambient light and colour jitter
//! ([`shading`]) over a procedural foliage background, and blurs slightly
//! (soft optics). [`target_image`] then adds sensor noise and paints the
//! target berry's box white and filled ([`post`]). The scene is rendered
//! once per configuration; each target only re-does the cheap last step.

pub mod depth;
pub mod noise;
pub mod post;
pub mod primitives;
pub mod raster;
pub mod shading;

use crate::synth::camera::{bounding_box, Camera};
use crate::synth::plant::{Berry, Plant};
use crate::synth::settings::RenderSettings;
use image::RgbImage;
use nalgebra::Vector3;
use post::FloatImage;
use primitives::{PatchShape, Shape};
use rand::Rng;
use shading::{Lighting, Material, Rgb};

/// Every primitive of a plant with its material.
pub fn plant_primitives(plant: &Plant, rng: &mut impl Rng) -> (Vec<Shape>, Vec<Material>) {
    let mut shapes = Vec::new();
    let mut materials = Vec::new();
    for b in &plant.berries {
        let axis = b.axis().into_inner();
        let ref_dir = axis
            .cross(&Vector3::x())
            .try_normalize(1e-9)
            .unwrap_or_else(|| axis.cross(&Vector3::y()).normalize());
        shapes.push(Shape::RoundCone {
            a: b.top,
            b: b.tip,
            r1: b.r_top,
            r2: b.r_tip,
            ref_dir,
        });
        materials.push(Material::Berry {
            ripeness: b.ripeness,
            r_top: b.r_top,
            length: (b.tip - b.top).norm(),
        });
        for s in sepals(b, &ref_dir, rng) {
            shapes.push(s);
            materials.push(Material::Sepal);
        }
    }
    for s in &plant.stems {
        shapes.push(Shape::Capsule {
            a: s.a,
            b: s.b,
            r: s.radius,
        });
        materials.push(Material::Stem(s.kind));
    }
    for l in &plant.leaflets {
        shapes.push(Shape::Patch {
            c: l.center,
            u: l.u,
            v: l.v,
            hu: l.half_length,
            hv: l.half_width,
            shape: PatchShape::Leaflet,
        });
        materials.push(Material::Leaf(l.shade));
    }
    if let Some(t) = &plant.tray {
        shapes.push(Shape::Cuboid {
            c: t.center,
            h: t.half_extents,
        });
        materials.push(Material::Tray(t.shade));
    }
    (shapes, materials)
}

/// The calyx: pointed sepals radiating from the stem over the shoulder.
fn sepals(b: &Berry, ref_dir: &Vector3<f64>, rng: &mut impl Rng) -> Vec<Shape> {
    let axis = b.axis().into_inner();
    let side = axis.cross(ref_dir);
    let n = rng.gen_range(6..=9);
    let phase = rng.gen_range(0.0..std::f64::consts::TAU);
    (0..n)
        .map(|k| {
            let phi =
                phase + std::f64::consts::TAU * k as f64 / n as f64 + rng.gen_range(-0.15..0.15);
            let radial = ref_dir * phi.cos() + side * phi.sin();
            let droop: f64 = rng.gen_range(0.25..0.6);
            let u = radial * droop.cos() + axis * droop.sin();
            let hu = b.r_top * rng.gen_range(0.45..0.65);
            Shape::Patch {
                c: b.calyx() + u * hu - axis * 0.0005,
                u,
                v: axis.cross(&radial),
                hu,
                hv: b.r_top * rng.gen_range(0.18..0.26),
                shape: PatchShape::Sepal,
            }
        })
        .collect()
}

/// Random lighting and colour jitter for one configuration.
pub fn sample_lighting(settings: &RenderSettings, camera: &Camera, rng: &mut impl Rng) -> Lighting {
    let rot = camera.pose.rotation;
    let (right, down, forward) = (rot * Vector3::x(), rot * Vector3::y(), rot * Vector3::z());
    let key_dir = (-forward * rng.gen_range(0.3..1.0) - down * rng.gen_range(0.1..1.0)
        + right * rng.gen_range(-0.8..0.8))
    .normalize();
    let j = settings.color_jitter as f32;
    let mut jitter = || -> Rgb { [0; 3].map(|_| 1.0 + rng.gen_range(-1.0..=1.0) * j) };
    let tint = jitter();
    let materials = [jitter(), jitter(), jitter(), jitter()];
    Lighting {
        key_dir,
        key: settings.light_intensity.sample(rng) as f32,
        ambient: settings.ambient.sample(rng) as f32,
        tint: [0, 1, 2].map(|k| 1.0 + (tint[k] - 1.0) * 0.5),
        jitter: materials,
        seed: rng.gen(),
        seeds: settings.seeds,
    }
}

/// Render a plant from `camera` (no box, no sensor noise): the colour
/// image and the exact z-depth per pixel (infinite where no primitive is
/// hit; see [`depth`]).
pub fn render_plant(
    plant: &Plant,
    camera: &Camera,
    settings: &RenderSettings,
    rng: &mut impl Rng,
) -> (FloatImage, Vec<f64>) {
    let (shapes, materials) = plant_primitives(plant, rng);
    let light = sample_lighting(settings, camera, rng);
    let g = raster::rasterise(camera, &shapes);
    let rays = raster::ray_table(camera);
    let (w, h) = (g.width, g.height);
    let pixels = g
        .hits
        .iter()
        .enumerate()
        .map(|(i, hit)| match hit {
            Some((k, hit)) => shading::shade(&materials[*k], hit, &rays[i], &light),
            None => {
                shading::background((i % w) as f32 / w as f32, (i / w) as f32 / h as f32, &light)
            }
        })
        .collect();
    let img = FloatImage {
        width: w,
        height: h,
        pixels,
    };
    let z = depth::z_depth(&g, camera);
    if settings.blur {
        (img.blurred(), z)
    } else {
        (img, z)
    }
}

/// The target berry's image box `[x1, y1, x2, y2]` (px): the bounding box of
/// its projected silhouette (occlusion ignored, as a human annotator would box it).
pub fn target_box(camera: &Camera, berry: &Berry) -> Option<[f64; 4]> {
    bounding_box(camera, &berry.silhouette_points())
}

/// Box centre `[cx, cy]`.
pub fn box_center(b: &[f64; 4]) -> [f64; 2] {
    [0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])]
}

/// The network input for one target: the rendered scene with sensor noise
/// of standard deviation `noise_std` and the box painted white.
pub fn target_image(
    scene: &FloatImage,
    bbox: &[f64; 4],
    noise_std: f64,
    rng: &mut impl Rng,
) -> RgbImage {
    let mut img = scene.to_rgb8_with_noise(noise_std, rng);
    post::paint_box(&mut img, bbox);
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::plant::sample_plant;
    use crate::synth::settings::{CameraSettings, PlantSettings};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn box_contains_the_rendered_silhouette_of_the_target() {
        let cam = Camera::reference_home(&CameraSettings::default().model).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let plant = sample_plant(
            &PlantSettings::default(),
            &cam,
            4.0,
            4,
            &crate::synth::plant::Placement::at_points(),
            &mut rng,
        )
        .unwrap();
        for b in &plant.berries {
            let bx = target_box(&cam, b).unwrap();
            let only = Plant {
                berries: vec![b.clone()],
                stems: vec![],
                leaflets: vec![],
                tray: None,
                crown: plant.crown,
            };
            let (shapes, _) = plant_primitives(&only, &mut rng);
            let g = raster::rasterise(&cam, &shapes[..1]);
            let [x0, y0, x1, y1] = post::box_pixels(&bx, 640, 480);
            let mut inside = 0;
            for (i, h) in g.hits.iter().enumerate() {
                if h.is_some() {
                    let (x, y) = ((i % 640) as u32, (i / 640) as u32);
                    assert!(
                        x >= x0 && x < x1 && y >= y0 && y < y1,
                        "pixel {x},{y} outside box {bx:?}"
                    );
                    inside += 1;
                }
            }
            // The silhouette fills a good part of its box (it is tight).
            let area = ((x1 - x0) * (y1 - y0)) as f64;
            assert!(inside as f64 > 0.5 * area, "{inside} of {area}");
        }
    }
}
