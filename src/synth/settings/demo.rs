//! [`DemoSettings`]: how the synthetic demonstrations are drawn.

use super::berry_extent;
use crate::error::{ensure_finite, ensure_positive};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// How the demonstrations are drawn.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DemoSettings {
    /// Demonstrations per target.
    pub demos: usize,
    /// Trajectory duration (s).
    pub duration_s: f64,
    /// Standard deviation of the start around home, per joint (rad).
    pub start_std_rad: f64,
    /// Largest start deviation from home (rad); draws beyond are redrawn.
    pub start_max_rad: f64,
    /// Pre-grasp TCP stop distance before the berry centre, along the approach (m).
    pub standoff_m: f64,
    /// Standard deviation of the pre-grasp position noise (m).
    pub position_noise_m: f64,
    /// Standard deviation of the approach-axis noise sideways (yaw, rad).
    pub axis_noise_rad: f64,
    /// Standard deviation of the approach-axis noise up/down (pitch, rad).
    pub axis_pitch_noise_rad: f64,
    /// Standard deviation of the stop distance along the approach (m).
    pub standoff_jitter_m: f64,
    /// Standard deviation per joint of the random null-space bias around the
    /// target's noise-free pre-grasp configuration (rad).
    pub null_space_std_rad: Vec<f64>,
    /// Standard deviation per joint of the noise added to the IK solution
    /// (rad): the demonstrator's own final-pose variation (the wrist and
    /// elbow vary most in the real data); missing entries are 0.
    pub final_joint_noise_rad: Vec<f64>,
    /// Pre-grasp position accuracy demanded of IK (m).
    pub ik_tolerance_m: f64,
    /// Pre-grasp approach-axis accuracy demanded of IK (rad).
    pub ik_axis_tolerance_rad: f64,
    /// Gain of the IK's pull towards the null-space bias (per iteration, 0..1).
    pub null_space_gain: f64,
    /// Largest via-point deviation of the minimum-jerk profile (rad).
    pub via_deviation_rad: f64,
    /// Required clearance between robot and every obstacle along a demo (m).
    pub clearance_m: f64,
    /// Check the clearance at every `check_stride`-th sample (and the last).
    pub check_stride: usize,
    /// Draws of one demonstration before the target is given up.
    pub max_tries: usize,
    /// Draws of a whole configuration before generation stops with an error.
    pub max_config_tries: usize,
}

impl Default for DemoSettings {
    fn default() -> Self {
        DemoSettings {
            demos: 10,
            duration_s: 4.0,
            start_std_rad: 0.004,
            start_max_rad: 0.012,
            standoff_m: 0.10,
            position_noise_m: 0.002,
            axis_noise_rad: 0.01,
            axis_pitch_noise_rad: 0.015,
            standoff_jitter_m: 0.01,
            null_space_std_rad: vec![0.005, 0.005, 0.005, 0.005, 0.005, 0.005, 0.4],
            final_joint_noise_rad: vec![0.0, 0.04, 0.02, 0.5, 0.06, 0.25, 0.0],
            ik_tolerance_m: 0.003,
            ik_axis_tolerance_rad: 0.02,
            null_space_gain: 0.8,
            via_deviation_rad: 0.08,
            clearance_m: 0.005,
            check_stride: 3,
            max_tries: 40,
            max_config_tries: 30,
        }
    }
}

impl DemoSettings {
    /// Check every field; errors name `demos.<field>`.
    pub fn validate(&self, berry_radius_hi: f64) -> Result<()> {
        if self.demos < 2 {
            return Err(Error::invalid(
                "demos.demos",
                format!(
                    "need >= 2 demonstrations for a covariance, got {}",
                    self.demos
                ),
            ));
        }
        ensure_positive("demos.duration_s", self.duration_s)?;
        ensure_finite(
            "demos",
            &[
                self.start_std_rad,
                self.start_max_rad,
                self.position_noise_m,
                self.axis_noise_rad,
                self.via_deviation_rad,
            ],
        )?;
        for (name, v) in [
            ("start_std_rad", self.start_std_rad),
            ("position_noise_m", self.position_noise_m),
            ("axis_pitch_noise_rad", self.axis_pitch_noise_rad),
            ("standoff_jitter_m", self.standoff_jitter_m),
            ("axis_noise_rad", self.axis_noise_rad),
            ("via_deviation_rad", self.via_deviation_rad),
            ("clearance_m", self.clearance_m),
            ("ik_tolerance_m", self.ik_tolerance_m),
            ("ik_axis_tolerance_rad", self.ik_axis_tolerance_rad),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(
                    format!("demos.{name}"),
                    format!("must be a finite number >= 0, got {v}"),
                ));
            }
        }
        if !(self.null_space_gain.is_finite() && (0.0..=1.0).contains(&self.null_space_gain)) {
            return Err(Error::invalid(
                "demos.null_space_gain",
                format!("must be in [0, 1], got {}", self.null_space_gain),
            ));
        }
        if self.start_max_rad < self.start_std_rad {
            return Err(Error::invalid(
                "demos.start_max_rad",
                "must be >= start_std_rad",
            ));
        }
        for (name, values) in [
            ("null_space_std_rad", &self.null_space_std_rad),
            ("final_joint_noise_rad", &self.final_joint_noise_rad),
        ] {
            ensure_finite(&format!("demos.{name}"), values)?;
            if let Some(i) = values.iter().position(|v| *v < 0.0) {
                return Err(Error::invalid(format!("demos.{name}[{i}]"), "must be >= 0"));
            }
        }
        let needed = berry_extent(berry_radius_hi)
            + self.clearance_m
            + 3.0 * (self.position_noise_m + self.standoff_jitter_m);
        if !(self.standoff_m.is_finite() && self.standoff_m >= needed) {
            return Err(Error::invalid(
                "demos.standoff_m",
                format!(
                    "impossible clearance: the pre-grasp TCP must stop >= {needed:.3} m from the berry centre \
                     (largest berry half length + clearance_m + 3 x position noise), got {}",
                    self.standoff_m
                ),
            ));
        }
        if self.clearance_m > 0.05 {
            return Err(Error::invalid(
                "demos.clearance_m",
                format!(
                    "impossible clearance: must be <= 0.05 m in a berry cluster, got {}",
                    self.clearance_m
                ),
            ));
        }
        if self.check_stride == 0 {
            return Err(Error::invalid("demos.check_stride", "must be >= 1"));
        }
        if self.max_tries == 0 || self.max_config_tries == 0 {
            return Err(Error::invalid("demos.max_tries", "must be >= 1"));
        }
        Ok(())
    }
}
