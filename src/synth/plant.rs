//! The plant sampler: one random strawberry plant configuration.
//!
//! A table-top plant: a crown in a tray (gutter) above the berries, trusses
//! (peduncles) arching over the tray's front edge down to branch nodes, one
//! stem per berry from a node to the berry's calyx, and trifoliate leaves on
//! petioles (a canopy above the crown and a backdrop behind the berries).
//!
//! A berry is a *round cone*: the convex hull of a shoulder sphere (centre
//! `top`, radius `r_top`) and a smaller tip sphere (centre `tip`, radius
//! `r_tip`) below it, which is the strawberry silhouette. Its collision
//! obstacle is the capsule `top`-`tip` of radius `r_top`, which contains it.
//! Berry centres lie in the configured region, pairwise `spacing_m` apart,
//! and every berry's image box lies inside the gripper camera's image.

use crate::synth::camera::{bounding_box, Camera};
use crate::synth::settings::PlantSettings;
use crate::{Error, Result};
use nalgebra::{Point3, Unit, Vector3};
use rand::Rng;
use std::f64::consts::PI;

/// Ripeness, which sets the berry colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Ripeness {
    /// Red.
    Ripe,
    /// Green to white; the value in [0, 1] moves from green (0) to white (1).
    Unripe(f64),
}

/// One strawberry.
#[derive(Clone, Debug)]
pub struct Berry {
    /// Obstacle id (`berry-<i>`).
    pub id: String,
    /// Centroid-like centre (the target position).
    pub center: Point3<f64>,
    /// Shoulder sphere centre.
    pub top: Point3<f64>,
    /// Tip sphere centre.
    pub tip: Point3<f64>,
    /// Shoulder radius (m).
    pub r_top: f64,
    /// Tip radius (m).
    pub r_tip: f64,
    /// Colour class.
    pub ripeness: Ripeness,
}

impl Berry {
    /// Unit axis from shoulder to tip (roughly down).
    pub fn axis(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(self.tip - self.top)
    }

    /// Where the stem meets the berry (top of the shoulder sphere).
    pub fn calyx(&self) -> Point3<f64> {
        self.top - self.axis().into_inner() * self.r_top
    }

    /// Points on the berry's surface dense enough that their projected
    /// bounding box contains the projected silhouette to within a tiny
    /// fraction of a pixel (both spheres' great circles and the cone between).
    pub fn silhouette_points(&self) -> Vec<Point3<f64>> {
        let mut pts = sphere_points(&self.top, self.r_top, 24, 48);
        pts.extend(sphere_points(&self.tip, self.r_tip, 12, 24));
        pts
    }
}

fn sphere_points(c: &Point3<f64>, r: f64, n_lat: usize, n_lon: usize) -> Vec<Point3<f64>> {
    let mut pts = Vec::with_capacity((n_lat + 1) * n_lon);
    for i in 0..=n_lat {
        let theta = PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let phi = 2.0 * PI * j as f64 / n_lon as f64;
            pts.push(
                c + Vector3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                ) * r,
            );
        }
    }
    pts
}

/// What a capsule is, for shading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StemKind {
    /// Berry stem (pedicel).
    Stem,
    /// Truss (peduncle).
    Peduncle,
    /// Leaf stalk.
    Petiole,
}

/// A stem segment.
#[derive(Clone, Debug)]
pub struct StemSegment {
    /// Obstacle id.
    pub id: String,
    /// One end.
    pub a: Point3<f64>,
    /// Other end.
    pub b: Point3<f64>,
    /// Radius (m).
    pub radius: f64,
    /// What it is.
    pub kind: StemKind,
}

/// One leaflet: a flat serrated ellipse.
#[derive(Clone, Debug)]
pub struct Leaflet {
    /// Obstacle id.
    pub id: String,
    /// Centre of the ellipse.
    pub center: Point3<f64>,
    /// Unit direction of the leaflet's length (midrib).
    pub u: Vector3<f64>,
    /// Unit direction of its width (in the leaf plane).
    pub v: Vector3<f64>,
    /// Half length (m).
    pub half_length: f64,
    /// Half width (m).
    pub half_width: f64,
    /// Shade of green in [0, 1] (0 dark, 1 light).
    pub shade: f64,
}

/// Thickness given to leaflet obstacles (m).
pub const LEAF_THICKNESS_M: f64 = 0.002;

impl Leaflet {
    /// Unit normal of the leaf plane.
    pub fn normal(&self) -> Vector3<f64> {
        self.u.cross(&self.v)
    }

