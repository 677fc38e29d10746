//! Generator settings: one struct per concern (plant, camera, render,
//! demonstrations, split), each with a `Default` taken from REFERENCE.md and
//! a `validate` that names the offending field.

mod demo;

pub use demo::DemoSettings;

use crate::error::{ensure_finite, ensure_in_range};
use crate::perception::camera::{CameraModel, Intrinsics};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// An axis-aligned box in the robot base frame (m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Lower corner `[x, y, z]`.
    pub min: [f64; 3],
    /// Upper corner `[x, y, z]`.
    pub max: [f64; 3],
}

impl Region {
    /// The region the real demonstrations occupy (REFERENCE.md).
    pub fn reference() -> Region {
        Region {
            min: [0.62, -0.20, 0.62],
            max: [0.70, 0.17, 0.84],
        }
    }

    /// Centre of the box.
    pub fn center(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| 0.5 * (self.min[i] + self.max[i]))
    }

    /// The 8 corners.
    pub fn corners(&self) -> Vec<[f64; 3]> {
        (0..8)
            .map(|k| {
                [0, 1, 2].map(|i| {
                    if k >> i & 1 == 0 {
                        self.min[i]
                    } else {
                        self.max[i]
                    }
                })
            })
            .collect()
    }

    /// Whether `p` lies inside (inclusive).
    pub fn contains(&self, p: &[f64; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    /// Finite, ordered corners.
    pub fn validate(&self, field: &str) -> Result<()> {
        ensure_finite(&format!("{field}.min"), &self.min)?;
        ensure_finite(&format!("{field}.max"), &self.max)?;
        for i in 0..3 {
            if self.min[i] > self.max[i] {
                return Err(Error::invalid(
                    format!("{field}.max[{i}]"),
                    format!("must be >= min[{i}] = {}, got {}", self.min[i], self.max[i]),
                ));
            }
        }
        Ok(())
    }
}

/// A closed interval `[lo, hi]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Range {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
}

impl Range {
    /// `[lo, hi]`.
    pub const fn new(lo: f64, hi: f64) -> Range {
        Range { lo, hi }
    }

    /// Finite, ordered, and `lo >= min_lo`.
    pub fn validate(&self, field: &str, min_lo: f64) -> Result<()> {
        ensure_finite(field, &[self.lo, self.hi])?;
        if self.lo < min_lo {
            return Err(Error::invalid(
                format!("{field}.lo"),
                format!("must be >= {min_lo}, got {}", self.lo),
            ));
        }
        if self.hi < self.lo {
            return Err(Error::invalid(
                format!("{field}.hi"),
                format!("must be >= lo = {}, got {}", self.lo, self.hi),
            ));
        }
        Ok(())
    }

    /// A uniform draw (returns `lo` for an empty interval).
    pub fn sample(&self, rng: &mut impl rand::Rng) -> f64 {
        if self.hi > self.lo {
            rng.gen_range(self.lo..=self.hi)
        } else {
            self.lo
        }
    }
}

/// What [`PlantSettings::region`] bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionAnchor {
    /// The pre-grasp TCP points: each berry lies `demos.standoff_m` further
    /// along the ray from the home TCP, so the demonstrations END in the
    /// region, as the real ones do (the default).
    #[default]
    PreGrasp,
    /// The berry centres themselves (demos end `standoff_m` short of it).
    Berry,
}

/// What a plant configuration looks like.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantSettings {
    /// Where the targets lie (base frame); see [`RegionAnchor`].
    pub region: Region,
    /// Whether `region` bounds the pre-grasp points (default) or the berries.
    pub region_anchor: RegionAnchor,
    /// Distance between any two berry centres of one configuration (m).
    pub spacing_m: Range,
    /// Shoulder (largest) radius of a berry (m).
    pub berry_radius_m: Range,
    /// Probability that a berry is unripe (green/white instead of red).
    pub unripe_fraction: f64,
    /// Number of trifoliate leaves per plant.
    pub leaves: Range,
    /// Leaflet length (m).
    pub leaflet_length_m: Range,
    /// Probability of a tray (gutter) box above the berries.
    pub tray_probability: f64,
    /// Radius of stems and peduncles (m).
    pub stem_radius_m: Range,
    /// Draws of one berry position before the sampler gives up.
    pub max_berry_tries: usize,
}

