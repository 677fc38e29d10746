//! One synthetic harvesting target for the problem generator, drawn with
//! [`crate::synth`]: a plant (its obstacles in the optimise-request schema,
//! [`crate::synth::obstacles::plant_obstacles`]), the demonstrations
//! towards one of its berries ([`crate::synth::demos::DemoContext`]) and
//! their fitted weight distribution.

use crate::promp::WeightDistribution;
use crate::robot::Robot;
use crate::scene::{Obstacle, Scene};
use crate::synth::demos::DemoContext;
use crate::synth::generate::Generator;
use crate::synth::obstacles::plant_obstacles;
use crate::synth::plant::sample_plant;
use crate::synth::settings::SynthSettings;
use crate::{Error, Result};
use nalgebra::{DVector, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Berries per synthetic plant.
pub const BERRIES_PER_PLANT: usize = 4;
/// One target: the plant's obstacles, the demonstrations and their Gaussian.
#[derive(Clone, Debug)]
pub struct SynthTarget {
    /// Every obstacle of the plant (the target berry included).
    pub obstacles: Vec<Obstacle>,
    /// Id of the target berry's obstacle.
    pub berry_id: String,
    /// Joint-major ProMP weights of every demonstration.
    pub demo_weights: Vec<DVector<f64>>,
    /// Full weight distribution fitted to the demonstrations.
    pub distribution: WeightDistribution,
    /// Mean final (pre-grasp) TCP position of the demonstrations (m).
    pub final_tcp: Vector3<f64>,
}

/// The synthetic generator the benchmark draws from: default settings with
/// [`BERRIES_PER_PLANT`] berries. Its demonstrations keep the synthetic
/// default clearance (5 mm); the benchmark asks for 2 cm, so the problem
/// generator keeps only draws where a demonstration verifies at 2 cm (the
/// synthetic settings cannot ask for more with the 10 cm pre-grasp standoff).
pub fn bench_generator(robot: &Robot) -> Result<Generator> {
    let settings = SynthSettings::new(1, BERRIES_PER_PLANT);
    Generator::new(settings, robot.clone())
}

/// Draw a plant and the demonstrations towards one of its berries; `None`
/// when the synthetic generator finds no valid demonstration for it.
pub fn draw_target(generator: &Generator, rng: &mut ChaCha8Rng) -> Result<Option<SynthTarget>> {
    let s = generator.settings();
    let plant = sample_plant(
        &s.plant,
        generator.camera(),
        s.camera.border_px,
        s.berries_per_config,
        &generator.placement(),
        rng,
    )?;
    let obstacles = plant_obstacles(&plant);
    let scene = Scene::new(obstacles.clone())?;
    let ctx = DemoContext {
        robot: generator.robot(),
        scene: &scene,
        basis: generator.basis(),
        settings: &s.demos,
    };
    let berry = &plant.berries[rng.gen_range(0..plant.berries.len())];
    let demos = match ctx.target(&berry.center, &berry.id, rng) {
        Ok(d) => d,
        Err(Error::Infeasible(_)) => return Ok(None),
        Err(e) => return Err(e),
    };
    let p = demos.final_tcp.position;
    Ok(Some(SynthTarget {
        obstacles,
        berry_id: berry.id.clone(),
        demo_weights: demos.demos.iter().map(|d| d.weights.clone()).collect(),
        distribution: demos.distribution,
        final_tcp: Vector3::new(p[0], p[1], p[2]),
    }))
}
