//! The 3-D position of a boxed target from an aligned depth image: the
//! berry's centre in the base frame, from the box the user drew and the
//! depth the camera measured.
//!
//! Every valid pixel inside an inner ellipse of the box (the box's own
//! shape, [`INNER_FRACTION`] of its half-sizes) is a sample of the berry's
//! front surface. Under a sphere model of radius `r` (the box's half width
//! at the sampled depth) a pixel at normalised offset `ρ` from the box
//! centre sees the surface `r·√(1 − ρ²)` in front of the centre, so each
//! sample gives an estimate of the centre's depth. A leaf in front of the
//! berry, the background behind it through a gap, and holes (no return)
//! must not move the answer: the estimate is the median of the densest
//! window of width [`window_m`] over the sorted estimates (the berry's
//! own surface is the largest consistent group), not of all of them. The
//! centre is then back-projected through the box centre
//! ([`Camera::back_project`]).

use super::camera::Camera;
use super::depth::DepthImage;
use crate::{Error, Result};

/// The inner ellipse's half-sizes as a fraction of the box's.
pub const INNER_FRACTION: f64 = 0.7;

/// Fewest valid samples for an estimate.
pub const MIN_SAMPLES: usize = 5;

/// Where the target is.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TargetEstimate {
    /// Centre of the berry (m, base frame).
    pub position: [f64; 3],
    /// Depth of the centre along the optical axis (m).
    pub depth_m: f64,
    /// Valid depth samples inside the inner ellipse.
    pub samples: usize,
    /// Samples in the densest window (the ones the estimate uses).
    pub inliers: usize,
}

/// Width (m) of the window of consistent centre estimates for a berry of
/// radius `radius_m`: half the radius, at least 4 mm.
pub fn window_m(radius_m: f64) -> f64 {
    (0.5 * radius_m).max(0.004)
}

/// The berry centre behind the box `[x1, y1, x2, y2]` (px) of `camera`'s
/// image, from `depth` (aligned with it). Errors name `field` (the depth
/// input) when the depth image does not match the camera or holds too few
/// valid samples inside the box.
pub fn locate_target(
    depth: &DepthImage,
    bbox: &[f64; 4],
    camera: &Camera,
    field: &str,
) -> Result<TargetEstimate> {
    let k = &camera.intrinsics;
    if (depth.width(), depth.height()) != (k.width, k.height) {
        return Err(Error::invalid(
            field,
            format!(
                "depth image is {}x{}, the camera's images are {}x{}",
                depth.width(),
                depth.height(),
                k.width,
                k.height
            ),
        ));
    }
    let estimates = centre_estimates(depth, bbox, k.fx);
    if estimates.len() < MIN_SAMPLES {
        return Err(Error::invalid(
            field,
            format!(
                "only {} valid depth samples inside the target box (at least {MIN_SAMPLES} needed)",
                estimates.len()
            ),
        ));
    }
    let mut sorted = estimates;
    sorted.sort_by(f64::total_cmp);
    let radius_m = 0.5 * (bbox[2] - bbox[0]) * sorted[sorted.len() / 2] / k.fx;
    let (depth_m, inliers) = densest_median(&sorted, window_m(radius_m));
    let (u, v) = (0.5 * (bbox[0] + bbox[2]), 0.5 * (bbox[1] + bbox[3]));
    let p = camera.back_project(u, v, depth_m);
    Ok(TargetEstimate {
        position: [p.x, p.y, p.z],
        depth_m,
        samples: sorted.len(),
        inliers,
    })
}

/// One centre-depth estimate per valid pixel inside the inner ellipse.
fn centre_estimates(depth: &DepthImage, bbox: &[f64; 4], fx: f64) -> Vec<f64> {
    let (uc, vc) = (0.5 * (bbox[0] + bbox[2]), 0.5 * (bbox[1] + bbox[3]));
    let (hw, hh) = (0.5 * (bbox[2] - bbox[0]), 0.5 * (bbox[3] - bbox[1]));
    if !(hw > 0.0 && hh > 0.0) {
        return Vec::new();
    }
    let (ax, ay) = (INNER_FRACTION * hw, INNER_FRACTION * hh);
    let clamp = |x: f64, hi: u32| x.clamp(0.0, hi as f64) as u32;
    let (x0, x1) = (
        clamp((uc - ax).floor(), depth.width()),
        clamp((uc + ax).ceil(), depth.width()),
    );
    let (y0, y1) = (
        clamp((vc - ay).floor(), depth.height()),
        clamp((vc + ay).ceil(), depth.height()),
    );
    let mut out = Vec::new();
    for y in y0..y1 {
        for x in x0..x1 {
            let (du, dv) = ((x as f64 + 0.5 - uc) / ax, (y as f64 + 0.5 - vc) / ay);
            let inner = du * du + dv * dv;
            if inner > 1.0 {
                continue;
            }
            if let Some(z) = depth.metres(x, y) {
                // Offset from the centre relative to the berry's radius.
                let rho2 = inner * INNER_FRACTION * INNER_FRACTION;
                let radius_m = hw * z / fx;
                out.push(z + radius_m * (1.0 - rho2).sqrt());
            }
        }
    }
    out
}