impl Default for PlantSettings {
    fn default() -> Self {
        PlantSettings {
            region: Region::reference(),
            region_anchor: RegionAnchor::PreGrasp,
            spacing_m: Range::new(0.05, 0.20),
            berry_radius_m: Range::new(0.011, 0.016),
            unripe_fraction: 0.2,
            leaves: Range::new(3.0, 6.0),
            leaflet_length_m: Range::new(0.035, 0.06),
            tray_probability: 0.7,
            stem_radius_m: Range::new(0.0015, 0.0025),
            max_berry_tries: 400,
        }
    }
}

impl PlantSettings {
    /// Check every field; errors name `plant.<field>`.
    pub fn validate(&self) -> Result<()> {
        self.region.validate("plant.region")?;
        self.spacing_m.validate("plant.spacing_m", 0.0)?;
        self.berry_radius_m
            .validate("plant.berry_radius_m", 0.003)?;
        if self.berry_radius_m.hi > 0.04 {
            return Err(Error::invalid(
                "plant.berry_radius_m.hi",
                format!("must be <= 0.04 m, got {}", self.berry_radius_m.hi),
            ));
        }
        probability("plant.unripe_fraction", self.unripe_fraction)?;
        probability("plant.tray_probability", self.tray_probability)?;
        self.leaves.validate("plant.leaves", 0.0)?;
        self.leaflet_length_m
            .validate("plant.leaflet_length_m", 0.005)?;
        self.stem_radius_m.validate("plant.stem_radius_m", 0.0005)?;
        let min_gap = 2.0 * berry_extent(self.berry_radius_m.hi);
        if self.spacing_m.lo < min_gap {
            return Err(Error::invalid(
                "plant.spacing_m.lo",
                format!(
                    "berries would overlap: must be >= {min_gap:.3} m (twice the largest berry's half length), got {}",
                    self.spacing_m.lo
                ),
            ));
        }
        if self.max_berry_tries == 0 {
            return Err(Error::invalid("plant.max_berry_tries", "must be >= 1"));
        }
        Ok(())
    }
}

/// Half length of a berry of shoulder radius `r` along its axis, measured
/// from its centre (used for spacing and clearance checks).
pub fn berry_extent(r: f64) -> f64 {
    1.45 * r
}

fn probability(field: &str, p: f64) -> Result<()> {
    if p.is_finite() && (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(Error::invalid(field, format!("must be in [0, 1], got {p}")))
    }
}

/// The gripper camera: intrinsics and its mount on the gripper.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSettings {
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Focal length x (px).
    pub fx: f64,
    /// Focal length y (px).
    pub fy: f64,
    /// Principal point x (px).
    pub cx: f64,
    /// Principal point y (px).
    pub cy: f64,
    /// Camera position behind the TCP along the gripper axis (m).
    pub mount_back_m: f64,
    /// Camera position above the gripper axis (m), towards world up.
    pub mount_up_m: f64,
    /// Pixels a target's box must keep from the image border.
    pub border_px: f64,
}

impl Default for CameraSettings {
    fn default() -> Self {
        let m = CameraModel::default();
        let k = m.intrinsics;
        CameraSettings {
            width: k.width,
            height: k.height,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            mount_back_m: m.mount_back_m,
            mount_up_m: m.mount_up_m,
            border_px: 4.0,
        }
    }
}

impl CameraSettings {
    /// The camera these settings describe.
    pub fn model(&self) -> CameraModel {
        CameraModel {
            intrinsics: Intrinsics {
                width: self.width,
                height: self.height,
                fx: self.fx,
                fy: self.fy,
                cx: self.cx,
                cy: self.cy,
            },
            mount_back_m: self.mount_back_m,
            mount_up_m: self.mount_up_m,
        }
    }