    /// Rim points of the ellipse (`n` of them), both faces of the slab.
    pub fn hull_points(&self, n: usize) -> Vec<Point3<f64>> {
        let nrm = self.normal() * (0.5 * LEAF_THICKNESS_M);
        let mut pts = Vec::with_capacity(2 * n);
        for k in 0..n {
            let t = 2.0 * PI * k as f64 / n as f64;
            let p = self.center
                + self.u * (self.half_length * t.cos())
                + self.v * (self.half_width * t.sin());
            pts.push(p + nrm);
            pts.push(p - nrm);
        }
        pts
    }
}

/// The tray (table top) under the plant: an axis-aligned box.
#[derive(Clone, Debug)]
pub struct Tray {
    /// Centre.
    pub center: Point3<f64>,
    /// Half extents.
    pub half_extents: Vector3<f64>,
    /// Brightness of its surface in [0, 1].
    pub shade: f64,
}

/// One plant configuration.
#[derive(Clone, Debug)]
pub struct Plant {
    /// Berries; index = berry number in the dataset.
    pub berries: Vec<Berry>,
    /// Stems, peduncles and petioles.
    pub stems: Vec<StemSegment>,
    /// Leaflets.
    pub leaflets: Vec<Leaflet>,
    /// Optional tray.
    pub tray: Option<Tray>,
    /// The crown (where stems and petioles start).
    pub crown: Point3<f64>,
}

/// How a point drawn in the plant region becomes a berry centre: pushed
/// `push_m` further along the ray from `origin` (the home TCP), so that the
/// drawn point is the pre-grasp point of a berry approached from home.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Ray origin (the home TCP).
    pub origin: Point3<f64>,
    /// Push distance (m, >= 0); 0 places berries at the drawn points.
    pub push_m: f64,
}

impl Placement {
    /// Berries at the drawn points.
    pub fn at_points() -> Placement {
        Placement {
            origin: Point3::origin(),
            push_m: 0.0,
        }
    }

    /// The berry centre for a drawn point `p` (`p` itself when it
    /// coincides with the origin).
    pub fn berry_center(&self, p: &Point3<f64>) -> Point3<f64> {
        match Unit::try_new(p - self.origin, 1e-9) {
            Some(dir) if self.push_m > 0.0 => p + dir.into_inner() * self.push_m,
            _ => *p,
        }
    }
}

/// Draw one plant with `n_berries` berries, every one visible to `camera`;
/// berry centres are the region draws moved by `placement`.
pub fn sample_plant(
    settings: &PlantSettings,
    camera: &Camera,
    border_px: f64,
    n_berries: usize,
    placement: &Placement,
    rng: &mut impl Rng,
) -> Result<Plant> {
    let berries = sample_berries(settings, camera, border_px, n_berries, placement, rng)?;
    let crown = sample_crown(&berries, rng);
    let tray =
        (rng.gen::<f64>() < settings.tray_probability).then(|| sample_tray(&berries, &crown, rng));
    let mut stems = sample_trusses(settings, &berries, &crown, rng);
    let (petioles, leaflets) = sample_leaves(settings, &berries, &crown, rng);
    stems.extend(petioles);
    Ok(Plant {
        berries,
        stems,
        leaflets,
        tray,
        crown,
    })
}

fn sample_berries(
    settings: &PlantSettings,
    camera: &Camera,
    border_px: f64,
    n: usize,
    placement: &Placement,
    rng: &mut impl Rng,
) -> Result<Vec<Berry>> {
    let mut berries: Vec<Berry> = Vec::with_capacity(n);
    let mut tries = 0;
    while berries.len() < n {
        tries += 1;
        if tries > settings.max_berry_tries * n {
            return Err(Error::Infeasible(format!(
                "could not place {n} berries pairwise {:.3}..{:.3} m apart inside plant.region and the camera view \
                 after {} draws (placed {}); widen plant.region or plant.spacing_m, or lower berries_per_config",
                settings.spacing_m.lo,
                settings.spacing_m.hi,
                tries - 1,
                berries.len()
            )));
        }
        let b = sample_berry(settings, berries.len(), placement, rng);
        if spacing_ok(settings, &berries, &b) && berry_visible(camera, &b, border_px) {
            berries.push(b);
        }
    }
    Ok(berries)
}