/// Median of the largest group of the sorted `values` that fits in a
/// window of `width` (ties: the nearer group), and the group's size.
fn densest_median(values: &[f64], width: f64) -> (f64, usize) {
    let mut best = (0, 0);
    let mut hi = 0;
    for lo in 0..values.len() {
        hi = hi.max(lo);
        while hi + 1 < values.len() && values[hi + 1] - values[lo] <= width {
            hi += 1;
        }
        if hi + 1 - lo > best.1 - best.0 {
            best = (lo, hi + 1);
        }
    }
    let group = &values[best.0..best.1];
    let n = group.len();
    let median = if n % 2 == 1 {
        group[n / 2]
    } else {
        0.5 * (group[n / 2 - 1] + group[n / 2])
    };
    (median, n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::CameraModel;
    use nalgebra::Point3;

    /// A berry (ball of radius `r` at `centre`) seen by `cam`, its box, and
    /// the z-depth of every pixel: the ball where a ray hits it, `behind`
    /// elsewhere; then `spoil` edits the pixels (occluders, holes).
    fn scene(
        cam: &Camera,
        centre: Point3<f64>,
        r: f64,
        behind: f64,
        spoil: impl Fn(u32, u32, &[f64; 4], f64) -> f64,
    ) -> (DepthImage, [f64; 4]) {
        let k = cam.intrinsics;
        let axis = cam.pose.rotation * nalgebra::Vector3::z();
        let c = cam.to_camera(&centre);
        let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
        let half = k.fx * r / c.z;
        let bbox = [u - half, v - half, u + half, v + half];
        let mut z = Vec::new();
        for y in 0..k.height {
            for x in 0..k.width {
                let d = cam.ray(x as f64 + 0.5, y as f64 + 0.5);
                let oc = centre - cam.position();
                let b = d.dot(&oc);
                let disc = b * b - (oc.norm_squared() - r * r);
                let depth = if disc > 0.0 {
                    (b - disc.sqrt()) * d.dot(&axis)
                } else {
                    behind
                };
                z.push(spoil(x, y, &bbox, depth));
            }
        }
        (
            DepthImage::from_metres(k.width, k.height, 0.001, &z).unwrap(),
            bbox,
        )
    }

    fn error(estimate: &TargetEstimate, centre: &Point3<f64>) -> f64 {
        (Point3::from(estimate.position) - centre).norm()
    }

    #[test]
    fn a_clean_berry_is_located_to_a_millimetre() {
        let cam = Camera::reference_home(&CameraModel::default()).unwrap();
        let centre = cam.position() + cam.ray(350.0, 210.0) * 0.45;
        let (depth, bbox) = scene(&cam, centre, 0.014, 0.9, |_, _, _, z| z);
        let t = locate_target(&depth, &bbox, &cam, "depth").unwrap();
        assert!(error(&t, &centre) < 1e-3, "{}", error(&t, &centre));
    }

    #[test]
    fn holes_a_leaf_in_front_and_the_background_do_not_move_it() {
        let cam = Camera::reference_home(&CameraModel::default()).unwrap();
        let centre = cam.position() + cam.ray(300.0, 260.0) * 0.5;
        // A leaf 4 cm in front over the left third of the box, every 5th
        // pixel without a return, the background 0.4 m behind.
        let spoil = |x: u32, y: u32, b: &[f64; 4], z: f64| {
            if (x + 3 * y).is_multiple_of(5) {
                0.0
            } else if (x as f64) < b[0] + (b[2] - b[0]) / 3.0 && (y as f64) > b[1] {
                0.46
            } else {
                z
            }
        };
        let (depth, bbox) = scene(&cam, centre, 0.015, 0.9, spoil);
        let t = locate_target(&depth, &bbox, &cam, "depth").unwrap();
        assert!(error(&t, &centre) < 1.5e-3, "{}", error(&t, &centre));
        assert!(t.inliers < t.samples);
    }

    #[test]
    fn no_valid_depth_in_the_box_is_an_error_naming_the_field() {
        let cam = Camera::reference_home(&CameraModel::default()).unwrap();
        let centre = cam.position() + cam.ray(320.0, 240.0) * 0.5;
        let (depth, bbox) = scene(&cam, centre, 0.015, 0.0, |_, _, _, _| 0.0);
        let e = locate_target(&depth, &bbox, &cam, "depth_base64").unwrap_err();
        assert!(e.to_string().contains("depth_base64"), "{e}");
        let small = DepthImage::new(4, 4, 0.001, vec![500; 16], "depth").unwrap();
        let e = locate_target(&small, &bbox, &cam, "depth_base64").unwrap_err();
        assert!(e.to_string().contains("4x4"), "{e}");
    }

    #[test]
    fn densest_window_ignores_a_nearer_occluder_and_the_background() {
        // 40 berry samples around 0.45, 25 leaf samples at 0.40, 20 background at 0.9.
        let mut v: Vec<f64> = (0..40).map(|i| 0.45 + 0.0001 * (i as f64 - 20.0)).collect();
        v.extend(std::iter::repeat_n(0.40, 25));
        v.extend(std::iter::repeat_n(0.9, 20));
        v.sort_by(f64::total_cmp);
        let (m, n) = densest_median(&v, 0.006);
        assert_eq!(n, 40);
        assert!((m - 0.45).abs() < 2e-4, "{m}");
    }
}
