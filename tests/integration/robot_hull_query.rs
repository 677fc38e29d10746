//! The hull-versus-segment query behind every mesh-link clearance: the local
//! walk with its separating-axis certificate answers exactly what the full
//! scan of every face answers, and both equal the brute-force minimum over
//! the hull's triangles, on the shipped Panda's hulls (also rigidly moved).

use crate::common::robot::{mesh_hulls, panda};
use dpmp::robot::hull::ConvexHull;
use dpmp::robot::hull_query::segment_triangle_distance;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn panda_hulls() -> Vec<ConvexHull> {
    mesh_hulls(&panda()).into_iter().map(|(_, h)| h).collect()
}

/// Exact distance from a segment outside the hull: the minimum over every
/// triangle (no pruning, no walk).
fn brute_force(hull: &ConvexHull, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let v = hull.vertices();
    hull.faces()
        .iter()
        .map(|f| {
            let [p, q, r] = f.map(|i| Vector3::from(v[i as usize]));
            segment_triangle_distance(a, b, &p, &q, &r)
        })
        .fold(f64::INFINITY, f64::min)
}

/// A random segment near the hull (some of them points, some overlapping).
fn segment_near(hull: &ConvexHull, rng: &mut ChaCha8Rng) -> (Vector3<f64>, Vector3<f64>) {
    let (ca, cb, r) = hull.bound();
    let (ca, cb) = (Vector3::from(ca), Vector3::from(cb));
    let around = ca + (cb - ca) * rng.gen_range(0.0..1.0);
    let spread = r + 0.12;
    let a = around + Vector3::from_fn(|_, _| rng.gen_range(-spread..spread));
    let b = if rng.gen_bool(0.3) {
        a
    } else {
        a + Vector3::from_fn(|_, _| rng.gen_range(-0.08..0.08))
    };
    (a, b)
}

#[test]
fn the_local_query_equals_the_full_scan_and_the_triangle_minimum() {
    let mut rng = ChaCha8Rng::seed_from_u64(19);
    let (mut separated, mut overlapping, mut beyond) = (0, 0, 0);
    for hull in panda_hulls() {
        for _ in 0..1500 {
            let (a, b) = segment_near(&hull, &mut rng);
            let limit = if rng.gen_bool(0.3) {
                f64::INFINITY
            } else {
                rng.gen_range(0.001..0.1)
            };
            let local = hull.segment_contact_within(&a, &b, limit);
            let scan = hull.segment_contact_scan(&a, &b, limit);
            match (&local, &scan) {
                (None, None) => {
                    beyond += 1;
                    assert!(brute_force(&hull, &a, &b) >= limit - 1e-12);
                }
                (Some(l), Some(s)) => {
                    assert!(
                        (l.distance - s.distance).abs() <= 1e-12,
                        "{a:?}-{b:?}: local {} scan {}",
                        l.distance,
                        s.distance
                    );
                    assert!(l.distance < limit);
                    if l.distance > 0.0 {
                        separated += 1;
                        let exact = brute_force(&hull, &a, &b);
                        assert!(
                            (l.distance - exact).abs() <= 1e-12,
                            "{} vs {exact}",
                            l.distance
                        );
                        let gap = (l.point_segment - l.point_hull).norm();
                        assert!((gap - l.distance).abs() <= 1e-12);
                        // The normal points from the segment towards the hull.
                        let along = (l.point_hull - l.point_segment).dot(&l.normal);
                        assert!((along - l.distance).abs() <= 1e-12);
                    } else {
                        overlapping += 1;
                    }
                }
                _ => panic!("{a:?}-{b:?} limit {limit}: local {local:?} scan {scan:?}"),
            }
        }
    }
    // The sample covers every case.
    assert!(separated > 2000 && overlapping > 100 && beyond > 1000);
}

#[test]
fn a_moved_hull_answers_the_moved_query() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for hull in panda_hulls() {
        let pose = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 0.5),
            UnitQuaternion::from_euler_angles(0.4, -1.1, 2.0),
        );
        let moved = hull.transformed(&pose);
        for _ in 0..300 {
            let (a, b) = segment_near(&hull, &mut rng);
            let (ma, mb) = (
                (pose * Point3::from(a)).coords,
                (pose * Point3::from(b)).coords,
            );
            let here = hull.segment_contact(&a, &b).distance;
            let there = moved.segment_contact(&ma, &mb).distance;
            assert!((here - there).abs() <= 1e-9, "{here} vs {there}");
        }
    }
}

#[test]
fn non_finite_segments_are_never_clear() {
    let hull = &panda_hulls()[0];
    let nan = Vector3::new(f64::NAN, 0.0, 0.0);
    let far = Vector3::new(f64::INFINITY, 0.0, 0.0);
    assert_eq!(hull.segment_contact(&nan, &nan).distance, f64::NEG_INFINITY);
    let c = hull.segment_contact_within(&far, &Vector3::zeros(), 0.1);
    assert_eq!(c.map(|c| c.distance), Some(f64::NEG_INFINITY));
}

/// The cheap bounds the clearance queries prune with, on the Panda's
/// hulls: the k-DOP's gap of a segment never exceeds its exact distance to
/// the hull's triangles, and for a point (a cloud's ball) is a median of
/// under 2 mm short of it, never 2.5 cm (where the bounding capsule is off
/// by up to 8 cm); the plane through a
/// separated answer's witness supports the hull (every vertex behind it),
/// so it bounds every other segment's distance too.
#[test]
fn the_slab_gap_and_the_witness_plane_never_exceed_the_distance() {
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let mut slacks: Vec<f64> = Vec::new();
    for hull in panda_hulls() {
        let slabs = hull.slabs();
        let mut planes: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new();
        for _ in 0..1000 {
            let (a, b) = segment_near(&hull, &mut rng);
            let exact = brute_force(&hull, &a, &b);
            let gap = slabs.segment_gap(&a, &b);
            if hull.plane_distance(&a.into()) > 0.0 && hull.plane_distance(&b.into()) > 0.0 {
                assert!(gap <= exact + 1e-12, "slab gap {gap} > distance {exact}");
                if exact < 0.05 && a == b {
                    slacks.push(exact - gap);
                }
                let Some(c) = hull.segment_contact_within(&a, &b, f64::INFINITY) else {
                    continue;
                };
                if c.distance > 0.0 {
                    planes.push((-c.normal, c.point_hull));
                }
                for (u, p) in &planes {
                    let bound = u.dot(&a).min(u.dot(&b)) - u.dot(p);
                    assert!(bound <= exact + 1e-7, "plane bound {bound} > {exact}");
                }
            }
        }
        for v in hull.vertices() {
            for (u, p) in &planes {
                let beyond = u.dot(&(Vector3::from(*v) - p));
                assert!(
                    beyond <= 1e-7,
                    "a vertex {beyond} m beyond a plane (normal {})",
                    u.norm()
                );
            }
        }
    }
    slacks.sort_by(f64::total_cmp);
    let (median, worst) = (slacks[slacks.len() / 2], slacks[slacks.len() - 1]);
    println!(
        "slab gap short of the distance over {} points within 5 cm: median {median} m, worst {worst} m",
        slacks.len()
    );
    assert!(slacks.len() > 200, "{} points within 5 cm", slacks.len());
    assert!(
        median < 0.002 && worst < 0.025,
        "median {median}, worst {worst}"
    );
}