fn sample_berry(
    settings: &PlantSettings,
    index: usize,
    placement: &Placement,
    rng: &mut impl Rng,
) -> Berry {
    let r = &settings.region;
    let drawn = Point3::from([0, 1, 2].map(|i| {
        if r.max[i] > r.min[i] {
            rng.gen_range(r.min[i]..=r.max[i])
        } else {
            r.min[i]
        }
    }));
    let center = placement.berry_center(&drawn);
    let r_top = settings.berry_radius_m.sample(rng);
    let h = rng.gen_range(1.0..=1.25) * r_top;
    let r_tip = rng.gen_range(0.38..=0.5) * r_top;
    let tilt: f64 = rng.gen_range(0.0..0.35);
    let azimuth: f64 = rng.gen_range(0.0..2.0 * PI);
    let axis = Vector3::new(
        tilt.sin() * azimuth.cos(),
        tilt.sin() * azimuth.sin(),
        -tilt.cos(),
    );
    let top = center - axis * (0.35 * h);
    let ripeness = if rng.gen::<f64>() < settings.unripe_fraction {
        Ripeness::Unripe(rng.gen())
    } else {
        Ripeness::Ripe
    };
    Berry {
        id: format!("berry-{index}"),
        center,
        top,
        tip: top + axis * h,
        r_top,
        r_tip,
        ripeness,
    }
}

fn spacing_ok(settings: &PlantSettings, berries: &[Berry], b: &Berry) -> bool {
    berries.iter().all(|o| {
        let d = (o.center - b.center).norm();
        d >= settings.spacing_m.lo && d <= settings.spacing_m.hi
    })
}

/// Whether the berry's image box lies inside the image with `border_px` to spare.
pub fn berry_visible(camera: &Camera, b: &Berry, border_px: f64) -> bool {
    bounding_box(camera, &b.silhouette_points()).is_some_and(|bx| camera.box_inside(&bx, border_px))
}

fn mean_point(points: impl Iterator<Item = Point3<f64>>) -> Point3<f64> {
    let (sum, n) = points.fold((Vector3::zeros(), 0.0f64), |(s, n), p| {
        (s + p.coords, n + 1.0)
    });
    Point3::from(sum / n.max(1.0))
}

fn max_coord(berries: &[Berry], i: usize) -> f64 {
    berries
        .iter()
        .map(|b| b.center[i])
        .fold(f64::NEG_INFINITY, f64::max)
}

fn sample_crown(berries: &[Berry], rng: &mut impl Rng) -> Point3<f64> {
    let m = mean_point(berries.iter().map(|b| b.center));
    let top_z = berries
        .iter()
        .map(|b| b.calyx().z)
        .fold(f64::NEG_INFINITY, f64::max);
    Point3::new(
        max_coord(berries, 0) + rng.gen_range(0.07..0.11),
        m.y + rng.gen_range(-0.03..0.03),
        top_z + rng.gen_range(0.07..0.12),
    )
}

/// A table (tray) top below the berries, seen from above by the camera at
/// home: its top lies 3..7 cm under the lowest berry tip, it starts just in
/// front of the berries and runs past the crown; light plastic or wood.
fn sample_tray(berries: &[Berry], crown: &Point3<f64>, rng: &mut impl Rng) -> Tray {
    let lowest = berries
        .iter()
        .map(|b| b.tip.z - b.r_tip)
        .fold(f64::INFINITY, f64::min);
    let nearest = berries
        .iter()
        .map(|b| b.center.x)
        .fold(f64::INFINITY, f64::min);
    let top = lowest - rng.gen_range(0.03..0.07);
    let hz = rng.gen_range(0.015..0.03);
    let front = nearest - rng.gen_range(0.0..0.03);
    let back = crown.x + rng.gen_range(0.08..0.2);
    Tray {
        center: Point3::new(
            0.5 * (front + back),
            crown.y + rng.gen_range(-0.1..0.1),
            top - hz,
        ),
        half_extents: Vector3::new(0.5 * (back - front), rng.gen_range(0.35..0.6), hz),
        shade: rng.gen_range(0.55..0.9),
    }
}

