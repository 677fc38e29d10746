//! Mesh URDFs end to end: a franka_description-style URDF (package://
//! names, ROS package layout) loads, measures and plans exactly like the
//! shipped Panda; binary STL, ASCII STL, OBJ and `scale` give the same
//! geometry; bad meshes are errors naming the URDF element and the file.

use crate::common::scene::sphere;
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::optimize;
use dpmp::robot::mesh::{MeshFormat, TriangleMesh};
use dpmp::robot::{Robot, PANDA_HOME, PANDA_MESHES, PANDA_URDF};
use dpmp::scene::Scene;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

/// `root/franka_description/{urdf/panda.urdf, meshes/collision/*.stl}` with
/// the URDF naming its meshes `package://franka_description/...`.
fn ros_package(root: &Path, urdf: &str) -> PathBuf {
    let pkg = root.join("franka_description");
    std::fs::create_dir_all(pkg.join("urdf")).unwrap();
    std::fs::create_dir_all(pkg.join("meshes/collision")).unwrap();
    for (name, bytes) in PANDA_MESHES {
        std::fs::write(pkg.join(name), bytes).unwrap();
    }
    let path = pkg.join("urdf/panda.urdf");
    std::fs::write(&path, urdf).unwrap();
    let limits = pkg
        .join("urdf")
        .join(dpmp::robot::limits_file::LIMITS_FILE_NAME);
    std::fs::write(limits, dpmp::robot::limits_file::PANDA_JOINT_LIMITS).unwrap();
    path
}

fn packaged_urdf() -> String {
    PANDA_URDF.replace(
        "filename=\"meshes/collision/",
        "filename=\"package://franka_description/meshes/collision/",
    )
}

fn load(path: &Path) -> Result<Robot, String> {
    Robot::from_urdf_file(path, "panda_link0", "panda_tcp").map_err(|e| e.to_string())
}

fn cluster() -> Scene {
    let robot = Robot::panda().unwrap();
    let tcp = robot.tcp_pose(&PANDA_HOME).translation.vector;
    Scene::new(
        (0..12)
            .map(|i| {
                let t = i as f64;
                let center = [
                    tcp.x + 0.05 + 0.02 * (t * 1.7).sin(),
                    tcp.y - 0.1 + 0.018 * t,
                    tcp.z - 0.05 + 0.03 * (t * 0.9).cos(),
                ];
                sphere(&format!("b{i}"), center, 0.015)
            })
            .collect(),
    )
    .unwrap()
}

/// Largest difference of the clearance to `scene` between two robots over
/// random configurations.
fn clearance_difference(a: &Robot, b: &Robot, scene: &Scene) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    (0..50)
        .map(|_| {
            let q: Vec<f64> = a
                .limits()
                .iter()
                .map(|l| rng.gen_range(l.lower..=l.upper))
                .collect();
            let da = scene.min_clearance(a, &a.fk(&q)).unwrap().distance;
            let db = scene.min_clearance(b, &b.fk(&q)).unwrap().distance;
            (da - db).abs()
        })
        .fold(0.0, f64::max)
}

#[test]
fn a_franka_description_style_urdf_loads_measures_and_plans_like_the_shipped_panda() {
    let dir = tempfile::tempdir().unwrap();
    let robot = load(&ros_package(dir.path(), &packaged_urdf()))
        .unwrap()
        .with_home(&PANDA_HOME)
        .unwrap();
    let panda = Robot::panda().unwrap();
    assert_eq!(robot.collision_shapes(), panda.collision_shapes());
    assert!(robot.warnings().is_empty(), "{:?}", robot.warnings());
    assert_eq!(clearance_difference(&robot, &panda, &cluster()), 0.0);
    let req = typical_request(&panda, 0, &ExampleSettings::default()).unwrap();
    let a = optimize(&req, &robot).unwrap();
    let b = optimize(&req, &panda).unwrap();
    assert_eq!(a.deterministic_json(), b.deterministic_json());
}

fn write_ascii_stl(mesh: &TriangleMesh) -> String {
    let mut out = String::from("solid hand\n");
    for t in &mesh.triangles {
        out.push_str(" facet normal 0 0 0\n  outer loop\n");
        for v in t {
            out.push_str(&format!("   vertex {:?} {:?} {:?}\n", v[0], v[1], v[2]));
        }
        out.push_str("  endloop\n endfacet\n");
    }
    out + "endsolid hand\n"
}

fn write_obj(mesh: &TriangleMesh, factor: f64) -> String {
    let mut out = String::new();
    for t in &mesh.triangles {
        for v in t {
            out.push_str(&format!(
                "v {:?} {:?} {:?}\n",
                v[0] * factor,
                v[1] * factor,
                v[2] * factor
            ));
        }
    }
    for k in 0..mesh.triangles.len() {
        out.push_str(&format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3));
    }
    out
}

fn hand_mesh() -> TriangleMesh {
    let bytes = PANDA_MESHES
        .iter()
        .find(|(n, _)| n.ends_with("hand.stl"))
        .unwrap()
        .1;
    TriangleMesh::parse(bytes, MeshFormat::Stl, [1.0; 3]).unwrap()
}

