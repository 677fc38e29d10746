//! The latest inputs and the rule that matches them to a target: the
//! newest colour image, the depth image whose stamp is closest to it
//! (within `stamp_tolerance_s`), the newest camera info, joint state and
//! camera pose. A target arriving when the colour image or the joint
//! state is older than `max_input_age_s` (by the node's clock, at
//! receipt), or when no depth image pairs with the colour one, is refused
//! with the reason; nothing is planned from it.

use super::msg::{CameraInfo, Image, JointState, Time, TransformStamped};
use crate::{Error, Result};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Depth images kept to pair with a colour image.
pub const DEPTH_HISTORY: usize = 8;

/// A message and when the node received it.
#[derive(Clone, Debug)]
pub struct Received<M> {
    /// The message.
    pub msg: M,
    /// Receipt time (the node's monotonic clock).
    pub at: Instant,
}

/// How inputs are matched.
#[derive(Clone, Copy, Debug)]
pub struct MatchRules {
    /// Largest stamp difference between a colour and a depth image.
    pub stamp_tolerance_s: f64,
    /// Oldest input accepted when a target arrives.
    pub max_age: Duration,
}

/// The inputs one plan is made from.
#[derive(Clone, Debug)]
pub struct Matched {
    /// The colour image.
    pub color: Image,
    /// The depth image paired with it.
    pub depth: Image,
    /// The newest camera info, if any came.
    pub camera_info: Option<CameraInfo>,
    /// The newest joint state.
    pub joint_state: JointState,
    /// The newest camera pose, if any came.
    pub camera_pose: Option<TransformStamped>,
}

/// The newest input of every kind.
#[derive(Debug, Default)]
pub struct LatestInputs {
    color: Option<Received<Image>>,
    depths: VecDeque<Received<Image>>,
    camera_info: Option<Received<CameraInfo>>,
    joint_state: Option<Received<JointState>>,
    camera_pose: Option<Received<TransformStamped>>,
}

impl LatestInputs {
    /// Keep a colour image.
    pub fn color(&mut self, msg: Image, at: Instant) {
        self.color = Some(Received { msg, at });
    }

    /// Keep a depth image (the last [`DEPTH_HISTORY`]).
    pub fn depth(&mut self, msg: Image, at: Instant) {
        if self.depths.len() == DEPTH_HISTORY {
            self.depths.pop_front();
        }
        self.depths.push_back(Received { msg, at });
    }

    /// Keep a camera info.
    pub fn camera_info(&mut self, msg: CameraInfo, at: Instant) {
        self.camera_info = Some(Received { msg, at });
    }

    /// Keep a joint state.
    pub fn joint_state(&mut self, msg: JointState, at: Instant) {
        self.joint_state = Some(Received { msg, at });
    }

    /// Keep a camera pose.
    pub fn camera_pose(&mut self, msg: TransformStamped, at: Instant) {
        self.camera_pose = Some(Received { msg, at });
    }

    /// The inputs for a target that arrived at `now`, or why there are
    /// none (the error names the topic).
    pub fn matched(&self, now: Instant, rules: &MatchRules) -> Result<Matched> {
        let color = fresh(self.color.as_ref(), "color", now, rules.max_age)?;
        let joint_state = fresh(
            self.joint_state.as_ref(),
            "joint_states",
            now,
            rules.max_age,
        )?;
        let stamp = color.header.stamp;
        // Newest first: of two depth images as close, the newer pairs.
        let depth = self
            .depths
            .iter()
            .rev()
            .map(|d| (stamp_gap(&d.msg.header.stamp, &stamp), d))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .ok_or_else(|| Error::invalid("depth", "no depth image received yet"))?;
        if depth.0 > rules.stamp_tolerance_s {
            return Err(Error::invalid(
                "depth",
                format!(
                    "no depth image within {} s of the colour image's stamp {:.6} s \
                     (the closest is {:.6} s away)",
                    rules.stamp_tolerance_s,
                    stamp.seconds(),
                    depth.0
                ),
            ));
        }
        Ok(Matched {
            color: color.clone(),
            depth: depth.1.msg.clone(),
            camera_info: self.camera_info.as_ref().map(|c| c.msg.clone()),
            joint_state: joint_state.clone(),
            camera_pose: self.camera_pose.as_ref().map(|c| c.msg.clone()),
        })
    }
}