    /// Check every field; errors name `camera.<field>`.
    pub fn validate(&self) -> Result<()> {
        self.model().validate("camera")?;
        ensure_finite("camera.border_px", &[self.border_px])?;
        if self.border_px < 0.0 {
            return Err(Error::invalid("camera.border_px", "must be >= 0"));
        }
        Ok(())
    }
}

/// The depth channel: an aligned z-depth image per target with a RealSense
/// D435i-like error model (see [`crate::synth::render::depth`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthSettings {
    /// Write a depth image per target (`depth/<id>.png`).
    pub enabled: bool,
    /// Apply the error model (off: the renderer's exact depth, quantised).
    pub noise: bool,
    /// Range noise `σ(z) = rms_per_m2 · z²` (1/m).
    pub rms_per_m2: f64,
    /// Fraction of pixels with no return anywhere.
    pub holes: f64,
    /// A depth step between 4-neighbours larger than this (m) is an edge.
    pub edge_jump_m: f64,
    /// Probability that a pixel on an edge has no return.
    pub edge_dropout: f64,
    /// Nearest depth with a return (m).
    pub min_range_m: f64,
    /// Farthest depth with a return (m); the background lies beyond.
    pub max_range_m: f64,
    /// Metres per 16-bit unit (0.001: millimetres).
    pub scale_m: f64,
}

impl Default for DepthSettings {
    fn default() -> Self {
        DepthSettings {
            enabled: true,
            noise: true,
            rms_per_m2: 0.004,
            holes: 0.03,
            edge_jump_m: 0.01,
            edge_dropout: 0.5,
            min_range_m: 0.105,
            max_range_m: 1.5,
            scale_m: crate::perception::depth::DEFAULT_DEPTH_SCALE_M,
        }
    }
}

impl DepthSettings {
    /// Check every field; errors name `depth.<field>`.
    pub fn validate(&self) -> Result<()> {
        let checks = [
            ("rms_per_m2", self.rms_per_m2, 0.0, 0.1),
            ("holes", self.holes, 0.0, 0.5),
            ("edge_jump_m", self.edge_jump_m, 1e-4, 1.0),
            ("edge_dropout", self.edge_dropout, 0.0, 1.0),
            ("min_range_m", self.min_range_m, 0.0, 10.0),
            ("max_range_m", self.max_range_m, 0.01, 60.0),
            ("scale_m", self.scale_m, 1e-5, 0.01),
        ];
        for (name, v, lo, hi) in checks {
            ensure_in_range(&format!("depth.{name}"), v, lo, hi)?;
        }
        if self.min_range_m >= self.max_range_m {
            return Err(Error::invalid(
                "depth.min_range_m",
                "must be below depth.max_range_m",
            ));
        }
        Ok(())
    }
}

/// Appearance randomisation of the renderer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RenderSettings {
    /// Draw seeds on the berries.
    pub seeds: bool,
    /// Standard deviation of the per-pixel sensor noise (0..255 scale).
    pub noise_std: Range,
    /// Relative jitter of every material colour.
    pub color_jitter: f64,
    /// Intensity of the key light.
    pub light_intensity: Range,
    /// Ambient light level.
    pub ambient: Range,
    /// Apply a 3x3 optical blur (soft camera).
    pub blur: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            seeds: true,
            noise_std: Range::new(1.5, 5.0),
            color_jitter: 0.08,
            light_intensity: Range::new(0.65, 1.05),
            ambient: Range::new(0.25, 0.45),
            blur: true,
        }
    }
}

impl RenderSettings {
    /// Check every field; errors name `render.<field>`.
    pub fn validate(&self) -> Result<()> {
        self.noise_std.validate("render.noise_std", 0.0)?;
        self.light_intensity
            .validate("render.light_intensity", 0.0)?;
        self.ambient.validate("render.ambient", 0.0)?;
        probability("render.color_jitter", self.color_jitter)
    }
}