/// The packaged Panda with the hand's mesh element replaced by `element`
/// and `extra` written beside the meshes.
fn variant(root: &Path, element: &str, extra: &[(&str, Vec<u8>)]) -> Result<Robot, String> {
    let urdf = packaged_urdf().replace(
        r#"<geometry><mesh filename="package://franka_description/meshes/collision/hand.stl"/></geometry>"#,
        element,
    );
    let path = ros_package(root, &urdf);
    for (name, bytes) in extra {
        std::fs::write(path.parent().unwrap().join(name), bytes).unwrap();
    }
    load(&path)
}

#[test]
fn ascii_stl_obj_and_scale_give_the_same_geometry() {
    let panda = Robot::panda().unwrap();
    let scene = cluster();
    let mesh = hand_mesh();
    let dir = tempfile::tempdir().unwrap();
    let ascii = variant(
        dir.path(),
        r#"<geometry><mesh filename="hand_ascii.stl"/></geometry>"#,
        &[("hand_ascii.stl", write_ascii_stl(&mesh).into_bytes())],
    )
    .unwrap();
    assert_eq!(ascii.collision_shapes(), panda.collision_shapes());
    let obj = variant(
        dir.path(),
        r#"<geometry><mesh filename="hand.obj"/></geometry>"#,
        &[("hand.obj", write_obj(&mesh, 1.0).into_bytes())],
    )
    .unwrap();
    assert_eq!(obj.collision_shapes(), panda.collision_shapes());
    let millimetres = variant(
        dir.path(),
        r#"<geometry><mesh filename="hand_mm.obj" scale="0.001 0.001 0.001"/></geometry>"#,
        &[("hand_mm.obj", write_obj(&mesh, 1000.0).into_bytes())],
    )
    .unwrap();
    assert!(clearance_difference(&millimetres, &panda, &scene) < 1e-9);
    // A mesh and a primitive on one link: both are kept.
    let mixed = variant(
        dir.path(),
        r#"<geometry><mesh filename="package://franka_description/meshes/collision/hand.stl"/></geometry>
        </collision><collision><origin xyz="0 0 0.2"/><geometry><sphere radius="0.01"/></geometry>"#,
        &[],
    )
    .unwrap();
    assert_eq!(
        mixed.collision_shapes().len(),
        panda.collision_shapes().len() + 1
    );
}

#[test]
fn bad_meshes_are_errors_naming_the_element_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let element = |file: &str, scale: &str| {
        format!(r#"<geometry><mesh filename="{file}"{scale}/></geometry>"#)
    };
    let expect = |robot: Result<Robot, String>, words: &[&str]| {
        let e = robot.expect_err("an error");
        assert!(
            e.contains("urdf.link[panda_hand].collision[0].geometry.mesh"),
            "{e}"
        );
        for w in words {
            assert!(e.contains(w), "'{w}' not in: {e}");
        }
    };
    expect(
        variant(dir.path(), &element("none.stl", ""), &[]),
        &["none.stl", "not found"],
    );
    let mut truncated = PANDA_MESHES[8].1.to_vec();
    truncated.truncate(1000);
    expect(
        variant(
            dir.path(),
            &element("cut.stl", ""),
            &[("cut.stl", truncated)],
        ),
        &["cut.stl", "must be"],
    );
    let mut empty = vec![0u8; 80];
    empty.extend(0u32.to_le_bytes());
    expect(
        variant(
            dir.path(),
            &element("empty.stl", ""),
            &[("empty.stl", empty)],
        ),
        &["empty.stl", "no triangles"],
    );
    let nan = "v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n";
    expect(
        variant(
            dir.path(),
            &element("nan.obj", ""),
            &[("nan.obj", nan.into())],
        ),
        &["nan.obj", "non-finite"],
    );
    expect(
        variant(
            dir.path(),
            &element(
                "package://franka_description/meshes/collision/hand.stl",
                r#" scale="1 0 1""#,
            ),
            &[],
        ),
        &["hand.stl", "scale"],
    );
    let flat = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
    expect(
        variant(
            dir.path(),
            &element("flat.obj", ""),
            &[("flat.obj", flat.into())],
        ),
        &["flat.obj", "flat"],
    );
    expect(
        variant(
            dir.path(),
            &element("hand.dae", ""),
            &[("hand.dae", b"<COLLADA/>".to_vec())],
        ),
        &["hand.dae", ".stl and .obj"],
    );
    // Not closed: allowed, with a warning naming the element.
    let open = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 2 3 4\n";
    let robot = variant(
        dir.path(),
        &element("open.obj", ""),
        &[("open.obj", open.into())],
    )
    .unwrap();
    assert!(
        robot
            .warnings()
            .iter()
            .any(|w| w.contains("urdf.link[panda_hand].collision[0]") && w.contains("not closed")),
        "{:?}",
        robot.warnings()
    );
    // URDF text without a file cannot resolve meshes.
    let e = Robot::from_urdf_str(PANDA_URDF, "panda_link0", "panda_tcp").unwrap_err();
    assert!(e.to_string().contains("as text"), "{e}");
}
