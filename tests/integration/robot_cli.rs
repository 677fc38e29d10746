//! `dpmp robot fk | clearance | ik | shapes` through the real binary.

const HOME: &str = "0.0348,-1.0102,-0.1525,-2.5334,-0.1583,2.8798,0.0543";

fn dpmp(args: &[&str]) -> (i32, serde_json::Value, String) {
    let out = crate::common::cli::dpmp(args);
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let json = serde_json::from_str(&stdout).unwrap_or(serde_json::Value::Null);
    (
        out.status.code().unwrap_or(-1),
        json,
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

#[test]
fn fk_prints_every_link_frame() {
    let (code, json, err) = dpmp(&["robot", "fk", "--q", HOME]);
    assert_eq!(code, 0, "{err}");
    let frames = json["frames"].as_object().unwrap();
    assert_eq!(frames.len(), 11);
    let tcp = &frames["panda_tcp"]["position"];
    let expect = [0.380, -0.062, 0.708];
    for i in 0..3 {
        assert!(
            (tcp[i].as_f64().unwrap() - expect[i]).abs() < 1.5e-3,
            "{tcp}"
        );
    }
    let q = frames["panda_link8"]["quaternion"].as_array().unwrap();
    let norm: f64 = q.iter().map(|v| v.as_f64().unwrap().powi(2)).sum();
    assert!((norm - 1.0).abs() < 1e-12);
}

#[test]
fn clearance_reports_the_closest_obstacle() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.json");
    std::fs::write(
        &scene,
        r#"{"obstacles": [
            {"id": "berry-1", "type": "sphere", "center": [0.5, -0.06, 0.68], "radius": 0.015},
            {"id": "far", "type": "box", "center": [-1.0, 0.0, 0.0], "half_extents": [0.1, 0.1, 0.1]}
        ]}"#,
    )
    .unwrap();
    let path = scene.to_str().unwrap();
    let (code, json, err) = dpmp(&[
        "robot",
        "clearance",
        "--q",
        HOME,
        "--scene",
        path,
        "--activation",
        "0.5",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json["obstacle"], "berry-1");
    let d = json["min_clearance_m"].as_f64().unwrap();
    assert!(d > 0.0 && d < 0.2, "{d}");
    assert_eq!(json["gradient"].as_array().unwrap().len(), 7);
    assert!(json["within"]
        .as_array()
        .unwrap()
        .iter()
        .all(|c| c["obstacle_id"] == "berry-1"));

    std::fs::write(
        &scene,
        r#"{"obstacles": [{"id": "b", "type": "sphere", "center": [0, 0, 0], "radius": -1}]}"#,
    )
    .unwrap();
    let (code, _, err) = dpmp(&["robot", "clearance", "--q", HOME, "--scene", path]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("obstacles[0].radius") && err.contains("\"b\""),
        "{err}"
    );
}

