//! Quaternions as the project writes them, `[x, y, z, w]` (URDF-free JSON,
//! obstacles, robot shapes), and their conversion to and from nalgebra's
//! [`UnitQuaternion`] (whose `Quaternion::new` takes `w` first).

use nalgebra::{Quaternion, UnitQuaternion};

/// The identity rotation, `[x, y, z, w]`.
pub const IDENTITY_XYZW: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

/// Normalised quaternion from `[x, y, z, w]`.
#[inline]
pub fn from_xyzw(q: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]))
}

/// A unit quaternion as `[x, y, z, w]`.
#[inline]
pub fn to_xyzw(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.i, q.j, q.k, q.w]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_trip_and_identity_is_identity() {
        assert_eq!(from_xyzw(&IDENTITY_XYZW), UnitQuaternion::identity());
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let back = from_xyzw(&to_xyzw(&q));
        assert!(back.angle_to(&q) < 1e-12);
    }
}
