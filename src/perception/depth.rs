//! Aligned z-depth images: per pixel the depth along the camera's optical
//! axis, stored as 16-bit integers times a scale (RealSense convention:
//! millimetres, `scale_m = 0.001`; 0 = no return), the same size and
//! intrinsics as the colour image. 16-bit single-channel PNG in and out.

use crate::{Error, Result};
use std::io::Cursor;

/// Depth scale of the RealSense convention (m per unit).
pub const DEFAULT_DEPTH_SCALE_M: f64 = 0.001;

/// A z-depth image (row-major, 0 = no return).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    width: u32,
    height: u32,
    scale_m: f64,
    data: Vec<u16>,
}

impl DepthImage {
    /// A depth image from raw units; `field` names the input in errors.
    pub fn new(width: u32, height: u32, scale_m: f64, data: Vec<u16>, field: &str) -> Result<Self> {
        check_scale(scale_m, field)?;
        if width == 0 || height == 0 || data.len() != width as usize * height as usize {
            return Err(Error::invalid(
                field,
                format!(
                    "{} depth values do not make a {width}x{height} image",
                    data.len()
                ),
            ));
        }
        Ok(DepthImage {
            width,
            height,
            scale_m,
            data,
        })
    }

    /// Quantise depths in metres (non-finite, non-positive or beyond the
    /// 16-bit range: no return).
    pub fn from_metres(width: u32, height: u32, scale_m: f64, metres: &[f64]) -> Result<Self> {
        let units = metres
            .iter()
            .map(|&z| {
                let u = (z / scale_m).round();
                if z.is_finite() && u >= 1.0 && u <= u16::MAX as f64 {
                    u as u16
                } else {
                    0
                }
            })
            .collect();
        DepthImage::new(width, height, scale_m, units, "depth")
    }

    /// Decode a 16-bit single-channel PNG; `field` names the input in errors.
    pub fn decode_png(bytes: &[u8], scale_m: f64, field: &str) -> Result<Self> {
        check_scale(scale_m, field)?;
        let image =
            image::load_from_memory_with_format(bytes, image::ImageFormat::Png).map_err(|e| {
                Error::invalid(
                    field,
                    format!("not a readable PNG: {}", super::image_error_words(&e)),
                )
            })?;
        let (width, height) = (image.width(), image.height());
        match image {
            image::DynamicImage::ImageLuma16(buffer) => {
                DepthImage::new(width, height, scale_m, buffer.into_raw(), field)
            }
            other => Err(Error::invalid(
                field,
                format!(
                    "must be a 16-bit single-channel PNG (depth units), got {:?}",
                    other.color()
                ),
            )),
        }
    }

    /// Encode as a 16-bit single-channel PNG.
    pub fn encode_png(&self) -> Result<Vec<u8>> {
        let buffer: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
            image::ImageBuffer::from_raw(self.width, self.height, self.data.clone())
                .ok_or_else(|| Error::Numerical("depth buffer size mismatch".into()))?;
        let mut out = Cursor::new(Vec::new());
        image::DynamicImage::ImageLuma16(buffer)
            .write_to(&mut out, image::ImageFormat::Png)
            .map_err(|e| Error::Numerical(format!("cannot encode the depth PNG: {e}")))?;
        Ok(out.into_inner())
    }

    /// Check that the depth image is aligned with a `width` x `height`
    /// colour image (same size); the error names `field`.
    pub fn check_aligned(&self, width: u32, height: u32, field: &str) -> Result<()> {
        if (self.width, self.height) == (width, height) {
            return Ok(());
        }
        Err(Error::invalid(
            field,
            format!(
                "the depth image is {}x{}, the image {width}x{height}: they must be aligned, same size",
                self.width, self.height
            ),
        ))
    }

    /// Image width (px).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height (px).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Metres per unit.
    pub fn scale_m(&self) -> f64 {
        self.scale_m
    }

    /// Raw units, row-major.
    pub fn units(&self) -> &[u16] {
        &self.data
    }

    /// Depth (m) at pixel `(x, y)`; `None` for no return or outside.
    pub fn metres(&self, x: u32, y: u32) -> Option<f64> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let u = self.data[y as usize * self.width as usize + x as usize];
        (u > 0).then_some(u as f64 * self.scale_m)
    }

    /// Fraction of pixels with a return.
    pub fn valid_fraction(&self) -> f64 {
        self.data.iter().filter(|&&u| u > 0).count() as f64 / self.data.len() as f64
    }
}

/// A depth scale (m per unit) must be finite, > 0 and <= 1; errors name
/// `field`.
pub fn check_scale(scale_m: f64, field: &str) -> Result<()> {
    if scale_m.is_finite() && scale_m > 0.0 && scale_m <= 1.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("depth scale {scale_m} m per unit must be finite, > 0 and <= 1"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_is_exact() {
        let data: Vec<u16> = (0..12u16).map(|i| i * 5000 + (i % 3)).collect();
        let d = DepthImage::new(4, 3, 0.001, data.clone(), "depth").unwrap();
        let back = DepthImage::decode_png(&d.encode_png().unwrap(), 0.001, "depth").unwrap();
        assert_eq!(back, d);
        assert_eq!(back.metres(1, 0), Some(5.001));
        assert_eq!(back.metres(0, 0), None);
        assert_eq!(back.metres(4, 0), None);
    }

    #[test]
    fn bad_inputs_name_the_field() {
        let e = DepthImage::new(2, 2, 0.001, vec![1; 3], "depth_base64").unwrap_err();
        assert!(e.to_string().contains("depth_base64"), "{e}");
        let e = DepthImage::new(2, 2, f64::NAN, vec![1; 4], "depth_scale_m").unwrap_err();
        assert!(e.to_string().contains("depth_scale_m"), "{e}");
        let e = DepthImage::decode_png(b"not a png", 0.001, "depth").unwrap_err();
        assert!(e.to_string().contains("PNG"), "{e}");
        // An 8-bit PNG is not a depth image.
        let rgb = image::RgbImage::new(2, 2);
        let mut bytes = Cursor::new(Vec::new());
        rgb.write_to(&mut bytes, image::ImageFormat::Png).unwrap();
        let e = DepthImage::decode_png(bytes.get_ref(), 0.001, "depth").unwrap_err();
        assert!(e.to_string().contains("16-bit"), "{e}");
    }

    #[test]
    fn metres_quantise_and_drop_what_has_no_return() {
        let d =
            DepthImage::from_metres(5, 1, 0.001, &[0.4567, f64::NAN, -1.0, 70.0, f64::INFINITY])
                .unwrap();
        assert_eq!(d.units(), &[457, 0, 0, 0, 0]);
        assert!((d.valid_fraction() - 0.2).abs() < 1e-12);
    }
}
