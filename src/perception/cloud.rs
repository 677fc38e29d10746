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
    /// One point per occupied voxel (m, base frame), voxels in the order
    /// the image first meets them (rows top to bottom).
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
/// order, are gathered by voxel and each voxel's become one point (the mean
/// of its returns), added in pixel order, so the cloud is the same bit for
/// bit for the same input, whatever the thread count.
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
    let mut max_unit = 0;
    for band in bands {
        cloud.returns += band.returns;
        cloud.out_of_range += band.out_of_range;
        cloud.removed_as_target += band.removed_as_target;
        max_unit = max_unit.max(band.max_unit);
        sums.extend(band.sums);
    }
    cloud.max_depth_m = f64::from(max_unit) * depth.scale_m();
    cloud.points = voxel_means(&sums, settings.voxel_m);
    cloud
}

/// What one band of rows adds to the cloud.
struct Band {
    /// Sums in voxel units (`p / voxel_m`).
    sums: Vec<VoxelSum>,
    returns: usize,
    out_of_range: usize,
    removed_as_target: usize,
    /// The deepest raw unit kept.
    max_unit: u16,
}

/// Reads bands of a depth image into voxel sums. Points are computed in
/// voxel units straight from the raw depth units (one multiply-add per
/// axis, no metres in between), so a point's voxel is its truncation.
struct BandReader<'a> {
    keep_out: Option<&'a KeepOut>,
    width: usize,
    voxel_m: f64,
    /// Deepest raw unit within the range (deeper returns are dropped).
    max_unit: u16,
    /// The base-frame ray through pixel (x, y) per raw depth unit, in voxel
    /// units, is R·((x − cx)/fx, (y − cy)/fy, 1)·scale/voxel: a column part
    /// (here) plus a row part ([`BandReader::row_ray`]).
    column_rays: Vec<Vector3<f64>>,
    /// R's second and third columns, scaled as the rays are.
    row_axis: Vector3<f64>,
    optical_axis: Vector3<f64>,
    /// The camera's position in voxel units.
    origin: Vector3<f64>,
    cy: f64,
    fy: f64,
}

impl<'a> BandReader<'a> {
    fn new(
        depth: &DepthImage,
        camera: &Camera,
        settings: &CloudSettings,
        keep_out: Option<&'a KeepOut>,
    ) -> BandReader<'a> {
        let k = &camera.intrinsics;
        let rotation = camera.pose.rotation.to_rotation_matrix().into_inner();
        let per_unit = depth.scale_m() / settings.voxel_m;
        BandReader {
            keep_out,
            width: depth.width() as usize,
            voxel_m: settings.voxel_m,
            max_unit: deepest_unit_within(depth.scale_m(), settings.max_range_m),
            column_rays: (0..depth.width())
                .map(|x| rotation.column(0) * ((f64::from(x) + 0.5 - k.cx) / k.fx * per_unit))
                .collect(),
            row_axis: rotation.column(1) * per_unit,
            optical_axis: rotation.column(2) * per_unit,
            origin: camera.pose.translation.vector / settings.voxel_m,
            cy: k.cy,
            fy: k.fy,
        }
    }

    /// The row part of the rays of row `y`.
    fn row_ray(&self, y: usize) -> Vector3<f64> {
        self.row_axis * ((y as f64 + 0.5 - self.cy) / self.fy) + self.optical_axis
    }

    /// The sums of the rows `units` (row-major), the first being row `first`.
    fn read(&self, first: usize, units: &[u16]) -> Band {
        let mut band = Band {
            sums: Vec::new(),
            returns: 0,
            out_of_range: 0,
            removed_as_target: 0,
            max_unit: 0,
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
                if raw > self.max_unit {
                    band.out_of_range += 1;
                    continue;
                }
                let p = (self.column_rays[x] + row_ray) * f64::from(raw) + self.origin;
                if self
                    .keep_out
                    .is_some_and(|k| k.holds(x as f64 + 0.5, v, &(p * self.voxel_m)))
                {
                    band.removed_as_target += 1;
                    continue;
                }
                band.max_unit = band.max_unit.max(raw);
                here[x] = merge_return(&mut band.sums, voxel_key(&p), p, above[x]);
            }
            std::mem::swap(&mut above, &mut here);
            here.fill(NO_SUM);
        }
        band
    }
}