/// `|a - b|` in seconds.
fn stamp_gap(a: &Time, b: &Time) -> f64 {
    let ns = |t: &Time| i64::from(t.sec) * 1_000_000_000 + i64::from(t.nanosec);
    (ns(a) - ns(b)).unsigned_abs() as f64 * 1e-9
}

/// The message of `slot` if it came no longer than `max_age` before `now`.
fn fresh<'a, M>(
    slot: Option<&'a Received<M>>,
    topic: &str,
    now: Instant,
    max_age: Duration,
) -> Result<&'a M> {
    let r = slot.ok_or_else(|| Error::invalid(topic, "nothing received yet"))?;
    let age = now.saturating_duration_since(r.at);
    if age > max_age {
        return Err(Error::invalid(
            topic,
            format!(
                "stale: received {:.3} s before the target (max_input_age_s {})",
                age.as_secs_f64(),
                max_age.as_secs_f64()
            ),
        ));
    }
    Ok(&r.msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamped(sec: i32, nanosec: u32) -> Image {
        let mut m = Image::default();
        m.header.stamp = Time { sec, nanosec };
        m
    }

    const RULES: MatchRules = MatchRules {
        stamp_tolerance_s: 0.02,
        max_age: Duration::from_secs(1),
    };

    #[test]
    fn the_closest_depth_within_the_tolerance_pairs_with_the_colour() {
        let t0 = Instant::now();
        let mut inputs = LatestInputs::default();
        assert_eq!(
            inputs.matched(t0, &RULES).unwrap_err().field(),
            Some("color")
        );
        inputs.color(stamped(10, 500_000_000), t0);
        assert_eq!(
            inputs.matched(t0, &RULES).unwrap_err().field(),
            Some("joint_states")
        );
        inputs.joint_state(JointState::default(), t0);
        assert_eq!(
            inputs.matched(t0, &RULES).unwrap_err().field(),
            Some("depth")
        );
        inputs.depth(stamped(10, 470_000_000), t0);
        // 30 ms away: refused, with the gap in the reason.
        let e = inputs.matched(t0, &RULES).unwrap_err();
        assert!(e.to_string().contains("0.030000"), "{e}");
        inputs.depth(stamped(10, 510_000_000), t0);
        inputs.depth(stamped(10, 540_000_000), t0);
        let m = inputs.matched(t0, &RULES).unwrap();
        assert_eq!(
            m.depth.header.stamp,
            Time {
                sec: 10,
                nanosec: 510_000_000
            }
        );
        // Of two as close, the newer.
        let mut newer = stamped(10, 510_000_000);
        newer.encoding = "16UC1".into();
        inputs.depth(newer, t0);
        assert_eq!(inputs.matched(t0, &RULES).unwrap().depth.encoding, "16UC1");
        // Across a second boundary.
        inputs.color(stamped(11, 5_000_000), t0);
        inputs.depth(stamped(10, 995_000_000), t0);
        let m = inputs.matched(t0, &RULES).unwrap();
        assert_eq!(
            m.depth.header.stamp,
            Time {
                sec: 10,
                nanosec: 995_000_000
            }
        );
    }

    #[test]
    fn stale_inputs_are_refused_and_the_history_is_bounded() {
        let t0 = Instant::now();
        let mut inputs = LatestInputs::default();
        inputs.color(stamped(1, 0), t0);
        inputs.joint_state(JointState::default(), t0 + Duration::from_millis(1500));
        for _ in 0..3 * DEPTH_HISTORY {
            inputs.depth(stamped(1, 0), t0);
        }
        assert_eq!(inputs.depths.len(), DEPTH_HISTORY);
        let later = t0 + Duration::from_millis(1600);
        let e = inputs.matched(later, &RULES).unwrap_err();
        assert_eq!(e.field(), Some("color"));
        assert!(e.to_string().contains("stale"), "{e}");
        inputs.color(stamped(1, 0), later);
        inputs.matched(later, &RULES).unwrap();
    }
}
