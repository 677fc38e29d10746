//! Generator settings: one struct per concern (plant, camera, render,
//! demonstrations, split), each with a `Default` taken from REFERENCE.md and
//! a `validate` that names the offending field.

mod demo;

pub use demo::DemoSettings;

use crate::error::{ensure_finite, ensure_in_range};
use crate::perception::camera::CameraModel;
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

/// The gripper camera of the synthetic data: the [`CameraModel`] the
/// images are rendered through (and that the dataset records) and the
/// border a target's box keeps.
///
/// Its JSON is flat, as settings files have always written it (`width`,
/// `height`, `fx`, `fy`, `cx`, `cy`, `mount_back_m`, `mount_up_m`,
/// `border_px`; each optional, unknown keys refused): serde's `flatten`
/// cannot be combined with `deny_unknown_fields`, so the two impls below
/// read and write the camera model's fields by name.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraSettings {
    /// Intrinsics and mount.
    pub model: CameraModel,
    /// Pixels a target's box must keep from the image border.
    pub border_px: f64,
}

impl Default for CameraSettings {
    fn default() -> Self {
        CameraSettings {
            model: CameraModel::default(),
            border_px: 4.0,
        }
    }
}

impl CameraSettings {
    /// Check every field; errors name `camera.<field>`.
    pub fn validate(&self) -> Result<()> {
        self.model.intrinsics.validate("camera")?;
        self.model.validate_mount("camera")?;
        ensure_finite("camera.border_px", &[self.border_px])?;
        if self.border_px < 0.0 {
            return Err(Error::invalid("camera.border_px", "must be >= 0"));
        }
        Ok(())
    }
}

/// The keys of [`CameraSettings`]' JSON, in the order it is written.
const CAMERA_FIELDS: &[&str] = &[
    "width",
    "height",
    "fx",
    "fy",
    "cx",
    "cy",
    "mount_back_m",
    "mount_up_m",
    "border_px",
];

impl Serialize for CameraSettings {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let k = &self.model.intrinsics;
        let mut out = s.serialize_struct("CameraSettings", CAMERA_FIELDS.len())?;
        out.serialize_field("width", &k.width)?;
        out.serialize_field("height", &k.height)?;
        out.serialize_field("fx", &k.fx)?;
        out.serialize_field("fy", &k.fy)?;
        out.serialize_field("cx", &k.cx)?;
        out.serialize_field("cy", &k.cy)?;
        out.serialize_field("mount_back_m", &self.model.mount_back_m)?;
        out.serialize_field("mount_up_m", &self.model.mount_up_m)?;
        out.serialize_field("border_px", &self.border_px)?;
        out.end()
    }
}

impl<'de> Deserialize<'de> for CameraSettings {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        d.deserialize_struct("CameraSettings", CAMERA_FIELDS, CameraSettingsVisitor)
    }
}

/// Reads the flat camera keys over the defaults.
struct CameraSettingsVisitor;

impl<'de> serde::de::Visitor<'de> for CameraSettingsVisitor {
    type Value = CameraSettings;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("camera settings (an object with the keys ")?;
        f.write_str(&CAMERA_FIELDS.join(", "))?;
        f.write_str(")")
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(
        self,
        mut map: A,
    ) -> std::result::Result<CameraSettings, A::Error> {
        use serde::de::Error as _;
        let mut out = CameraSettings::default();
        let mut seen = Vec::new();
        while let Some(key) = map.next_key::<String>()? {
            let Some(&name) = CAMERA_FIELDS.iter().find(|f| **f == key) else {
                return Err(A::Error::unknown_field(&key, CAMERA_FIELDS));
            };
            if seen.contains(&name) {
                return Err(A::Error::duplicate_field(name));
            }
            seen.push(name);
            let model = &mut out.model;
            match name {
                "width" => model.intrinsics.width = map.next_value()?,
                "height" => model.intrinsics.height = map.next_value()?,
                "fx" => model.intrinsics.fx = map.next_value()?,
                "fy" => model.intrinsics.fy = map.next_value()?,
                "cx" => model.intrinsics.cx = map.next_value()?,
                "cy" => model.intrinsics.cy = map.next_value()?,
                "mount_back_m" => model.mount_back_m = map.next_value()?,
                "mount_up_m" => model.mount_up_m = map.next_value()?,
                _ => out.border_px = map.next_value()?,
            }
        }
        Ok(out)
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
    /// Intruders per target, placed across its demonstrated mean path after
    /// the demonstrations (0..=3; [`crate::synth::intruders`]).
    #[serde(skip_serializing_if = "is_zero")]
    pub intruders: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Most intruders per target.
pub const MAX_INTRUDERS: usize = 3;

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
        if self.intruders > MAX_INTRUDERS {
            return Err(Error::invalid(
                "intruders",
                format!("must be in 0..={MAX_INTRUDERS}, got {}", self.intruders),
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
    fn camera_settings_keep_their_flat_json() {
        // The bytes the settings files of every earlier dataset hold.
        let flat = r#"{"width":640,"height":480,"fx":615.0,"fy":615.0,"cx":320.0,"cy":240.0,"mount_back_m":0.1,"mount_up_m":0.07,"border_px":4.0}"#;
        let default = CameraSettings::default();
        assert_eq!(serde_json::to_string(&default).unwrap(), flat);
        let back: CameraSettings = serde_json::from_str(flat).unwrap();
        assert_eq!(back, default);
        assert_eq!(back.model, CameraModel::default());
        // Missing keys keep their defaults; the given ones land in the model.
        let some: CameraSettings =
            serde_json::from_str(r#"{"fx": 600, "width": 320, "mount_up_m": 0.05}"#).unwrap();
        assert_eq!(some.model.intrinsics.fx, 600.0);
        assert_eq!(some.model.intrinsics.width, 320);
        assert_eq!(some.model.intrinsics.fy, 615.0);
        assert_eq!(some.model.mount_up_m, 0.05);
        assert_eq!(some.border_px, 4.0);
    }

    #[test]
    fn camera_settings_refuse_unknown_repeated_and_mistyped_keys() {
        for (text, needle) in [
            (r#"{"fov": 1.0}"#, "unknown field `fov`"),
            (r#"{"intrinsics": {}}"#, "unknown field `intrinsics`"),
            (r#"{"fx": 600, "fx": 610}"#, "duplicate field `fx`"),
            (r#"{"width": 640.5}"#, "invalid type"),
            (r#"{"cx": "320"}"#, "invalid type"),
            (r#"[640, 480]"#, "invalid type"),
        ] {
            let e = serde_json::from_str::<CameraSettings>(text).unwrap_err();
            assert!(e.to_string().contains(needle), "{text}: {e}");
        }
        let e = CameraSettings {
            border_px: -1.0,
            ..CameraSettings::default()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.field(), Some("camera.border_px"));
        let mut bad = CameraSettings::default();
        bad.model.intrinsics.fx = 0.5;
        assert_eq!(bad.validate().unwrap_err().field(), Some("camera.fx"));
        assert_eq!(
            bad.model.validate("camera").unwrap_err().field(),
            Some("camera.intrinsics.fx")
        );
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
