//! The Panda's collision primitives contain Franka's collision meshes (every
//! vertex, with the recorded margin), and the capsule fitting routine
//! contains what it fits. The mesh checks skip when `../shared` is absent.

use dpmp::robot::fit::{containment_margin, fit_capsules, surface_samples, FitOptions};
use dpmp::robot::stl::{read_binary_stl, unique_vertices};
use dpmp::robot::Robot;
use std::path::PathBuf;

/// Margin recorded in the URDF comment, less the rounding of its numbers.
const RECORDED_MARGIN_M: f64 = 0.0029;

fn mesh_dir() -> Option<PathBuf> {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let candidates = [
        std::env::var_os("DPMP_SHARED").map(PathBuf::from),
        Some(manifest.join("../shared")),
        Some(manifest.join("../../shared")),
        Some(PathBuf::from("/work/shared")),
    ];
    candidates
        .into_iter()
        .flatten()
        .map(|p| p.join("reference/franka/collision"))
        .find(|p| p.join("link0.stl").exists())
}

#[test]
fn every_mesh_vertex_is_inside_the_link_primitives() {
    let Some(dir) = mesh_dir() else {
        eprintln!(
            "skipping: Franka collision meshes (../shared/reference/franka/collision) not found"
        );
        return;
    };
    let robot = Robot::panda().unwrap();
    let meshes = (0..8)
        .map(|i| (format!("link{i}.stl"), format!("panda_link{i}")))
        .chain([("hand.stl".to_string(), "panda_hand".to_string())]);
    let mut worst_overall = f64::INFINITY;
    for (file, link_name) in meshes {
        let triangles = read_binary_stl(&dir.join(&file)).unwrap();
        let vertices = unique_vertices(&triangles);
        assert!(vertices.len() > 50, "{file}: {} vertices", vertices.len());
        let link = robot.link_index(&link_name).unwrap();
        let shapes: Vec<_> = robot
            .collision_shapes()
            .iter()
            .filter(|s| s.link == link)
            .collect();
        assert!(!shapes.is_empty(), "{link_name} has no primitives");
        let mut worst = f64::INFINITY;
        for v in &vertices {
            let depth = shapes
                .iter()
                .map(|s| -s.geometry.signed_distance(v))
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(
                depth >= RECORDED_MARGIN_M,
                "{file}: vertex {v:?} only {depth} m inside"
            );
            worst = worst.min(depth);
        }
        eprintln!(
            "{file}: {} vertices, worst margin {:.2} mm",
            vertices.len(),
            worst * 1e3
        );
        worst_overall = worst_overall.min(worst);
    }
    assert!(
        worst_overall < 0.004,
        "the fit is looser than the 3 mm it records: {worst_overall}"
    );
}

#[test]
fn refitting_link1_reproduces_a_containing_fit() {
    let Some(dir) = mesh_dir() else {
        eprintln!("skipping: Franka collision meshes not found");
        return;
    };
    let vertices = unique_vertices(&read_binary_stl(&dir.join("link1.stl")).unwrap());
    let options = FitOptions {
        initial: Some(vec![
            [[0.0, 0.0, -0.192], [0.0, 0.0, 0.0]],
            [[0.0, -0.129, 0.0], [0.0, 0.055, 0.0]],
        ]),
        restarts: 1,
        iterations: 3000,
        ..FitOptions::default()
    };
    let capsules = fit_capsules(&vertices, &options);
    assert_eq!(capsules.len(), 2);
    assert!(containment_margin(&vertices, &capsules) >= options.margin_m - 1e-12);
    // link 1 is two cylinders of radius 0.055: the fit must stay close
    for c in &capsules {
        assert!(c.radius < 0.062, "{c:?}");
    }
}

/// A closed cylinder mesh of radius `r` from z = 0 to z = `h`.
fn cylinder_mesh(r: f64, h: f64, n: usize) -> Vec<[[f64; 3]; 3]> {
    let ring = |z: f64| -> Vec<[f64; 3]> {
        (0..n)
            .map(|k| {
                let t = k as f64 / n as f64 * std::f64::consts::TAU;
                [r * t.cos(), r * t.sin(), z]
            })
            .collect()
    };
    let (bottom, top) = (ring(0.0), ring(h));
    let mut tris = Vec::new();
    for k in 0..n {
        let j = (k + 1) % n;
        tris.push([bottom[k], bottom[j], top[k]]);
        tris.push([top[k], bottom[j], top[j]]);
        tris.push([[0.0, 0.0, 0.0], bottom[j], bottom[k]]);
        tris.push([[0.0, 0.0, h], top[k], top[j]]);
    }
    tris
}

#[test]
fn fitting_a_cylinder_gives_a_tight_containing_capsule() {
    let points = surface_samples(&cylinder_mesh(0.05, 0.3, 24), 2);
    let options = FitOptions {
        capsules: 1,
        margin_m: 0.002,
        iterations: 2000,
        restarts: 2,
        ..FitOptions::default()
    };
    let capsules = fit_capsules(&points, &options);
    assert_eq!(capsules.len(), 1);
    let margin = containment_margin(&points, &capsules);
    assert!(margin >= 0.002 - 1e-12, "margin {margin}");
    // A capsule holding a flat-ended cylinder needs its axis through the
    // end faces: the radius stays near 0.05 + margin.
    assert!(capsules[0].radius < 0.0575, "{:?}", capsules[0]);
    // deterministic
    assert_eq!(capsules, fit_capsules(&points, &options));
}