/// Trusses: crown -> arch over the tray edge -> node; stems node -> calyx.
fn sample_trusses(
    settings: &PlantSettings,
    berries: &[Berry],
    crown: &Point3<f64>,
    rng: &mut impl Rng,
) -> Vec<StemSegment> {
    let mut order: Vec<usize> = (0..berries.len()).collect();
    order.sort_by(|&a, &b| berries[a].center.y.total_cmp(&berries[b].center.y));
    let n_trusses = if berries.len() >= 4 { 2 } else { 1 };
    let front = max_coord(berries, 0) + 0.03;
    let mut segs = Vec::new();
    for (t, group) in order.chunks(berries.len().div_ceil(n_trusses)).enumerate() {
        let calyx_mean = mean_point(group.iter().map(|&i| berries[i].calyx()));
        let top_z = group
            .iter()
            .map(|&i| berries[i].calyx().z)
            .fold(f64::NEG_INFINITY, f64::max);
        let node = Point3::new(
            calyx_mean.x + rng.gen_range(0.01..0.03),
            calyx_mean.y + rng.gen_range(-0.01..0.01),
            top_z + rng.gen_range(0.025..0.05),
        );
        let arch = Point3::new(
            front.min(crown.x - 0.02),
            0.5 * (crown.y + node.y),
            crown.z + rng.gen_range(0.0..0.02),
        );
        let r = settings.stem_radius_m.hi * 1.3;
        segs.push(stem(
            format!("peduncle-{t}a"),
            *crown,
            arch,
            r,
            StemKind::Peduncle,
        ));
        segs.push(stem(
            format!("peduncle-{t}b"),
            arch,
            node,
            r,
            StemKind::Peduncle,
        ));
        for &i in group {
            let calyx = berries[i].calyx();
            let bend = Point3::from((node.coords + calyx.coords) * 0.5)
                + Vector3::new(
                    rng.gen_range(-0.004..0.004),
                    rng.gen_range(-0.006..0.006),
                    rng.gen_range(0.0..0.008),
                );
            let r = settings.stem_radius_m.sample(rng);
            segs.push(stem(format!("stem-{i}a"), node, bend, r, StemKind::Stem));
            segs.push(stem(format!("stem-{i}b"), bend, calyx, r, StemKind::Stem));
        }
    }
    segs
}

fn stem(id: String, a: Point3<f64>, b: Point3<f64>, radius: f64, kind: StemKind) -> StemSegment {
    StemSegment {
        id,
        a,
        b,
        radius,
        kind,
    }
}

/// Trifoliate leaves: canopy leaves rise from the crown, backdrop leaves
/// hang behind the berries facing the camera.
fn sample_leaves(
    settings: &PlantSettings,
    berries: &[Berry],
    crown: &Point3<f64>,
    rng: &mut impl Rng,
) -> (Vec<StemSegment>, Vec<Leaflet>) {
    let n = settings.leaves.sample(rng).round() as usize;
    let mean = mean_point(berries.iter().map(|b| b.center));
    let back_x = max_coord(berries, 0);
    let mut petioles = Vec::new();
    let mut leaflets = Vec::new();
    for k in 0..n {
        let backdrop = k % 2 == 1;
        let end = if backdrop {
            Point3::new(
                back_x + rng.gen_range(0.06..0.12),
                mean.y + rng.gen_range(-0.15..0.15),
                mean.z + rng.gen_range(-0.06..0.08),
            )
        } else {
            let az: f64 = rng.gen_range(-0.8 * PI..0.8 * PI) * 0.5;
            let el: f64 = rng.gen_range(0.3..1.0);
            let len = rng.gen_range(0.10..0.18);
            crown
                + Vector3::new(
                    az.cos() * el.cos() * 0.6 + 0.3,
                    az.sin() * el.cos(),
                    el.sin(),
                ) * len
        };
        let r = settings.stem_radius_m.hi;
        petioles.push(stem(
            format!("petiole-{k}"),
            *crown,
            end,
            r,
            StemKind::Petiole,
        ));
        // Leaf plane: canopy leaves roughly horizontal, backdrop leaves face -x.
        let normal = if backdrop {
            Vector3::new(-1.0, rng.gen_range(-0.4..0.4), rng.gen_range(-0.3..0.5)).normalize()
        } else {
            Vector3::new(rng.gen_range(-0.5..0.2), rng.gen_range(-0.4..0.4), 1.0).normalize()
        };
        let stalk = (end - crown).normalize();
        let main = (stalk - normal * stalk.dot(&normal))
            .try_normalize(1e-9)
            .unwrap_or_else(|| normal.cross(&Vector3::y()).normalize());
        let main = if backdrop && main.z > 0.0 && rng.gen_bool(0.5) {
            -main
        } else {
            main
        };
        let side = normal.cross(&main);
        let length = settings.leaflet_length_m.sample(rng);
        let shade = rng.gen_range(0.2..0.8);
        for (j, ang) in [0.0f64, 0.9, -0.9].into_iter().enumerate() {
            let ang = ang + rng.gen_range(-0.15..0.15);
            let u = main * ang.cos() + side * ang.sin();
            let half_length = 0.5
                * length
                * if j == 0 {
                    1.0
                } else {
                    rng.gen_range(0.8..0.95)
                };
            leaflets.push(Leaflet {
                id: format!("leaf-{k}-{j}"),
                center: end + u * (half_length + 0.004),
                u,
                v: normal.cross(&u),
                half_length,
                half_width: half_length * rng.gen_range(0.6..0.75),
                shade: (shade + rng.gen_range(-0.1f64..0.1)).clamp(0.0, 1.0),
            });
        }
    }
    (petioles, leaflets)
}

