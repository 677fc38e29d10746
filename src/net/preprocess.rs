//! Image preprocessing, the ONE path used by training, evaluation and
//! serving: validate the target box, paint it as a white filled rectangle
//! unless the caller already masked the image, resize to the network's
//! square input (exact area averaging, [`super::resize`]), normalise to
//! `[-1, 1]` (CHW, f32), and compute the cVAE
//! condition (box centre divided by the image width and height; the paper's
//! `/ [640, 480]` for the dataset's VGA images).

use super::resize::{box_pixels, resize_normalise, Paint};
use crate::{Error, Result};
use image::{Rgb, RgbImage};
use serde::{Deserialize, Serialize};

/// Preprocessing settings stored in the model config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreprocessConfig {
    /// Side of the square network input (the paper: 128).
    pub input_size: usize,
    /// Colour painted over the target box when the caller has not masked.
    pub box_colour: [u8; 3],
    /// Pixel value mapping: `x / 255 * scale + shift` (default maps to [-1, 1]).
    pub scale: f32,
    /// See `scale`.
    pub shift: f32,
}

impl Default for PreprocessConfig {
    fn default() -> Self {
        PreprocessConfig {
            input_size: 128,
            box_colour: [255, 255, 255],
            scale: 2.0,
            shift: -1.0,
        }
    }
}

impl PreprocessConfig {
    /// Check the settings; errors name the field.
    pub fn validate(&self) -> Result<()> {
        if !(8..=1024).contains(&self.input_size) {
            return Err(Error::invalid(
                "input_size",
                format!("must be in 8..=1024, got {}", self.input_size),
            ));
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(Error::invalid("scale", "must be a positive finite number"));
        }
        if !self.shift.is_finite() {
            return Err(Error::invalid("shift", "must be a finite number"));
        }
        Ok(())
    }
}

/// One preprocessed input: the image tensor data and the condition.
#[derive(Clone, Debug, PartialEq)]
pub struct Prepared {
    /// `3 x input_size x input_size`, channel-major, normalised.
    pub pixels: Vec<f32>,
    /// Box centre normalised by the image width and height.
    pub condition: [f32; 2],
    /// The target's depth (m, camera z of the berry centre), for models
    /// conditioned on it ([`crate::net::ModelConfig::depth_condition`]).
    pub depth_m: Option<f64>,
}

/// Centre (m) of the depth condition's normalisation.
pub const DEPTH_CONDITION_CENTRE_M: f64 = 0.45;

/// Scale (m) of the depth condition's normalisation.
pub const DEPTH_CONDITION_SCALE_M: f64 = 0.1;

impl Prepared {
    /// The condition vector a model with `depth_condition` reads: the box
    /// centre, then (when asked) the normalised depth; an error naming the
    /// depth input when the model needs depth and there is none.
    pub fn condition_values(&self, depth_condition: bool) -> Result<Vec<f32>> {
        let mut values = self.condition.to_vec();
        if depth_condition {
            let depth = self.depth_m.ok_or_else(|| {
                Error::invalid(
                    "depth",
                    "this model is conditioned on the target's depth: give it the berry's depth, or use a box-only model (models/rgb-only)",
                )
            })?;
            values.push(((depth - DEPTH_CONDITION_CENTRE_M) / DEPTH_CONDITION_SCALE_M) as f32);
        }
        Ok(values)
    }
}

/// Validate a target box `[x1, y1, x2, y2]` in pixels of a `width x height`
/// image: finite, inside the image, positive width and height.
pub fn validate_box(target_box: [f64; 4], width: u32, height: u32) -> Result<()> {
    for (i, v) in target_box.iter().enumerate() {
        if !v.is_finite() {
            return Err(Error::invalid(
                format!("box[{i}]"),
                format!("must be a finite number, got {v}"),
            ));
        }
    }
    let [x1, y1, x2, y2] = target_box;
    let (w, h) = (f64::from(width), f64::from(height));
    let inside = |name: &str, v: f64, hi: f64| {
        if (0.0..=hi).contains(&v) {
            Ok(())
        } else {
            Err(Error::invalid(
                name.to_string(),
                format!("{v} is outside the image (0..={hi})"),
            ))
        }
    };
    inside("box[0]", x1, w)?;
    inside("box[1]", y1, h)?;
    inside("box[2]", x2, w)?;
    inside("box[3]", y2, h)?;
    if x2 <= x1 || y2 <= y1 {
        return Err(Error::invalid(
            "box",
            format!("needs x1 < x2 and y1 < y2, got [{x1}, {y1}, {x2}, {y2}]"),
        ));
    }
    Ok(())
}

