//! Obstacle JSON (the request schema) and validation errors that name the
//! field and the obstacle id.

use crate::common::scene::{obstacle, sphere};
use dpmp::geometry::{OrientedBox, Sphere};
use dpmp::scene::{BerryShape, Obstacle, ObstacleShape, Scene, SceneFile};
use serde_json::json;

const REQUEST_OBSTACLES: &str = r#"{"obstacles": [
    {"id": "berry-2", "type": "sphere", "center": [0.6, 0.0, 0.7], "radius": 0.015},
    {"id": "stem-2", "type": "capsule", "a": [0.6, 0.0, 0.715], "b": [0.6, 0.0, 0.8], "radius": 0.003},
    {"id": "tray", "type": "box", "center": [0.5, 0.0, 0.2], "half_extents": [0.1, 0.2, 0.05],
     "rotation": [0, 0, 0, 1]},
    {"id": "leaf", "type": "convex", "points": [[0.5, 0.1, 0.6], [0.55, 0.1, 0.6], [0.5, 0.15, 0.6], [0.52, 0.12, 0.62]]},
    {"id": "post", "type": "cylinder", "a": [0.8, 0.3, 0.0], "b": [0.8, 0.3, 1.0], "radius": 0.02},
    {"id": "berry-3", "type": "berry", "center": [0.65, 0.1, 0.7], "radius": 0.014, "elongation": 0.005,
     "stem_top": [0.65, 0.1, 0.78], "stem_radius": 0.002},
    {"id": "plate", "type": "box", "center": [0.0, 0.5, 0.0], "half_extents": [0.1, 0.1, 0.01]}
]}"#;

fn parse(text: &str) -> Result<SceneFile, serde_json::Error> {
    serde_json::from_str(text)
}

