//! The world the camera sees: an aligned depth image back-projected through
//! the camera that took it into a base-frame point cloud, with invalid and
//! out-of-range pixels dropped, the target berry kept out (the gripper must
//! reach it), and the rest downsampled to one point per voxel — what a
//! `points` obstacle takes.
//!
//! The cloud holds only the surfaces the camera saw: what hides behind them
//! (the far side of a leaf, a stem behind a berry) and what lies outside
//! the view is not in it.

use super::camera::Camera;
use super::depth::DepthImage;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Default voxel edge of the downsampled cloud (m).
pub const DEFAULT_VOXEL_M: f64 = 0.005;

/// Default farthest depth kept (m): beyond it a return is background for a
/// hand-mounted camera at the plant.
pub const DEFAULT_MAX_RANGE_M: f64 = 1.2;

/// How the cloud is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudSettings {
    /// Voxel edge (m): one point (the mean of its returns) per voxel.
    pub voxel_m: f64,
    /// Returns deeper than this (m, along the optical axis) are dropped.
    pub max_range_m: f64,
}

impl Default for CloudSettings {
    fn default() -> Self {
        CloudSettings {
            voxel_m: DEFAULT_VOXEL_M,
            max_range_m: DEFAULT_MAX_RANGE_M,
        }
    }
}

/// The target kept out of the cloud: the pixels of its box, and any point
/// within `radius_m` of its centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeepOut {
    /// The target box `[x1, y1, x2, y2]` (px).
    pub target_box: [f64; 4],
    /// The target's centre (m, base frame).
    pub center: [f64; 3],
    /// Radius around the centre kept clear (m).
    pub radius_m: f64,
}

/// A sensed cloud and what went into it.
#[derive(Clone, Debug, PartialEq)]
pub struct SensedCloud {
    /// One point per occupied voxel (m, base frame), in voxel order.
    pub points: Vec<[f64; 3]>,
    /// Pixels with a depth return.
    pub returns: usize,
    /// Returns dropped beyond the range.
    pub out_of_range: usize,
    /// Returns removed as the target.
    pub removed_as_target: usize,
    /// The deepest return kept (m along the optical axis; 0 when none).
    pub max_depth_m: f64,
}

/// Voxel coordinates are packed into one `u64` key, 21 bits each, offset by
/// half their range: ±2^20 voxels (±5 km at 5 mm) around the base.
const KEY_BITS: u32 = 21;
const KEY_OFFSET: i64 = 1 << (KEY_BITS - 1);

/// Rows per band: bands are read in parallel, each into its own sums, and
/// joined in band order, so the cloud does not depend on the thread count.
const BAND_ROWS: usize = 40;

/// The cloud of `depth` seen by `camera` (the pose it was taken from).
///
/// Each kept return is keyed by its voxel and added to a running sum: the
/// sum of the pixel before it in its row or of the pixel above it when that
/// is of the same voxel (at 5 mm voxels and half a metre a voxel spans
/// several pixels both ways), a new sum otherwise. Bands of
/// [`BAND_ROWS`] rows are read in parallel; their sums, joined in band
/// order, are sorted by (key, position) and each voxel's become one point
/// (the mean of its returns), added in pixel order, so the cloud is the
/// same bit for bit for the same input, whatever the thread count.
pub fn depth_cloud(
    depth: &DepthImage,
    camera: &Camera,
    settings: &CloudSettings,
    keep_out: Option<&KeepOut>,
) -> SensedCloud {
    let width = depth.width() as usize;
    let reader = BandReader::new(depth, camera, settings, keep_out);
    let bands: Vec<Band> = depth
        .units()
        .par_chunks(width.max(1) * BAND_ROWS)
        .enumerate()
        .map(|(b, rows)| reader.read(b * BAND_ROWS, rows))
        .collect();
    let mut cloud = SensedCloud {
        points: Vec::new(),
        returns: 0,
        out_of_range: 0,
        removed_as_target: 0,
        max_depth_m: 0.0,
    };
    let mut sums = Vec::with_capacity(bands.iter().map(|b| b.sums.len()).sum());
    for band in bands {
        cloud.returns += band.returns;
        cloud.out_of_range += band.out_of_range;
        cloud.removed_as_target += band.removed_as_target;
        cloud.max_depth_m = cloud.max_depth_m.max(band.max_depth_m);
        sums.extend(band.sums);
    }
    cloud.points = voxel_means(&sums);
    cloud
}