/// The cVAE condition: box centre divided by the image size.
pub fn box_condition(target_box: [f64; 4], width: u32, height: u32) -> [f32; 2] {
    let cx = 0.5 * (target_box[0] + target_box[2]) / f64::from(width);
    let cy = 0.5 * (target_box[1] + target_box[3]) / f64::from(height);
    [cx as f32, cy as f32]
}

/// Paint the box (pixels whose centres lie inside it) with `colour`.
pub fn paint_box(image: &mut RgbImage, target_box: [f64; 4], colour: [u8; 3]) {
    let (w, h) = image.dimensions();
    let [x0, y0, x1, y1] = box_pixels(target_box, w, h);
    for y in y0..y1 {
        for x in x0..x1 {
            image.put_pixel(x as u32, y as u32, Rgb(colour));
        }
    }
}

/// Preprocess one image with its target box (the single shared path): the
/// box is painted on the fly while area-averaging to the input size
/// ([`resize_normalise`]), so the caller's image is neither copied nor
/// changed.
pub fn prepare(
    image: &RgbImage,
    target_box: [f64; 4],
    mask_applied: bool,
    config: &PreprocessConfig,
) -> Result<Prepared> {
    let (width, height) = image.dimensions();
    if width == 0 || height == 0 {
        return Err(Error::invalid("image", "image is empty"));
    }
    validate_box(target_box, width, height)?;
    let paint = (!mask_applied).then(|| Paint {
        pixels: box_pixels(target_box, width, height),
        colour: config.box_colour,
    });
    Ok(Prepared {
        pixels: resize_normalise(image, config.input_size, paint, config.scale, config.shift),
        condition: box_condition(target_box, width, height),
        depth_m: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_validation_names_the_coordinate() {
        assert!(validate_box([10.0, 10.0, 20.0, 30.0], 640, 480).is_ok());
        let e = validate_box([10.0, f64::NAN, 20.0, 30.0], 640, 480).unwrap_err();
        assert_eq!(e.field(), Some("box[1]"));
        let e = validate_box([10.0, 10.0, 700.0, 30.0], 640, 480).unwrap_err();
        assert_eq!(e.field(), Some("box[2]"));
        let e = validate_box([20.0, 10.0, 10.0, 30.0], 640, 480).unwrap_err();
        assert_eq!(e.field(), Some("box"));
    }

    #[test]
    fn painting_covers_exactly_the_box_pixels() {
        let mut image = RgbImage::new(10, 8);
        paint_box(&mut image, [2.0, 1.0, 5.0, 4.0], [255, 255, 255]);
        let white = image.pixels().filter(|p| p.0 == [255, 255, 255]).count();
        assert_eq!(white, 3 * 3);
        assert_eq!(image.get_pixel(2, 1).0, [255, 255, 255]);
        assert_eq!(image.get_pixel(5, 1).0, [0, 0, 0]);
    }

    #[test]
    fn condition_is_centre_over_size_and_pixels_are_in_range() {
        let image = RgbImage::from_pixel(640, 480, Rgb([0, 128, 255]));
        let config = PreprocessConfig {
            input_size: 16,
            ..Default::default()
        };
        let p = prepare(&image, [300.0, 200.0, 340.0, 280.0], true, &config).unwrap();
        assert_eq!(p.condition, [0.5, 0.5]);
        assert_eq!(p.pixels.len(), 3 * 16 * 16);
        assert!((p.pixels[0] + 1.0).abs() < 1e-6);
        assert!((p.pixels[2 * 256] - 1.0).abs() < 1e-6);
        let masked = prepare(&image, [0.0, 0.0, 640.0, 480.0], false, &config).unwrap();
        assert!(masked.pixels.iter().all(|&v| (v - 1.0).abs() < 1e-6));
    }
}