#[test]
fn the_request_examples_parse_and_round_trip() {
    let file = parse(REQUEST_OBSTACLES).unwrap();
    assert_eq!(file.obstacles.len(), 7);
    assert_eq!(file.obstacles[0].id, "berry-2");
    assert_eq!(
        file.obstacles[0].shape,
        ObstacleShape::Sphere(Sphere {
            center: [0.6, 0.0, 0.7],
            radius: 0.015
        })
    );
    match &file.obstacles[6].shape {
        ObstacleShape::Box(OrientedBox { rotation, .. }) => {
            assert_eq!(*rotation, [0.0, 0.0, 0.0, 1.0])
        }
        other => panic!("{other:?}"),
    }
    match &file.obstacles[5].shape {
        ObstacleShape::Berry(BerryShape {
            elongation,
            stem_radius,
            ..
        }) => {
            assert_eq!(*elongation, 0.005);
            assert_eq!(*stem_radius, 0.002);
        }
        other => panic!("{other:?}"),
    }
    let text = serde_json::to_string(&file).unwrap();
    assert!(text.contains(r#""id":"berry-2","type":"sphere""#), "{text}");
    assert_eq!(parse(&text).unwrap(), file);
    let scene = Scene::new(file.obstacles).unwrap();
    assert_eq!(scene.obstacles().len(), 7);
    assert!(!scene.is_empty());
}

#[test]
fn unknown_fields_missing_ids_and_unknown_types_are_rejected() {
    let e = parse(r#"{"obstacles": [{"id": "b", "type": "sphere", "center": [0,0,0], "radius": 0.1, "colour": 1}]}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("colour") && e.contains("\"b\""), "{e}");
    let e = parse(r#"{"obstacles": [{"type": "sphere", "center": [0,0,0], "radius": 0.1}]}"#)
        .unwrap_err();
    assert!(e.to_string().contains("id"), "{e}");
    let e =
        parse(r#"{"obstacles": [{"id": "t", "type": "torus", "center": [0,0,0]}]}"#).unwrap_err();
    assert!(e.to_string().contains("torus"), "{e}");
    let e =
        parse(r#"{"obstacles": [{"id": "s", "type": "sphere", "center": [0,0], "radius": 0.1}]}"#)
            .unwrap_err();
    assert!(e.to_string().contains("\"s\""), "{e}");
    assert!(parse(r#"{"obstacles": [], "extra": 1}"#).is_err());
}

/// Where the spheres of the validation tests sit.
const CENTRE: [f64; 3] = [0.5, 0.0, 0.5];

fn error_of(obstacles: Vec<Obstacle>) -> (String, String) {
    let e = Scene::new(obstacles).unwrap_err();
    (e.field().unwrap_or("").to_string(), e.to_string())
}

#[test]
fn bad_obstacles_name_the_field_and_the_id() {
    let (field, msg) = error_of(vec![
        sphere("a", CENTRE, 0.1),
        sphere("b", CENTRE, 0.1),
        sphere("berry-2", CENTRE, -0.01),
    ]);
    assert_eq!(field, "obstacles[2].radius");
    assert!(msg.contains("berry-2"), "{msg}");

    let mut nan = sphere("n", CENTRE, 0.1);
    if let ObstacleShape::Sphere(Sphere { center, .. }) = &mut nan.shape {
        center[1] = f64::NAN;
    }
    assert_eq!(error_of(vec![nan]).0, "obstacles[0].center[1]");

    let (field, msg) = error_of(vec![sphere("dup", CENTRE, 0.1), sphere("dup", CENTRE, 0.2)]);
    assert_eq!(field, "obstacles[1].id");
    assert!(msg.contains("dup"));
    assert_eq!(
        error_of(vec![sphere(" ", CENTRE, 0.1)]).0,
        "obstacles[0].id"
    );

    let flat_box = obstacle(
        "tray",
        ObstacleShape::Box(OrientedBox {
            center: [0.0; 3],
            half_extents: [0.1, 0.0, 0.1],
            rotation: [0.0, 0.0, 0.0, 1.0],
        }),
    );
    let (field, msg) = error_of(vec![flat_box]);
    assert_eq!(field, "obstacles[0].half_extents[1]");
    assert!(msg.contains("tray"));

    let skew = obstacle(
        "skew",
        ObstacleShape::Box(OrientedBox {
            center: [0.0; 3],
            half_extents: [0.1; 3],
            rotation: [0.0, 0.0, 0.0, 2.0],
        }),
    );
    assert_eq!(error_of(vec![skew]).0, "obstacles[0].rotation");

    let three = obstacle(
        "leaf",
        ObstacleShape::Convex {
            points: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        },
    );
    let (field, msg) = error_of(vec![three]);
    assert_eq!(field, "obstacles[0].points");
    assert!(msg.contains("leaf") && msg.contains("4"), "{msg}");

    let coplanar = obstacle(
        "leaf-2",
        ObstacleShape::Convex {
            points: vec![
                [0.0; 3],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.5, 0.2, 0.0],
            ],
        },
    );
    let (field, msg) = error_of(vec![coplanar]);
    assert_eq!(field, "obstacles[0].points");
    assert!(msg.contains("coplanar"), "{msg}");

    let cylinder = obstacle(
        "post",
        ObstacleShape::Cylinder {
            a: [0.1; 3],
            b: [0.1; 3],
            radius: 0.01,
        },
    );
    assert_eq!(error_of(vec![cylinder]).0, "obstacles[0].b");

    let swallowed_stem = obstacle(
        "berry-9",
        ObstacleShape::Berry(BerryShape {
            center: [0.0; 3],
            radius: 0.02,
            elongation: 0.01,
            stem_top: [0.0, 0.0, 0.025],
            stem_radius: 0.002,
        }),
    );
    let (field, msg) = error_of(vec![swallowed_stem]);
    assert_eq!(field, "obstacles[0].stem_top");
    assert!(msg.contains("berry-9"));

    let fat_stem = obstacle(
        "berry-8",
        ObstacleShape::Berry(BerryShape {
            center: [0.0; 3],
            radius: 0.01,
            elongation: 0.0,
            stem_top: [0.0, 0.0, 0.1],
            stem_radius: 0.02,
        }),
    );
    assert_eq!(error_of(vec![fat_stem]).0, "obstacles[0].stem_radius");
}

#[test]
fn scene_files_load_and_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("scene.json");
    std::fs::write(&good, REQUEST_OBSTACLES).unwrap();
    assert_eq!(Scene::from_file(&good).unwrap().obstacles().len(), 7);
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"obstacles\": [").unwrap();
    assert!(Scene::from_file(&bad)
        .unwrap_err()
        .to_string()
        .contains("bad.json"));
}

/// The obstacle wire format, exactly: what `/v1/optimize`, `/v1/plan`,
/// scene files and dataset records accept and write back, and the serde
/// messages API users read for unknown fields, unknown types, short arrays
/// and missing fields.
#[test]
fn wire_format_is_pinned() {
    let file = parse(REQUEST_OBSTACLES).unwrap();
    assert_eq!(
        serde_json::to_string(&file).unwrap(),
        r#"{"obstacles":[{"id":"berry-2","type":"sphere","center":[0.6,0.0,0.7],"radius":0.015},{"id":"stem-2","type":"capsule","a":[0.6,0.0,0.715],"b":[0.6,0.0,0.8],"radius":0.003},{"id":"tray","type":"box","center":[0.5,0.0,0.2],"half_extents":[0.1,0.2,0.05],"rotation":[0.0,0.0,0.0,1.0]},{"id":"leaf","type":"convex","points":[[0.5,0.1,0.6],[0.55,0.1,0.6],[0.5,0.15,0.6],[0.52,0.12,0.62]]},{"id":"post","type":"cylinder","a":[0.8,0.3,0.0],"b":[0.8,0.3,1.0],"radius":0.02},{"id":"berry-3","type":"berry","center":[0.65,0.1,0.7],"radius":0.014,"elongation":0.005,"stem_top":[0.65,0.1,0.78],"stem_radius":0.002},{"id":"plate","type":"box","center":[0.0,0.5,0.0],"half_extents":[0.1,0.1,0.01],"rotation":[0.0,0.0,0.0,1.0]}]}"#
    );
    let error = |text: &str| parse(text).unwrap_err().to_string();
    assert_eq!(
        error(
            r#"{"obstacles": [{"id": "b", "type": "sphere", "center": [0,0,0], "radius": 0.1, "colour": 1}]}"#
        ),
        r#"obstacle "b": unknown field `colour`, expected `center` or `radius` at line 1 column 92"#
    );
    assert_eq!(
        error(r#"{"obstacles": [{"id": "t", "type": "torus", "center": [0,0,0]}]}"#),
        r#"obstacle "t": unknown variant `torus`, expected one of `sphere`, `capsule`, `cylinder`, `box`, `convex`, `berry`, `points` at line 1 column 63"#
    );
    assert_eq!(
        error(r#"{"obstacles": [{"id": "s", "type": "sphere", "center": [0,0], "radius": 0.1}]}"#),
        r#"obstacle "s": invalid length 2, expected an array of length 3 at line 1 column 77"#
    );
    assert_eq!(
        error(r#"{"obstacles": [{"id": "s", "type": "capsule", "a": [0,0,0], "radius": 1}]}"#),
        r#"obstacle "s": missing field `b` at line 1 column 73"#
    );
    assert_eq!(
        error(
            r#"{"obstacles": [{"id": "c", "type": "capsule", "a": [0,0,0], "b": [0,0,1], "radius": 1, "center": [0,0,0]}]}"#
        ),
        r#"obstacle "c": unknown field `center`, expected one of `a`, `b`, `radius` at line 1 column 106"#
    );
    assert_eq!(
        error(
            r#"{"obstacles": [{"id": "x", "type": "box", "center": [0,0,0], "half_extents": [1,1,1], "rotation": [0,0,1]}]}"#
        ),
        r#"obstacle "x": invalid length 3, expected an array of length 4 at line 1 column 107"#
    );
    assert_eq!(
        error(r#"{"obstacles": [{"id": "x", "type": "box", "center": [0,0,0], "size": [1,1,1]}]}"#),
        r#"obstacle "x": unknown field `size`, expected one of `center`, `half_extents`, `rotation` at line 1 column 78"#
    );
    assert_eq!(
        error(r#"{"obstacles": [{"id": "x", "center": [0,0,0], "radius": 1}]}"#),
        r#"obstacle "x": missing field `type` at line 1 column 59"#
    );
    let plate = &file.obstacles[6];
    assert_eq!(
        serde_json::to_string(plate).unwrap(),
        r#"{"id":"plate","type":"box","center":[0.0,0.5,0.0],"half_extents":[0.1,0.1,0.01],"rotation":[0.0,0.0,0.0,1.0]}"#
    );
}

/// Every validation error, field path and message exactly.
#[test]
fn validation_messages_are_pinned() {
    let cases = [
        r#"{"id": "s", "type": "sphere", "center": [0,0,0], "radius": 0}"#,
        r#"{"id": "c", "type": "capsule", "a": [0,0,0], "b": [0,0,1], "radius": -1}"#,
        r#"{"id": "y", "type": "cylinder", "a": [0,0,0], "b": [0,0,0], "radius": 1}"#,
        r#"{"id": "y", "type": "cylinder", "a": [0,0,0], "b": [0,0,1], "radius": 0}"#,
        r#"{"id": "x", "type": "box", "center": [0,0,0], "half_extents": [1,0,1]}"#,
        r#"{"id": "x", "type": "box", "center": [0,0,0], "half_extents": [1,1,1], "rotation": [0,0,0,2]}"#,
        r#"{"id": "v", "type": "convex", "points": [[0,0,0],[1,0,0],[0,1,0]]}"#,
        r#"{"id": "v", "type": "convex", "points": [[0,0,0],[1,0,0],[0,1,0],[1,1,0]]}"#,
        r#"{"id": "b", "type": "berry", "center": [0,0,0], "radius": 0, "stem_top": [0,0,1]}"#,
        r#"{"id": "b", "type": "berry", "center": [0,0,0], "radius": 0.1, "elongation": -1, "stem_top": [0,0,1]}"#,
        r#"{"id": "b", "type": "berry", "center": [0,0,0], "radius": 0.1, "stem_top": [0,0,1], "stem_radius": 0}"#,
        r#"{"id": "b", "type": "berry", "center": [0,0,0], "radius": 0.1, "stem_top": [0,0,1], "stem_radius": 0.2}"#,
        r#"{"id": "b", "type": "berry", "center": [0,0,0], "radius": 0.1, "stem_top": [0,0,0.05]}"#,
    ];
    let messages: Vec<String> = cases
        .iter()
        .map(|text| {
            let o: Obstacle = serde_json::from_str(text).unwrap();
            let e = Scene::new(vec![o]).unwrap_err();
            format!("{} | {e}", e.field().unwrap_or(""))
        })
        .collect();
    assert_eq!(
        messages,
        [
            r#"obstacles[0].radius | invalid obstacles[0].radius: obstacle "s": must be a size in [0.000000001, 100] m, got 0"#,
            r#"obstacles[0].radius | invalid obstacles[0].radius: obstacle "c": must be a size in [0.000000001, 100] m, got -1"#,
            r#"obstacles[0].b | invalid obstacles[0].b: obstacle "y": must differ from a (zero-length cylinder)"#,
            r#"obstacles[0].radius | invalid obstacles[0].radius: obstacle "y": must be a size in [0.000000001, 100] m, got 0"#,
            r#"obstacles[0].half_extents[1] | invalid obstacles[0].half_extents[1]: obstacle "x": must be a size in [0.000000001, 100] m, got 0"#,
            r#"obstacles[0].rotation | invalid obstacles[0].rotation: obstacle "x": must be a unit quaternion [x, y, z, w], norm is 2"#,
            r#"obstacles[0].points | invalid obstacles[0].points: obstacle "v": a convex hull needs at least 4 points, got 3"#,
            r#"obstacles[0].points | invalid obstacles[0].points: obstacle "v": the points are coplanar (the hull has no volume)"#,
            r#"obstacles[0].radius | invalid obstacles[0].radius: obstacle "b": must be a size in [0.000000001, 100] m, got 0"#,
            r#"obstacles[0].elongation | invalid obstacles[0].elongation: obstacle "b": must be in [0, 100] m, got -1"#,
            r#"obstacles[0].stem_radius | invalid obstacles[0].stem_radius: obstacle "b": must be a size in [0.000000001, 100] m, got 0"#,
            r#"obstacles[0].stem_radius | invalid obstacles[0].stem_radius: obstacle "b": must not exceed the radius 0.1, got 0.2"#,
            r#"obstacles[0].stem_top | invalid obstacles[0].stem_top: obstacle "b": must lie outside the berry body"#,
        ]
    );
    let nan = obstacle(
        "v",
        ObstacleShape::Convex {
            points: vec![[0.0; 3], [1.0, 0.0, f64::NAN]],
        },
    );
    let e = Scene::new(vec![nan]).unwrap_err();
    assert_eq!(
        format!("{} | {e}", e.field().unwrap_or("")),
        r#"obstacles[0].points[1][2] | invalid obstacles[0].points[1][2]: obstacle "v": must be a finite coordinate within ±100 m, got NaN"#
    );
}

/// A number from about −1e300 to 1e300, log-uniform in magnitude, often
/// near the validation bounds.
fn extreme(rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    use rand::Rng;
    let magnitude = 10f64.powf(rng.gen_range(-300.0..300.0));
    let near_bound = [100.0, 100.0000001, 99.999, 1e-9, 0.99e-9, 0.0][rng.gen_range(0..6)];
    let v = if rng.gen_bool(0.3) {
        near_bound
    } else {
        magnitude
    };
    if rng.gen_bool(0.5) {
        v
    } else {
        -v
    }
}

/// Obstacles of every type with extreme coordinates and sizes: each
/// request either solves or is refused naming an obstacle field, and
/// nothing panics (parry's EPA and capsule code panic on some such input
/// when it reaches them).
#[test]
fn extreme_obstacles_are_refused_or_solved_never_a_panic() {
    use rand::{Rng, SeedableRng};
    let (robot, mut base) = crate::common::requests::typical(0, &Default::default());
    base.task.promp.n_samples = 20;
    base.task.options.max_iterations = 3;
    base.task.options.restarts = 0;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(99);
    let (mut refused, mut solved) = (0, 0);
    for case in 0..60 {
        let mut p = || [extreme(&mut rng), extreme(&mut rng), extreme(&mut rng)];
        let (a, b, c) = (p(), p(), p());
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(case);
        let size = extreme(&mut r).abs();
        let kind = rng.gen_range(0..5);
        let mut shape = match kind {
            0 => json!({"type": "sphere", "center": a, "radius": size}),
            1 => json!({"type": "capsule", "a": a, "b": b, "radius": size}),
            2 => json!({"type": "cylinder", "a": a, "b": b, "radius": size}),
            3 => json!({"type": "box", "center": a, "half_extents": [size, size * 0.5, 0.01]}),
            _ => json!({"type": "convex", "points": [a, b, c, [0.5, 0.5, 0.5]]}),
        };
        // Half the cases near the arm, where the narrow phase runs.
        if case % 2 == 0 && kind != 4 {
            let key = if kind == 0 || kind == 3 {
                "center"
            } else {
                "a"
            };
            shape[key] = json!([0.5, 0.0, 0.6]);
        }
        shape["id"] = json!("x");
        let mut request = base.clone();
        request.task.obstacles = vec![serde_json::from_value(shape.clone()).unwrap()];
        let outcome = std::panic::catch_unwind(|| dpmp::optim::optimize(&request, &robot));
        match outcome {
            Err(_) => panic!("case {case}: panicked on {shape}"),
            Ok(Ok(_)) => solved += 1,
            Ok(Err(dpmp::Error::Invalid { field, .. })) => {
                assert!(field.starts_with("obstacles[0]"), "case {case}: {field}");
                refused += 1;
            }
            Ok(Err(e)) => panic!("case {case}: {e} on {shape}"),
        }
    }
    eprintln!("{refused} refused, {solved} solved");
    assert!(refused > 0 && solved > 0);
}