/// What one band of rows adds to the cloud.
struct Band {
    sums: Vec<VoxelSum>,
    returns: usize,
    out_of_range: usize,
    removed_as_target: usize,
    max_depth_m: f64,
}

/// Reads bands of a depth image into voxel sums.
struct BandReader<'a> {
    settings: &'a CloudSettings,
    keep_out: Option<&'a KeepOut>,
    width: usize,
    scale_m: f64,
    /// The base-frame ray through pixel (x, y) at unit depth is
    /// R·((x − cx)/fx, (y − cy)/fy, 1): a column part (here) plus a row
    /// part ([`BandReader::row_ray`]).
    column_rays: Vec<Vector3<f64>>,
    rotation: nalgebra::Matrix3<f64>,
    origin: Vector3<f64>,
    cy: f64,
    fy: f64,
}

impl<'a> BandReader<'a> {
    fn new(
        depth: &DepthImage,
        camera: &Camera,
        settings: &'a CloudSettings,
        keep_out: Option<&'a KeepOut>,
    ) -> BandReader<'a> {
        let k = &camera.intrinsics;
        let rotation = camera.pose.rotation.to_rotation_matrix().into_inner();
        BandReader {
            settings,
            keep_out,
            width: depth.width() as usize,
            scale_m: depth.scale_m(),
            column_rays: (0..depth.width())
                .map(|x| rotation.column(0) * ((f64::from(x) + 0.5 - k.cx) / k.fx))
                .collect(),
            rotation,
            origin: camera.pose.translation.vector,
            cy: k.cy,
            fy: k.fy,
        }
    }

    /// The row part of the rays of row `y`.
    fn row_ray(&self, y: usize) -> Vector3<f64> {
        self.rotation.column(1) * ((y as f64 + 0.5 - self.cy) / self.fy) + self.rotation.column(2)
    }

    /// The sums of the rows `units` (row-major), the first being row `first`.
    fn read(&self, first: usize, units: &[u16]) -> Band {
        let per_voxel = 1.0 / self.settings.voxel_m;
        let mut band = Band {
            sums: Vec::new(),
            returns: 0,
            out_of_range: 0,
            removed_as_target: 0,
            max_depth_m: 0.0,
        };
        // The sum each pixel of this row and of the row above went into.
        let (mut above, mut here) = (vec![NO_SUM; self.width], vec![NO_SUM; self.width]);
        for (r, row) in units.chunks_exact(self.width.max(1)).enumerate() {
            let v = (first + r) as f64 + 0.5;
            let row_ray = self.row_ray(first + r);
            for (x, &raw) in row.iter().enumerate() {
                if raw == 0 {
                    continue;
                }
                band.returns += 1;
                let z = f64::from(raw) * self.scale_m;
                if z > self.settings.max_range_m {
                    band.out_of_range += 1;
                    continue;
                }
                let p = (self.column_rays[x] + row_ray) * z + self.origin;
                if self
                    .keep_out
                    .is_some_and(|k| k.holds(x as f64 + 0.5, v, &p))
                {
                    band.removed_as_target += 1;
                    continue;
                }
                band.max_depth_m = band.max_depth_m.max(z);
                let key = voxel_key(&p, per_voxel);
                here[x] = merge_return(&mut band.sums, key, p, above[x]);
            }
            std::mem::swap(&mut above, &mut here);
            here.fill(NO_SUM);
        }
        band
    }
}

/// No sum (a pixel without a kept return).
const NO_SUM: u32 = u32::MAX;

/// Add the return `p` of voxel `key` to the sums, where the pixel above it
/// went into sum `above`: to the last sum (the pixel before it in its row)
/// or to `above` when that sum is of the same voxel (a voxel spans several
/// pixels both ways), to a new sum otherwise. Returns the sum's index.
#[inline]
fn merge_return(sums: &mut Vec<VoxelSum>, key: u64, p: Vector3<f64>, above: u32) -> u32 {
    let last = sums.len().wrapping_sub(1);
    if let Some(s) = sums.last_mut().filter(|s| s.key == key) {
        s.add(&p, 1);
        return last as u32;
    }
    if let Some(s) = sums.get_mut(above as usize).filter(|s| s.key == key) {
        s.add(&p, 1);
        return above;
    }
    sums.push(VoxelSum::new(key, p));
    last.wrapping_add(1) as u32
}