/// Train / validation / test split fractions (by configuration).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SplitSettings {
    /// Fraction of configurations for validation.
    pub val_fraction: f64,
    /// Fraction of configurations for testing.
    pub test_fraction: f64,
}

impl Default for SplitSettings {
    fn default() -> Self {
        SplitSettings {
            val_fraction: 0.1,
            test_fraction: 0.1,
        }
    }
}

impl SplitSettings {
    /// Fractions in [0, 1) with a non-empty training share.
    pub fn validate(&self) -> Result<()> {
        probability("split.val_fraction", self.val_fraction)?;
        probability("split.test_fraction", self.test_fraction)?;
        if self.val_fraction + self.test_fraction >= 1.0 {
            return Err(Error::invalid(
                "split",
                "val_fraction + test_fraction must be < 1",
            ));
        }
        Ok(())
    }
}

/// Every generator setting (written into the manifest).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthSettings {
    /// Plant configurations to draw.
    pub configs: usize,
    /// Berries (= targets) per configuration.
    pub berries_per_config: usize,
    /// Plant appearance and placement.
    pub plant: PlantSettings,
    /// Gripper camera.
    pub camera: CameraSettings,
    /// Renderer randomisation.
    pub render: RenderSettings,
    /// The depth channel and its error model.
    pub depth: DepthSettings,
    /// Demonstrations.
    pub demos: DemoSettings,
    /// Dataset split.
    pub split: SplitSettings,
}

impl SynthSettings {
    /// Defaults with `configs` x `berries_per_config` targets.
    pub fn new(configs: usize, berries_per_config: usize) -> SynthSettings {
        SynthSettings {
            configs,
            berries_per_config,
            ..Default::default()
        }
    }

    /// Check every setting (geometry-free checks; reachability and
    /// visibility are checked by [`crate::synth::generate::preflight`]).
    pub fn validate(&self) -> Result<()> {
        if self.configs == 0 || self.configs > 100_000 {
            return Err(Error::invalid(
                "configs",
                format!("must be in 1..=100000, got {}", self.configs),
            ));
        }
        if self.berries_per_config == 0 || self.berries_per_config > 20 {
            return Err(Error::invalid(
                "berries_per_config",
                format!(
                    "must be in 1..=20 (the issue asks for 3-8), got {}",
                    self.berries_per_config
                ),
            ));
        }
        self.plant.validate()?;
        self.camera.validate()?;
        self.render.validate()?;
        self.depth.validate()?;
        self.demos.validate(self.plant.berry_radius_m.hi)?;
        self.split.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        SynthSettings::new(2, 5).validate().unwrap();
    }

    #[test]
    fn zero_berries_is_rejected_by_name() {
        let e = SynthSettings::new(2, 0).validate().unwrap_err();
        assert_eq!(e.field(), Some("berries_per_config"));
    }

    #[test]
    fn impossible_clearance_is_rejected() {
        let mut s = SynthSettings::new(2, 3);
        s.demos.standoff_m = 0.01;
        assert_eq!(s.validate().unwrap_err().field(), Some("demos.standoff_m"));
        let mut s = SynthSettings::new(2, 3);
        s.demos.clearance_m = 0.2;
        assert!(s.validate().is_err());
    }

    #[test]
    fn inverted_or_nan_region_is_rejected() {
        let mut s = SynthSettings::new(2, 3);
        s.plant.region.max[1] = -0.5;
        assert_eq!(
            s.validate().unwrap_err().field(),
            Some("plant.region.max[1]")
        );
        s.plant.region = Region::reference();
        s.plant.region.min[2] = f64::NAN;
        assert_eq!(
            s.validate().unwrap_err().field(),
            Some("plant.region.min[2]")
        );
    }

    #[test]
    fn region_corners_are_inside() {
        let r = Region::reference();
        let corners = r.corners();
        assert_eq!(corners.len(), 8);
        assert!(corners.iter().all(|c| r.contains(c)));
        assert!(r.contains(&r.center()));
    }
}