/// Pairwise distances between berry centres.
pub fn pairwise_distances(centers: &[[f64; 3]]) -> Vec<f64> {
    let mut d = Vec::new();
    for i in 0..centers.len() {
        for j in i + 1..centers.len() {
            d.push(
                (0..3)
                    .map(|k| (centers[i][k] - centers[j][k]).powi(2))
                    .sum::<f64>()
                    .sqrt(),
            );
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::settings::{berry_extent, CameraSettings};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn plant(seed: u64, n: usize) -> Plant {
        let cam = Camera::reference_home(&CameraSettings::default().model).unwrap();
        sample_plant(
            &PlantSettings::default(),
            &cam,
            4.0,
            n,
            &Placement::at_points(),
            &mut ChaCha8Rng::seed_from_u64(seed),
        )
        .unwrap()
    }

    #[test]
    fn berries_respect_region_spacing_and_view() {
        let s = PlantSettings::default();
        let cam = Camera::reference_home(&CameraSettings::default().model).unwrap();
        for seed in 0..20 {
            let p = plant(seed, 5);
            assert_eq!(p.berries.len(), 5);
            let centers: Vec<[f64; 3]> = p.berries.iter().map(|b| b.center.coords.into()).collect();
            assert!(centers.iter().all(|c| s.region.contains(c)));
            for d in pairwise_distances(&centers) {
                assert!(
                    (s.spacing_m.lo..=s.spacing_m.hi).contains(&d),
                    "spacing {d}"
                );
            }
            assert!(p.berries.iter().all(|b| berry_visible(&cam, b, 4.0)));
        }
    }

    #[test]
    fn berry_extent_bounds_the_round_cone() {
        for seed in 0..10 {
            for b in plant(seed, 4).berries {
                let ext = berry_extent(b.r_top);
                for q in b.silhouette_points() {
                    assert!((q - b.center).norm() <= ext + 1e-9);
                }
            }
        }
    }

    #[test]
    fn every_berry_has_a_stem_reaching_its_calyx() {
        let p = plant(3, 6);
        for (i, b) in p.berries.iter().enumerate() {
            let s = p
                .stems
                .iter()
                .find(|s| s.id == format!("stem-{i}b"))
                .unwrap();
            assert!((s.b - b.calyx()).norm() < 1e-12);
        }
        assert!(p
            .leaflets
            .iter()
            .all(|l| (l.normal().norm() - 1.0).abs() < 1e-9 && l.u.dot(&l.v).abs() < 1e-9));
    }

    #[test]
    fn placement_pushes_along_the_ray_from_the_origin() {
        let p = Placement {
            origin: Point3::new(0.38, -0.06, 0.71),
            push_m: 0.1,
        };
        let drawn = Point3::new(0.66, 0.1, 0.8);
        let b = p.berry_center(&drawn);
        assert!(((b - drawn).norm() - 0.1).abs() < 1e-12);
        let (u, v) = ((drawn - p.origin).normalize(), (b - p.origin).normalize());
        assert!((u - v).norm() < 1e-12);
        assert_eq!(Placement::at_points().berry_center(&drawn), drawn);
    }

    #[test]
    fn impossible_packing_is_a_clear_error() {
        let mut s = PlantSettings::default();
        s.region.max = s.region.min;
        s.max_berry_tries = 5;
        let cam = Camera::reference_home(&CameraSettings::default().model).unwrap();
        let e = sample_plant(
            &s,
            &cam,
            4.0,
            3,
            &Placement::at_points(),
            &mut ChaCha8Rng::seed_from_u64(1),
        )
        .unwrap_err();
        assert!(e.to_string().contains("could not place 3 berries"));
    }

    #[test]
    fn same_seed_same_plant() {
        let a = plant(11, 5);
        let b = plant(11, 5);
        for (x, y) in a.berries.iter().zip(&b.berries) {
            assert_eq!(x.center, y.center);
        }
        assert_eq!(a.leaflets.len(), b.leaflets.len());
    }
}