/// The returns of one voxel read so far: their sum and count.
#[derive(Clone, Copy, Debug)]
struct VoxelSum {
    key: u64,
    sum: Vector3<f64>,
    count: u32,
}

impl VoxelSum {
    fn new(key: u64, p: Vector3<f64>) -> VoxelSum {
        VoxelSum {
            key,
            sum: p,
            count: 1,
        }
    }

    fn add(&mut self, sum: &Vector3<f64>, count: u32) {
        self.sum += sum;
        self.count += count;
    }
}

/// The packed key of the voxel holding `p` (`per_voxel`: voxels per metre).
/// A coordinate is shifted by [`KEY_OFFSET`] voxels before truncating, so
/// truncation is the floor (within 2^-32 of a voxel at the boundaries, the
/// rounding of the shift), and cells beyond the key's range are clamped.
#[inline]
fn voxel_key(p: &Vector3<f64>, per_voxel: f64) -> u64 {
    let mask = (1i64 << KEY_BITS) - 1;
    let cell = |c: f64| ((c * per_voxel + KEY_OFFSET as f64) as i64).clamp(0, mask) as u64;
    (cell(p.x) << (2 * KEY_BITS)) | (cell(p.y) << KEY_BITS) | cell(p.z)
}

/// The mean point of each voxel: the sums sorted by (key, position), so
/// the sums of one voxel are added in pixel order, the same every time.
fn voxel_means(sums: &[VoxelSum]) -> Vec<[f64; 3]> {
    let mut order: Vec<(u64, u32)> = sums
        .iter()
        .enumerate()
        .map(|(i, s)| (s.key, i as u32))
        .collect();
    order.par_sort_unstable();
    order
        .chunk_by(|a, b| a.0 == b.0)
        .map(|run| {
            let mut total = sums[run[0].1 as usize];
            for &(_, i) in &run[1..] {
                let s = &sums[i as usize];
                total.add(&s.sum, s.count);
            }
            (total.sum / f64::from(total.count)).into()
        })
        .collect()
}

