//! Demonstrations: start at home, end at the pre-grasp pose, stay within
//! the joint limits and collision-free (checked at every sample).

use dpmp::promp::{Basis, PrompConfig};
use dpmp::robot::Robot;
use dpmp::scene::Scene;
use dpmp::synth::camera::Camera;
use dpmp::synth::demos::DemoContext;
use dpmp::synth::obstacles::plant_obstacles;
use dpmp::synth::plant::{sample_plant, Placement};
use dpmp::synth::settings::SynthSettings;
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;

#[test]
fn demos_start_at_home_reach_the_pregrasp_and_are_collision_free() {
    let robot = Robot::panda().unwrap();
    let s = SynthSettings::new(1, 3);
    let home = robot.home();
    let tcp = robot.tcp_pose(&home);
    let cam = Camera::on_gripper(
        &s.camera.model,
        Point3::from(tcp.translation.vector),
        tcp.rotation * Vector3::z(),
    )
    .unwrap();
    let basis = Basis::new(&PrompConfig::default()).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut checked = 0;
    for _ in 0..6 {
        let plant =
            sample_plant(&s.plant, &cam, 4.0, 3, &Placement::at_points(), &mut rng).unwrap();
        let scene = Scene::new(plant_obstacles(&plant)).unwrap();
        let ctx = DemoContext {
            robot: &robot,
            scene: &scene,
            basis: &basis,
            settings: &s.demos,
        };
        let b = &plant.berries[0];
        let Ok(td) = ctx.target(&b.center, &b.id, &mut rng) else {
            continue;
        };
        assert_eq!(td.demos.len(), 10);
        for d in &td.demos {
            assert_eq!(d.trajectory.nrows(), 150);
            for (j, (q, h)) in d.start().iter().zip(&home).enumerate() {
                assert!(
                    (q - h).abs() <= s.demos.start_max_rad + 1e-12,
                    "joint {j} starts {q} vs home {h}"
                );
            }
            // Pre-grasp: the TCP stops standoff short of the berry centre.
            let dist = (d.final_tcp.translation.vector - b.center.coords).norm();
            assert!(
                (dist - s.demos.standoff_m).abs()
                    < 4.0 * (s.demos.position_noise_m + s.demos.standoff_jitter_m) + 3e-3,
                "{dist}"
            );
            for k in 0..150 {
                let q: Vec<f64> = d.trajectory.row(k).iter().copied().collect();
                for (v, lim) in q.iter().zip(robot.limits()) {
                    assert!(*v >= lim.lower && *v <= lim.upper);
                }
                let c = scene.min_clearance(&robot, &robot.fk(&q)).unwrap();
                // Checked every 3rd sample at clearance_m; in between it may dip by motion of ~1 mm.
                assert!(
                    c.distance > s.demos.clearance_m - 0.003,
                    "sample {k}: {} m to {}",
                    c.distance,
                    c.obstacle_id(&scene)
                );
            }
            assert!(d.min_clearance_m >= s.demos.clearance_m);
        }
        // The ProMP fit reproduces the demonstration closely.
        let rec = dpmp::promp::trajectory_from_weights(&basis, td.demos[0].weights.as_slice(), 7);
        let err = (rec - &td.demos[0].trajectory).abs().max();
        assert!(err < 0.02, "fit error {err}");
        checked += 1;
    }
    assert!(checked >= 3, "only {checked} plants had demonstrations");
}
