//! Robot-versus-scene clearance: closed forms for spheres, penetration
//! signs, normals, the broad phase against brute force, and the clearance
//! gradient against central finite differences.

use crate::common::robot::{at_fractions, panda};
use crate::common::scene::sphere;
use dpmp::geometry::{Capsule, OrientedBox, Primitive};
use dpmp::robot::{Robot, PANDA_HOME};
use dpmp::scene::{BerryShape, Obstacle, ObstacleShape, Scene};
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;

/// Exact signed distance from a ball to every robot primitive, in f64.
fn closed_form_sphere_clearance(
    robot: &Robot,
    q: &[f64],
    center: &[f64; 3],
    radius: f64,
) -> (f64, usize) {
    let frames = robot.fk(q);
    robot
        .collision_shapes()
        .iter()
        .enumerate()
        .map(|(i, s)| {
            (
                s.geometry
                    .transformed(&frames.poses[s.link])
                    .signed_distance(center)
                    - radius,
                i,
            )
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap()
}

/// A cluster of 20 berries (with stems) around the paper's berry workspace.
pub fn berry_cluster() -> Vec<Obstacle> {
    (0..20)
        .map(|i| {
            let t = i as f64;
            let center = [
                0.62 + 0.02 * (t * 0.7).sin(),
                -0.2 + 0.02 * t,
                0.62 + 0.011 * t,
            ];
            Obstacle {
                id: format!("berry-{i}"),
                shape: ObstacleShape::Berry(BerryShape {
                    center,
                    radius: 0.012 + 0.0005 * (i % 5) as f64,
                    elongation: 0.004,
                    stem_top: [center[0], center[1], center[2] + 0.06],
                    stem_radius: 0.002,
                }),
            }
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    #[test]
    fn sphere_clearance_matches_the_closed_form(
        fractions in proptest::collection::vec(0.05f64..0.95, 7),
        center in proptest::array::uniform3(-0.6f64..0.8),
        radius in 0.005f64..0.1,
    ) {
        let robot = panda();
        let q = at_fractions(&robot, &fractions);
        let center = [center[0], center[1], center[2] + 0.5];
        let scene = Scene::new(vec![sphere("s", center, radius)]).unwrap();
        let c = scene.min_clearance(&robot, &robot.fk(&q)).unwrap();
        let (expect, _) = closed_form_sphere_clearance(&robot, &q, &center, radius);
        prop_assert!((c.distance - expect).abs() < 2e-5, "parry {} closed form {expect}", c.distance);
        prop_assert_eq!(c.obstacle_id(&scene), "s");
        prop_assert_eq!(c.link_name(&robot), robot.collision_shapes()[c.shape].link_name.as_str());
        // witness points: distance between them equals |distance|, the normal is unit
        let gap = Vector3::from(c.point_robot) - Vector3::from(c.point_obstacle);
        prop_assert!((gap.norm() - c.distance.abs()).abs() < 2e-5);
        prop_assert!((Vector3::from(c.normal).norm() - 1.0).abs() < 1e-5);
        if c.distance.abs() > 1e-4 {
            // the normal points from the obstacle towards the robot
            prop_assert!(gap.normalize().dot(&Vector3::from(c.normal)) * c.distance.signum() > 0.999);
        }
    }

    #[test]
    fn broad_phase_gives_the_same_pairs_as_brute_force(
        fractions in proptest::collection::vec(0.05f64..0.95, 7),
        activation in 0.01f64..0.3,
    ) {
        let robot = panda();
        let q = at_fractions(&robot, &fractions);
        let frames = robot.fk(&q);
        let scene = Scene::new(berry_cluster()).unwrap();
        let within = scene.clearances_within(&robot, &frames, activation);
        let everything = scene.clearances_within(&robot, &frames, 100.0);
        prop_assert_eq!(everything.len(), robot.collision_shapes().len() * 20);
        let brute: Vec<_> = everything.iter().filter(|c| c.distance < activation).collect();
        prop_assert_eq!(within.len(), brute.len());
        for (a, b) in within.iter().zip(brute) {
            prop_assert_eq!((a.shape, a.obstacle), (b.shape, b.obstacle));
            prop_assert!((a.distance - b.distance).abs() < 1e-6);
        }
        for c in &everything {
            let pair = scene.pair_clearance(&robot, &frames, c.shape, c.obstacle).unwrap();
            prop_assert!((pair.distance - c.distance).abs() < 1e-6);
        }
        prop_assert!(scene.pair_clearance(&robot, &frames, robot.collision_shapes().len(), 0).is_none());
        prop_assert!(scene.pair_clearance(&robot, &frames, 0, 20).is_none());
        let min = scene.min_clearance(&robot, &frames).unwrap();
        let brute_min = everything.iter().map(|c| c.distance).fold(f64::INFINITY, f64::min);
        prop_assert!((min.distance - brute_min).abs() < 1e-6, "{} vs {brute_min}", min.distance);
        // Branch and bound finds the same closest pair as the full list
        // (first in its order on ties), or nothing when none is within.
        let closest = scene.closest_within(&robot, &frames, activation);
        let first_min = within.iter().fold(None::<&dpmp::scene::Clearance>, |best, c| match best {
            Some(b) if b.distance <= c.distance => Some(b),
            _ => Some(c),
        });
        match (closest, first_min) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                prop_assert_eq!((a.shape, a.obstacle), (b.shape, b.obstacle));
                prop_assert!((a.distance - b.distance).abs() < 1e-12);
            }
            (a, b) => prop_assert!(false, "closest_within {:?} vs list {:?}", a.map(|c| c.distance), b.map(|c| c.distance)),
        }
    }
}

#[test]
fn penetration_is_negative_with_the_right_depth_and_normal() {
    let robot = panda();
    let frames = robot.fk(&PANDA_HOME);
    let hand = frames.poses[robot.link_index("panda_hand").unwrap()];
    // 7 mm inside the hand mesh's flat +x face (x = 0.032 in the hand frame).
    let inside = hand * Point3::new(0.025, 0.0, 0.02);
    let center = inside.coords.into();
    let scene = Scene::new(vec![sphere("inside", center, 0.02)]).unwrap();
    let c = scene.min_clearance(&robot, &frames).unwrap();
    let (expect, _) = closed_form_sphere_clearance(&robot, &PANDA_HOME, &center, 0.02);
    assert!(
        expect < -0.02,
        "the ball's centre is inside the hand: {expect}"
    );
    assert!(
        (c.distance - expect).abs() < 1e-4,
        "{} vs {expect}",
        c.distance
    );
    let within = scene.clearances_within(&robot, &frames, 0.0);
    assert!(!within.is_empty() && within.iter().all(|c| c.distance < 0.0));
    assert_eq!(scene.obstacle_containing(&inside, 0.0), Some(0));
    // the normal points out of the obstacle towards the robot: pushing the
    // ball along it (towards the robot) deepens the penetration
    let pushed = Vector3::from(center) + Vector3::from(c.normal) * 0.002;
    let (deeper, _) = closed_form_sphere_clearance(&robot, &PANDA_HOME, &pushed.into(), 0.02);
    assert!(deeper < expect, "{deeper} vs {expect}");
}

#[test]
fn clearance_gradient_matches_finite_differences() {
    let robot = panda();
    let tcp = robot.tcp_pose(&PANDA_HOME);
    // berries ahead of the gripper, to the side of the forearm, and a box
    let ahead = tcp * Point3::new(0.02, 0.03, 0.08);
    let side = robot.fk(&PANDA_HOME).poses[4] * Point3::new(0.0, 0.0, 0.2);
    let scenes = [
        vec![sphere("ahead", ahead.coords.into(), 0.015)],
        vec![sphere("side", side.coords.into(), 0.03)],
        vec![Obstacle {
            id: "box".into(),
            shape: ObstacleShape::Box(OrientedBox {
                center: (tcp * Point3::new(0.05, 0.1, 0.05)).coords.into(),
                half_extents: [0.03, 0.02, 0.04],
                rotation: [0.1, 0.2, 0.3, 0.927_361_849_549_570_4],
            }),
        }],
    ];
    let h = 1e-4;
    for obstacles in scenes {
        let scene = Scene::new(obstacles).unwrap();
        let (c, gradient) = scene
            .min_clearance_with_gradient(&robot, &PANDA_HOME)
            .unwrap();
        let frames = robot.fk(&PANDA_HOME);
        assert_eq!(
            gradient,
            scene.clearance_gradient(&robot, &PANDA_HOME, &frames, &c)
        );
        for i in 0..7 {
            let mut plus = PANDA_HOME.to_vec();
            plus[i] += h;
            let mut minus = PANDA_HOME.to_vec();
            minus[i] -= h;
            let dp = scene.min_clearance(&robot, &robot.fk(&plus)).unwrap();
            let dm = scene.min_clearance(&robot, &robot.fk(&minus)).unwrap();
            assert_eq!(
                (dp.shape, dm.shape),
                (c.shape, c.shape),
                "the closest pair changed"
            );
            let fd = (dp.distance - dm.distance) / (2.0 * h);
            assert!(
                (gradient[i] - fd).abs() < 2e-3 + 2e-3 * fd.abs(),
                "{}: joint {i}: analytic {} fd {fd}",
                c.obstacle_id(&scene),
                gradient[i]
            );
        }
    }
}

#[test]
fn clearance_gradient_matches_the_closed_form_derivative() {
    // With a ball obstacle the exact distance is available in f64, so the
    // finite difference can use a small step.
    let robot = panda();
    let center: [f64; 3] = (robot.tcp_pose(&PANDA_HOME) * Point3::new(0.03, -0.02, 0.09))
        .coords
        .into();
    let scene = Scene::new(vec![sphere("berry", center, 0.012)]).unwrap();
    let (c, gradient) = scene
        .min_clearance_with_gradient(&robot, &PANDA_HOME)
        .unwrap();
    let h = 1e-6;
    for i in 0..7 {
        let mut plus = PANDA_HOME.to_vec();
        plus[i] += h;
        let mut minus = PANDA_HOME.to_vec();
        minus[i] -= h;
        let (dp, sp) = closed_form_sphere_clearance(&robot, &plus, &center, 0.012);
        let (dm, sm) = closed_form_sphere_clearance(&robot, &minus, &center, 0.012);
        assert_eq!((sp, sm), (c.shape, c.shape));
        let fd = (dp - dm) / (2.0 * h);
        assert!(
            (gradient[i] - fd).abs() < 2e-4,
            "joint {i}: analytic {} fd {fd}",
            gradient[i]
        );
    }
}

#[test]
fn berries_are_a_body_plus_a_stem() {
    let robot = panda();
    let frames = robot.fk(&PANDA_HOME);
    let tcp = frames.poses[robot.tcp_link()];
    let center = tcp * Point3::new(0.0, 0.0, 0.15);
    let berry = Obstacle {
        id: "berry".into(),
        shape: ObstacleShape::Berry(BerryShape {
            center: center.coords.into(),
            radius: 0.015,
            elongation: 0.005,
            stem_top: (center + Vector3::new(0.0, 0.0, 0.08)).coords.into(),
            stem_radius: 0.002,
        }),
    };
    let scene = Scene::new(vec![berry]).unwrap();
    let c = scene.min_clearance(&robot, &frames).unwrap();
    // closed form: every primitive against the body capsule and the stem capsule
    let body = Primitive::Capsule(Capsule {
        a: (center - Vector3::new(0.0, 0.0, 0.005)).coords.into(),
        b: (center + Vector3::new(0.0, 0.0, 0.005)).coords.into(),
        radius: 0.015,
    });
    let expect = scene
        .clearances_within(&robot, &frames, 10.0)
        .iter()
        .map(|c| c.distance)
        .fold(f64::INFINITY, f64::min);
    assert!((c.distance - expect).abs() < 1e-9);
    // the robot witness point lies on a primitive, the obstacle one on the berry
    let on_body = body.signed_distance(&c.point_obstacle);
    let stem = Primitive::Capsule(Capsule {
        a: (center + Vector3::new(0.0, 0.0, 0.018)).coords.into(),
        b: (center + Vector3::new(0.0, 0.0, 0.08)).coords.into(),
        radius: 0.002,
    });
    let on_stem = stem.signed_distance(&c.point_obstacle);
    assert!(
        on_body.abs() < 1e-4 || on_stem.abs() < 1e-4,
        "{on_body} {on_stem}"
    );
    assert!(c.distance > 0.0 && c.distance < 0.15);
    // containing query: the centre is inside, a point 5 cm off is not within 1 cm
    assert_eq!(scene.obstacle_containing(&center, 0.0), Some(0));
    assert_eq!(
        scene.obstacle_containing(&(center + Vector3::new(0.05, 0.0, 0.0)), 0.01),
        None
    );
    assert_eq!(
        scene.obstacle_containing(&(center + Vector3::new(0.05, 0.0, 0.0)), 0.04),
        Some(0)
    );
}

#[test]
fn cylinders_convex_hulls_and_empty_scenes() {
    let robot = panda();
    let frames = robot.fk(&PANDA_HOME);
    assert!(Scene::empty().min_clearance(&robot, &frames).is_none());
    assert!(Scene::empty()
        .clearances_within(&robot, &frames, 1.0)
        .is_empty());
    assert!(Scene::empty().is_empty());
    // a vertical post 0.3 m in front of the TCP: flat-ended cylinder vs
    // capsule of the same axis differ only beyond the end faces
    let tcp = frames.poses[robot.tcp_link()].translation.vector;
    let post = Obstacle {
        id: "post".into(),
        shape: ObstacleShape::Cylinder {
            a: [tcp.x + 0.3, tcp.y, 0.0],
            b: [tcp.x + 0.3, tcp.y, 1.2],
            radius: 0.02,
        },
    };
    let capsule = Obstacle {
        id: "post".into(),
        shape: ObstacleShape::Capsule(Capsule {
            a: [tcp.x + 0.3, tcp.y, 0.0],
            b: [tcp.x + 0.3, tcp.y, 1.2],
            radius: 0.02,
        }),
    };
    let d_cyl = Scene::new(vec![post])
        .unwrap()
        .min_clearance(&robot, &frames)
        .unwrap()
        .distance;
    let d_cap = Scene::new(vec![capsule])
        .unwrap()
        .min_clearance(&robot, &frames)
        .unwrap()
        .distance;
    assert!((d_cyl - d_cap).abs() < 1e-5, "{d_cyl} {d_cap}");
    // a tetrahedron hull vs its bounding sphere: the hull is never closer
    let c = Vector3::new(tcp.x + 0.1, tcp.y + 0.05, tcp.z);
    let pts: Vec<[f64; 3]> = [
        [1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
    ]
    .iter()
    .map(|v| (c + Vector3::from(*v) * 0.02).into())
    .collect();
    let hull = Scene::new(vec![Obstacle {
        id: "leaf".into(),
        shape: ObstacleShape::Convex { points: pts },
    }])
    .unwrap();
    let ball = Scene::new(vec![sphere("ball", c.into(), 0.02 * 3f64.sqrt())]).unwrap();
    let d_hull = hull.min_clearance(&robot, &frames).unwrap().distance;
    let d_ball = ball.min_clearance(&robot, &frames).unwrap().distance;
    assert!(
        d_hull >= d_ball - 1e-6 && d_hull < d_ball + 0.03,
        "{d_hull} {d_ball}"
    );
}