impl KeepOut {
    /// Whether the return at pixel `(u, v)`, point `p`, belongs to the target.
    fn holds(&self, u: f64, v: f64, p: &Vector3<f64>) -> bool {
        let b = &self.target_box;
        let in_box = u >= b[0] && u <= b[2] && v >= b[1] && v <= b[3];
        in_box || (p - Vector3::from(self.center)).norm() <= self.radius_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::CameraModel;
    use nalgebra::Point3;

    /// A camera at the reference home pose and a depth image of a wall
    /// `z` m along its axis (every pixel), `far` beyond it in the right half.
    fn wall(z: f64, far: f64) -> (Camera, DepthImage) {
        let model = CameraModel::default();
        let camera = Camera::reference_home(&model).unwrap();
        let k = model.intrinsics;
        let metres: Vec<f64> = (0..k.height)
            .flat_map(|_| (0..k.width).map(move |x| if x < k.width / 2 { z } else { far }))
            .collect();
        let depth = DepthImage::from_metres(k.width, k.height, 0.0005, &metres).unwrap();
        (camera, depth)
    }

    #[test]
    fn every_point_projects_back_onto_the_wall_it_came_from() {
        let (camera, depth) = wall(0.4, 2.0);
        let cloud = depth_cloud(&depth, &camera, &CloudSettings::default(), None);
        let n = (depth.width() * depth.height()) as usize;
        assert_eq!(cloud.returns, n);
        assert_eq!(cloud.out_of_range, n / 2);
        assert!(!cloud.points.is_empty());
        for p in &cloud.points {
            // Projection inverts back-projection: inside the left half of the
            // image, at the wall's depth (a voxel mean moves by < a voxel).
            let ([u, v], z) = camera.project(&Point3::from(*p)).unwrap();
            assert!((z - 0.4).abs() < DEFAULT_VOXEL_M, "depth {z}");
            assert!(
                u >= -1.0 && u <= f64::from(depth.width()) / 2.0 + 1.0,
                "u {u}"
            );
            assert!(v >= -1.0 && v <= f64::from(depth.height()) + 1.0, "v {v}");
        }
        // Downsampling: no two points share a voxel.
        let keys: std::collections::BTreeSet<[i64; 3]> = cloud
            .points
            .iter()
            .map(|p| p.map(|c| (c / DEFAULT_VOXEL_M).floor() as i64))
            .collect();
        assert!(
            keys.len() * 10 > cloud.points.len() * 9,
            "{} voxels",
            keys.len()
        );
    }

    #[test]
    fn the_target_is_kept_out_by_its_box_and_its_ball() {
        let (camera, depth) = wall(0.4, 0.4);
        let k = CameraModel::default().intrinsics;
        let (cx, cy) = (f64::from(k.width) / 2.0, f64::from(k.height) / 2.0);
        let centre = camera.back_project(cx, cy, 0.4);
        let keep_out = KeepOut {
            target_box: [cx - 20.0, cy - 20.0, cx + 20.0, cy + 20.0],
            center: centre.into(),
            radius_m: 0.03,
        };
        let all = depth_cloud(&depth, &camera, &CloudSettings::default(), None);
        let kept = depth_cloud(&depth, &camera, &CloudSettings::default(), Some(&keep_out));
        assert!(kept.removed_as_target > 41 * 41);
        assert!(kept.points.len() < all.points.len());
        for p in &kept.points {
            let ([u, v], _) = camera.project(&Point3::from(*p)).unwrap();
            let inside = u > cx - 19.0 && u < cx + 19.0 && v > cy - 19.0 && v < cy + 19.0;
            assert!(!inside, "a kept point at ({u}, {v}) is in the target box");
            let d = (Vector3::from(*p) - centre.coords).norm();
            assert!(
                d > 0.03 - DEFAULT_VOXEL_M,
                "a kept point {d} m from the target"
            );
        }
        // Same input, same cloud.
        assert_eq!(
            kept,
            depth_cloud(&depth, &camera, &CloudSettings::default(), Some(&keep_out))
        );
    }

    /// The merged sums give each voxel the plain mean of its returns: a
    /// slanted, noisy surface back-projected pixel by pixel and grouped in
    /// a map by the floor of the coordinates is the same cloud to 1e-12.
    #[test]
    fn each_point_is_the_mean_of_its_voxel_returns() {
        use rand::{Rng, SeedableRng};
        let model = CameraModel::default();
        let camera = Camera::reference_home(&model).unwrap();
        let k = model.intrinsics;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let metres: Vec<f64> = (0..k.height)
            .flat_map(|y| (0..k.width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let hole = rng.gen_bool(0.05);
                let z =
                    0.3 + 0.001 * f64::from(x) + 0.0004 * f64::from(y) + rng.gen_range(0.0..0.004);
                if hole {
                    0.0
                } else {
                    z
                }
            })
            .collect();
        let depth = DepthImage::from_metres(k.width, k.height, 0.0001, &metres).unwrap();
        let settings = CloudSettings::default();
        let cloud = depth_cloud(&depth, &camera, &settings, None);
        let mut voxels: std::collections::BTreeMap<[i64; 3], (Vector3<f64>, f64)> =
            std::collections::BTreeMap::new();
        for y in 0..depth.height() {
            for x in 0..depth.width() {
                let Some(z) = depth.metres(x, y) else {
                    continue;
                };
                if z > settings.max_range_m {
                    continue;
                }
                let p = camera
                    .back_project(f64::from(x) + 0.5, f64::from(y) + 0.5, z)
                    .coords;
                let key = [p.x, p.y, p.z].map(|c| (c / settings.voxel_m).floor() as i64);
                let e = voxels.entry(key).or_insert((Vector3::zeros(), 0.0));
                e.0 += p;
                e.1 += 1.0;
            }
        }
        assert_eq!(cloud.points.len(), voxels.len());
        // Both are in voxel order (x, then y, then z).
        for (p, (sum, n)) in cloud.points.iter().zip(voxels.values()) {
            let mean = sum / *n;
            assert!(
                (Vector3::from(*p) - mean).norm() < 1e-12,
                "{p:?} vs {mean:?}"
            );
        }
    }

    /// The bands are joined in band order: one thread or two, the same
    /// cloud bit for bit.
    #[test]
    fn the_cloud_does_not_depend_on_the_thread_count() {
        let (camera, depth) = wall(0.45, 0.9);
        let settings = CloudSettings::default();
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| depth_cloud(&depth, &camera, &settings, None))
        };
        let one = on(1);
        assert!(one.points.len() > 1000);
        assert_eq!(one, on(2));
        assert_eq!(one, on(3));
    }
}
