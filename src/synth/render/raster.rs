//! Visibility: every primitive is ray-cast over the screen rectangle that
//! bounds its projection, keeping per pixel the nearest hit (a depth buffer).

use crate::synth::camera::{Camera, NEAR_M};
use crate::synth::render::primitives::{Hit, Shape};
use nalgebra::{Point3, Vector3};

/// The nearest primitive and hit per pixel (row-major).
pub struct GBuffer {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Per pixel: index of the nearest primitive and its hit.
    pub hits: Vec<Option<(usize, Hit)>>,
}

impl GBuffer {
    /// Depth (distance along the ray) at pixel `(x, y)`, infinite for background.
    pub fn depth(&self, x: usize, y: usize) -> f64 {
        self.hits[y * self.width + x].map_or(f64::INFINITY, |(_, h)| h.t)
    }
}

/// Pixel rectangle `[x0, x1) x [y0, y1)` that contains the projection of a
/// sphere (the whole image when the sphere crosses the near plane).
pub fn screen_rect(camera: &Camera, center: &Point3<f64>, radius: f64) -> Option<[usize; 4]> {
    let k = &camera.intrinsics;
    let (w, h) = (k.width as f64, k.height as f64);
    let c = camera.to_camera(center);
    if c.z + radius < NEAR_M {
        return None;
    }
    if c.z - radius < NEAR_M {
        return Some([0, 0, k.width as usize, k.height as usize]);
    }
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for z in [c.z - radius, c.z + radius] {
        for dx in [-radius, radius] {
            for dy in [-radius, radius] {
                let (u, v) = (k.fx * (c.x + dx) / z + k.cx, k.fy * (c.y + dy) / z + k.cy);
                u0 = u0.min(u);
                u1 = u1.max(u);
                v0 = v0.min(v);
                v1 = v1.max(v);
            }
        }
    }
    let clamp = |x: f64, hi: f64| x.clamp(0.0, hi) as usize;
    let r = [
        clamp(u0.floor(), w),
        clamp(v0.floor(), h),
        clamp(u1.ceil() + 1.0, w),
        clamp(v1.ceil() + 1.0, h),
    ];
    (r[0] < r[2] && r[1] < r[3]).then_some(r)
}

/// Ray-cast every shape into a depth-tested G-buffer.
pub fn rasterise(camera: &Camera, shapes: &[Shape]) -> GBuffer {
    let (width, height) = (
        camera.intrinsics.width as usize,
        camera.intrinsics.height as usize,
    );
    let mut hits: Vec<Option<(usize, Hit)>> = vec![None; width * height];
    let rays = ray_table(camera);
    let origin = camera.position();
    for (index, shape) in shapes.iter().enumerate() {
        let (c, r) = shape.bounding_sphere();
        let Some([x0, y0, x1, y1]) = screen_rect(camera, &c, r) else {
            continue;
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let px = y * width + x;
                if let Some(hit) = shape.intersect(&origin, &rays[px]) {
                    if hits[px].is_none_or(|(_, h)| hit.t < h.t) {
                        hits[px] = Some((index, hit));
                    }
                }
            }
        }
    }
    GBuffer {
        width,
        height,
        hits,
    }
}

/// Unit ray through every pixel centre.
pub fn ray_table(camera: &Camera) -> Vec<Vector3<f64>> {
    let (w, h) = (
        camera.intrinsics.width as usize,
        camera.intrinsics.height as usize,
    );
    (0..w * h)
        .map(|i| camera.ray((i % w) as f64 + 0.5, (i / w) as f64 + 0.5))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::settings::CameraSettings;

    #[test]
    fn nearer_shape_wins_and_rect_covers_projection() {
        let cam = Camera::reference_home(&CameraSettings::default().model).unwrap();
        let ahead = |d: f64| cam.position() + cam.ray(320.0, 240.0) * d;
        let near = Shape::Capsule {
            a: ahead(0.3),
            b: ahead(0.3) + Vector3::z() * 0.01,
            r: 0.01,
        };
        let far = Shape::Capsule {
            a: ahead(0.5),
            b: ahead(0.5) + Vector3::z() * 0.01,
            r: 0.05,
        };
        let g = rasterise(&cam, &[far.clone(), near.clone()]);
        let centre = g.hits[240 * 640 + 320].unwrap();
        assert_eq!(centre.0, 1);
        assert!((centre.1.t - 0.29).abs() < 0.002);
        // Every pixel hit by the far capsule lies inside its screen rectangle.
        let (c, r) = far.bounding_sphere();
        let rect = screen_rect(&cam, &c, r).unwrap();
        let alone = rasterise(&cam, &[far]);
        for (i, h) in alone.hits.iter().enumerate() {
            if h.is_some() {
                let (x, y) = (i % 640, i / 640);
                assert!(x >= rect[0] && x < rect[2] && y >= rect[1] && y < rect[3]);
            }
        }
        assert!(g.depth(0, 0).is_infinite());
    }
}
