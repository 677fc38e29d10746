//! The depth channel of the gripper camera: the renderer's depth buffer as a
//! z-depth image (distance along the optical axis), with a RealSense
//! D435i-like error model ([`DepthSettings`]):
//!
//! - range noise growing with the square of the distance (stereo depth:
//!   `σ(z) = rms_per_m2 · z²`, about 0.8 mm at 0.45 m by default);
//! - no return nearer than the minimum range or beyond the maximum range
//!   (the background of the plant is beyond it);
//! - dropout at depth edges (a pixel whose 4-neighbours differ from it by
//!   more than `edge_jump_m` has no return with `edge_dropout` probability:
//!   stereo matching fails at occlusion boundaries);
//! - a fraction `holes` of pixels with no return anywhere.
//!
//! With `noise: false` the image is the renderer's exact depth, quantised.

use crate::perception::camera::Camera;
use crate::perception::depth::DepthImage;
use crate::synth::render::raster::GBuffer;
use crate::synth::settings::DepthSettings;
use crate::Result;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// The exact z-depth (m) per pixel of a G-buffer (infinite: background).
pub fn z_depth(g: &GBuffer, camera: &Camera) -> Vec<f64> {
    let axis = camera.pose.rotation * nalgebra::Vector3::z();
    let rays = super::raster::ray_table(camera);
    g.hits
        .iter()
        .zip(&rays)
        .map(|(hit, ray)| hit.map_or(f64::INFINITY, |(_, h)| h.t * ray.dot(&axis)))
        .collect()
}

/// The measured depth image for an exact z-depth `exact` (row-major,
/// `width` px wide), drawn with `rng` under `settings`.
pub fn measured_depth(
    exact: &[f64],
    width: usize,
    settings: &DepthSettings,
    rng: &mut impl Rng,
) -> Result<DepthImage> {
    let height = exact.len() / width.max(1);
    let in_range = |z: f64| z >= settings.min_range_m && z <= settings.max_range_m;
    let mut out: Vec<f64> = exact
        .iter()
        .map(|&z| if in_range(z) { z } else { f64::NAN })
        .collect();
    if settings.noise {
        let jump = |i: usize, j: usize| {
            let (a, b) = (exact[i], exact[j]);
            !(a.is_finite() && b.is_finite()) || (a - b).abs() > settings.edge_jump_m
        };
        for (i, z) in out.iter_mut().enumerate() {
            let (x, y) = (i % width, i / width);
            let edge = (x > 0 && jump(i, i - 1))
                || (x + 1 < width && jump(i, i + 1))
                || (y > 0 && jump(i, i - width))
                || (y + 1 < height && jump(i, i + width));
            // Draw every random number for every pixel, so one pixel's fate
            // does not shift the stream of the next.
            let (hole, dropout) = (rng.gen::<f64>(), rng.gen::<f64>());
            let sigma = settings.rms_per_m2 * exact[i].min(settings.max_range_m).powi(2);
            let e = Normal::new(0.0, sigma.max(0.0)).map_or(0.0, |n| n.sample(rng));
            if hole < settings.holes || (edge && dropout < settings.edge_dropout) {
                *z = f64::NAN;
            } else {
                *z += e;
            }
        }
    }
    DepthImage::from_metres(width as u32, height as u32, settings.scale_m, &out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::CameraModel;
    use crate::synth::render::primitives::Shape;
    use crate::synth::render::raster::rasterise;
    use rand::SeedableRng;

    fn camera() -> Camera {
        Camera::reference_home(&CameraModel::default()).unwrap()
    }

    #[test]
    fn z_depth_of_a_ball_is_the_analytic_ray_sphere_depth() {
        let cam = camera();
        let centre = cam.position() + cam.ray(300.0, 250.0) * 0.45;
        let r = 0.02;
        let g = rasterise(
            &cam,
            &[Shape::Capsule {
                a: centre,
                b: centre,
                r,
            }],
        );
        let z = z_depth(&g, &cam);
        let axis = cam.pose.rotation * nalgebra::Vector3::z();
        let mut hit = 0;
        for (i, z) in z.iter().enumerate() {
            let (u, v) = ((i % 640) as f64 + 0.5, (i / 640) as f64 + 0.5);
            let d = cam.ray(u, v);
            let oc = centre - cam.position();
            let b = d.dot(&oc);
            let disc = b * b - (oc.norm_squared() - r * r);
            if disc > 1e-12 {
                hit += 1;
                let analytic = (b - disc.sqrt()) * d.dot(&axis);
                assert!((z - analytic).abs() < 1e-9, "pixel {i}: {z} vs {analytic}");
            } else if disc < -1e-9 {
                assert!(z.is_infinite());
            }
        }
        assert!(hit > 1000);
    }

    #[test]
    fn without_noise_the_image_is_the_exact_depth_quantised() {
        let exact: Vec<f64> = (0..400).map(|i| 0.05 + 0.004 * i as f64).collect();
        let s = DepthSettings {
            noise: false,
            ..Default::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let d = measured_depth(&exact, 20, &s, &mut rng).unwrap();
        for (i, z) in exact.iter().enumerate() {
            let m = d.metres((i % 20) as u32, (i / 20) as u32);
            if *z < s.min_range_m || *z > s.max_range_m {
                assert_eq!(m, None);
            } else {
                assert!((m.unwrap() - z).abs() <= 0.5e-3 + 1e-12);
            }
        }
    }

    #[test]
    fn noise_holes_and_edge_dropout_follow_the_model() {
        let (w, h) = (200, 200);
        // A wall at 0.5 m with a 5 cm step down the middle column.
        let exact: Vec<f64> = (0..w * h)
            .map(|i| if i % w < w / 2 { 0.5 } else { 0.55 })
            .collect();
        let s = DepthSettings::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let d = measured_depth(&exact, w, &s, &mut rng).unwrap();
        let (mut errors, mut holes, mut edge, mut edge_dropped) = (Vec::new(), 0, 0, 0);
        for y in 0..h {
            for x in 0..w {
                let m = d.metres(x as u32, y as u32);
                if x == w / 2 - 1 || x == w / 2 {
                    edge += 1;
                    edge_dropped += m.is_none() as usize;
                } else if x < w / 2 - 1 {
                    match m {
                        Some(m) => errors.push(m - 0.5),
                        None => holes += 1,
                    }
                }
            }
        }
        let n = errors.len() as f64;
        let std = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        // σ = 0.004 · 0.5² = 1 mm, plus the 1 mm quantisation (σ ≈ 0.29 mm).
        let expected = (1e-3f64.powi(2) + 1e-6 / 12.0).sqrt();
        assert!(
            (std - expected).abs() < 0.08 * expected,
            "{std} vs {expected}"
        );
        let hole_rate = holes as f64 / (n + holes as f64);
        assert!((hole_rate - s.holes).abs() < 0.01, "{hole_rate}");
        let drop_rate = edge_dropped as f64 / edge as f64;
        let expected_drop = s.holes + (1.0 - s.holes) * s.edge_dropout;
        assert!((drop_rate - expected_drop).abs() < 0.08, "{drop_rate}");
    }
}
