//! [`PairContact`]: what one robot/obstacle pair query answers, whichever
//! query answered it (the general one in `distance`, the closed forms of
//! `round_contact`).

use nalgebra::Vector3;

/// Signed distance and witness points of one robot/obstacle pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairContact {
    /// Signed distance (m), negative when penetrating.
    pub distance: f64,
    /// Witness point on the robot primitive (base frame).
    pub point_robot: Vector3<f64>,
    /// Witness point on the obstacle (base frame).
    pub point_obstacle: Vector3<f64>,
    /// Unit normal from the obstacle towards the robot.
    pub normal: Vector3<f64>,
}