/// The shipped example scene works as the README says, and a request file's
/// obstacles are the same scene.
#[test]
fn clearance_takes_the_example_scene_and_a_request_file() {
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/scene.json");
    let (code, from_scene, err) = dpmp(&["robot", "clearance", "--q", HOME, "--scene", example]);
    assert_eq!(code, 0, "{err}");
    assert!(
        from_scene["min_clearance_m"].as_f64().unwrap() > 0.0,
        "{from_scene}"
    );
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example).unwrap()).unwrap();
    let mut request = crate::common::requests::typical_json(1, &Default::default());
    request["obstacles"] = scene["obstacles"].clone();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("req.json");
    std::fs::write(&path, request.to_string()).unwrap();
    let (code, from_request, err) = dpmp(&[
        "robot",
        "clearance",
        "--q",
        HOME,
        "--scene",
        path.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(from_request, from_scene);
}

#[test]
fn bad_flags_are_invalid_input() {
    let (code, _, err) = dpmp(&["robot", "fk", "--q", "0,0,0"]);
    assert_eq!(code, 2);
    assert!(err.contains("--q"), "{err}");
    let (code, _, err) = dpmp(&["robot", "fk", "--q", "0,0,x,0,0,0,0"]);
    assert_eq!(code, 2);
    assert!(err.contains("--q[2]"), "{err}");
    let (code, _, err) = dpmp(&["robot", "ik", "--position", "0.6,0,0.7", "--axis", "0,0,0"]);
    assert_eq!(code, 2);
    assert!(err.contains("--axis"), "{err}");
}

#[test]
fn ik_and_shapes_print_json() {
    let (code, json, err) = dpmp(&[
        "robot",
        "ik",
        "--position",
        "0.66,0.05,0.75",
        "--axis",
        "1,0,-0.2",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json["converged"], true);
    assert!(json["position_error_m"].as_f64().unwrap() < 1e-3);
    let (code, json, err) = dpmp(&["robot", "shapes"]);
    assert_eq!(code, 0, "{err}");
    let shapes = json["shapes"].as_array().unwrap();
    // Nine mesh hulls (links 0..7, hand) and four boxes per finger.
    assert_eq!(shapes.len(), 17);
    assert!(shapes
        .iter()
        .any(|s| s["link_name"] == "panda_hand" && s["geometry"]["type"] == "box"));
    assert!(shapes
        .iter()
        .any(|s| s["link_name"] == "panda_link5" && s["geometry"]["type"] == "convex"));
    let (code, json, err) = dpmp(&["robot", "geometry", "--spacing", "0.005"]);
    assert_eq!(code, 0, "{err}");
    let links = json["links"].as_array().unwrap();
    assert_eq!(links.len(), 9);
    for l in links {
        let t = &l["tightness"];
        assert!(t["containment_excess_m"].as_f64().unwrap() <= 1e-6, "{l}");
        assert!(t["max_gap_m"].as_f64().unwrap() <= 0.0015, "{l}");
    }
    let (code, _, err) = dpmp(&["robot", "geometry", "--spacing", "0"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--spacing"), "{err}");
}

/// The robot shapes wire format (`GET /v1/robot`, `dpmp robot shapes`),
/// exactly: hand-built primitives, URDF primitives placed by rotated
/// origins, and the shipped Panda's shapes and CLI output by hash.
#[test]
fn robot_shapes_json_is_pinned() {
    use dpmp::geometry::{Capsule, OrientedBox, Primitive, Sphere};
    use dpmp::robot::{LinkShape, Robot};
    use sha2::{Digest, Sha256};
    let shape = |link: usize, geometry: Primitive| LinkShape {
        link,
        link_name: format!("l{link}"),
        geometry: geometry.into(),
    };
    let shapes = [
        shape(
            0,
            Primitive::Capsule(Capsule {
                a: [0.0, 0.0, -0.1],
                b: [0.0, 0.0, 0.1],
                radius: 0.05,
            }),
        ),
        shape(
            1,
            Primitive::Sphere(Sphere {
                center: [0.1, 0.2, 0.3],
                radius: 0.04,
            }),
        ),
        shape(
            2,
            Primitive::Box(OrientedBox {
                center: [0.0, 0.5, 0.0],
                half_extents: [0.1, 0.2, 0.3],
                rotation: [0.0, 0.0, 0.0, 1.0],
            }),
        ),
    ];
    assert_eq!(
        serde_json::to_string(&shapes).unwrap(),
        r#"[{"link":0,"link_name":"l0","geometry":{"type":"capsule","a":[0.0,0.0,-0.1],"b":[0.0,0.0,0.1],"radius":0.05}},{"link":1,"link_name":"l1","geometry":{"type":"sphere","center":[0.1,0.2,0.3],"radius":0.04}},{"link":2,"link_name":"l2","geometry":{"type":"box","center":[0.0,0.5,0.0],"half_extents":[0.1,0.2,0.3],"rotation":[0.0,0.0,0.0,1.0]}}]"#
    );

    let urdf = r#"<robot name="prims">
      <link name="base"><collision><origin xyz="0 0 0.05" rpy="0.1 0.2 0.3"/><geometry><sphere radius="0.1"/></geometry></collision></link>
      <link name="a"><collision><origin xyz="0 0.1 0.25" rpy="0.5 0 0"/><geometry><cylinder radius="0.05" length="0.5"/></geometry></collision>
        <collision><origin xyz="0.2 0 0.1" rpy="0 0.7 -0.4"/><geometry><box size="0.1 0.2 0.3"/></geometry></collision></link>
      <link name="b"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><origin xyz="0 0 0.1"/>
        <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="2" effort="1"/></joint>
      <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.5" rpy="0 0.3 0"/>
        <axis xyz="1 0 0"/><limit lower="-1" upper="1" velocity="2" effort="1"/></joint>
    </robot>"#;
    let robot = Robot::from_urdf_str(urdf, "base", "b").unwrap();
    assert_eq!(
        serde_json::to_string(robot.collision_shapes()).unwrap(),
        r#"[{"link":0,"link_name":"base","geometry":{"type":"sphere","center":[0.0,0.0,0.05],"radius":0.1}},{"link":1,"link_name":"a","geometry":{"type":"capsule","a":[0.0,0.21985638465105076,0.03060435952740681],"b":[0.0,-0.019856384651050746,0.4693956404725932],"radius":0.05}},{"link":1,"link_name":"a","geometry":{"type":"box","center":[0.2,0.0,0.1],"half_extents":[0.05,0.1,0.15],"rotation":[0.06812327793826826,0.3360626807021292,-0.18662454822852997,0.920647799997774]}}]"#
    );

    let hex = |bytes: &[u8]| format!("{:x}", Sha256::digest(bytes));
    let panda = serde_json::to_string(Robot::panda().unwrap().collision_shapes()).unwrap();
    assert_eq!(
        hex(panda.as_bytes()),
        "7e6cf70c3d8b85040949da63b844266e752ec30edce7464d312300c49d695880"
    );
    let out = crate::common::cli::dpmp(&["robot", "shapes"]);
    assert!(out.status.success());
    assert_eq!(
        hex(&out.stdout),
        "95ec7738360eb6212920c1f53b1ca8eda77e79398b5a82e577fd2cda63e59d25"
    );
}