/// The deepest raw unit whose depth (`unit × scale_m`) is within
/// `max_range_m` (0: none is).
fn deepest_unit_within(scale_m: f64, max_range_m: f64) -> u16 {
    let within = |u: u32| f64::from(u) * scale_m <= max_range_m;
    let top = u32::from(u16::MAX);
    let mut unit = (max_range_m / scale_m).clamp(0.0, f64::from(top)) as u32;
    while unit < top && within(unit + 1) {
        unit += 1;
    }
    while unit > 0 && !within(unit) {
        unit -= 1;
    }
    unit as u16
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

/// The packed key of the voxel holding `p` (in voxel units). A coordinate
/// is shifted by [`KEY_OFFSET`] voxels before truncating, so truncation is
/// the floor (within 2^-32 of a voxel at the boundaries, the rounding of the
/// shift), and cells beyond the key's range are clamped.
#[inline]
fn voxel_key(p: &Vector3<f64>) -> u64 {
    // Clamped as a float, so the cast needs no saturation of its own.
    let top = ((1u64 << KEY_BITS) - 1) as f64;
    let cell = |c: f64| (c + KEY_OFFSET as f64).clamp(0.0, top) as i64 as u64;
    (cell(p.x) << (2 * KEY_BITS)) | (cell(p.y) << KEY_BITS) | cell(p.z)
}

/// The mean point of each voxel, voxels in the order they are first met
/// (bands top to bottom, pixels in row order): the sums are gathered by key
/// in an open-addressing table and each voxel's are added in pixel order,
/// so the cloud is the same bit for bit every time. The sums are in voxel
/// units; the means are in metres.
fn voxel_means(sums: &[VoxelSum], voxel_m: f64) -> Vec<[f64; 3]> {
    let slots_bits = (2 * sums.len())
        .max(16)
        .next_power_of_two()
        .trailing_zeros();
    let mask = (1usize << slots_bits) - 1;
    let mut slots = vec![NO_SUM; mask + 1];
    let mut voxels: Vec<VoxelSum> = Vec::with_capacity(sums.len());
    for s in sums {
        let mut slot = key_slot(s.key, slots_bits);
        loop {
            match slots[slot] {
                NO_SUM => {
                    slots[slot] = voxels.len() as u32;
                    voxels.push(*s);
                    break;
                }
                v if voxels[v as usize].key == s.key => {
                    voxels[v as usize].add(&s.sum, s.count);
                    break;
                }
                _ => slot = (slot + 1) & mask,
            }
        }
    }
    voxels
        .iter()
        .map(|v| (v.sum * (voxel_m / f64::from(v.count))).into())
        .collect()
}

/// The table slot a voxel key hashes to (Fibonacci hashing: the top `bits`
/// bits of the key times 2^64 / φ).
#[inline]
fn key_slot(key: u64, bits: u32) -> usize {
    (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize
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
        // Each point is its voxel's mean (a mean lies in its voxel).
        let mut seen = std::collections::BTreeSet::new();
        for p in &cloud.points {
            let key = p.map(|c| (c / settings.voxel_m).floor() as i64);
            let (sum, n) = voxels[&key];
            let mean = sum / n;
            assert!(
                (Vector3::from(*p) - mean).norm() < 1e-12,
                "{p:?} vs {mean:?}"
            );
            assert!(seen.insert(key), "voxel {key:?} twice");
        }
    }

    /// The range cut on raw units keeps exactly the returns whose depth in
    /// metres is within the range.
    #[test]
    fn the_deepest_unit_kept_is_the_last_within_the_range() {
        for (scale, range) in [
            (0.001, 1.2),
            (0.0005, 1.2),
            (0.0001, 0.3),
            (1e-4, 0.7),
            (0.00025, 100.0),
            (0.001, 0.0005),
        ] {
            let unit = deepest_unit_within(scale, range);
            let within = |u: u16| f64::from(u) * scale <= range;
            assert!(unit == 0 || within(unit), "{scale} {range}: {unit}");
            assert!(
                unit == u16::MAX || !within(unit + 1),
                "{scale} {range}: {unit}"
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
