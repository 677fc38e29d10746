//! Image input for `/v1/plan`: base64 (optionally a `data:` URL) or raw
//! multipart bytes, PNG or JPEG only, with the pixel limit checked from the
//! image header before any pixel is decoded (decompression bombs), and
//! decoder limits set for the full decode.

use super::error::ApiError;
use axum::http::StatusCode;
use base64::Engine as _;
use image::{DynamicImage, ImageFormat, ImageReader, Limits};
use std::io::Cursor;

/// Decode base64 text (standard alphabet, padding optional, whitespace
/// ignored, an optional `data:image/...;base64,` prefix) into bytes.
pub fn decode_base64(field: &str, text: &str) -> Result<Vec<u8>, ApiError> {
    let payload = match text.strip_prefix("data:") {
        Some(rest) => match rest.split_once(',') {
            Some((meta, data)) if meta.ends_with(";base64") => data,
            _ => {
                return Err(malformed_base64(
                    field,
                    "a data URL must look like data:image/png;base64,...",
                ))
            }
        },
        None => text,
    };
    let compact: String = payload
        .chars()
        .filter(|c| !c.is_ascii_whitespace())
        .collect();
    let engine = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
    );
    engine
        .decode(compact.as_bytes())
        .map_err(|e| malformed_base64(field, &e.to_string()))
}

fn malformed_base64(field: &str, message: &str) -> ApiError {
    ApiError::new(
        StatusCode::BAD_REQUEST,
        "malformed_base64",
        format!("the image is not valid base64: {message}"),
    )
    .with_field(field)
}

/// Decode PNG or JPEG bytes with at most `max_pixels` pixels. Errors name
/// `field`: 415 `unsupported_image_format`, 413 `image_too_large`, 400
/// `malformed_image`.
pub fn decode_image(field: &str, bytes: &[u8], max_pixels: u64) -> Result<DynamicImage, ApiError> {
    let format = guess_format(field, bytes)?;
    let (width, height) = ImageReader::with_format(Cursor::new(bytes), format)
        .into_dimensions()
        .map_err(|e| malformed_image(field, &e.to_string()))?;
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 {
        return Err(malformed_image(field, "the image has no pixels"));
    }
    if pixels > max_pixels {
        return Err(ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "image_too_large",
            format!("the image has {width}x{height} = {pixels} pixels, more than the limit of {max_pixels}"),
        )
        .with_field(field));
    }
    let mut reader = ImageReader::with_format(Cursor::new(bytes), format);
    let mut limits = Limits::default();
    limits.max_image_width = Some(width);
    limits.max_image_height = Some(height);
    // RGBA f32 is the widest buffer a PNG/JPEG decoder produces, plus slack.
    limits.max_alloc = Some(pixels.saturating_mul(16).saturating_add(1 << 20));
    reader.limits(limits);
    reader
        .decode()
        .map_err(|e| malformed_image(field, &e.to_string()))
}

fn guess_format(field: &str, bytes: &[u8]) -> Result<ImageFormat, ApiError> {
    let unsupported = || {
        ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_image_format",
            "the image must be PNG or JPEG",
        )
        .with_field(field)
    };
    match image::guess_format(bytes) {
        Ok(f @ (ImageFormat::Png | ImageFormat::Jpeg)) => Ok(f),
        Ok(_) => Err(unsupported()),
        Err(_) if bytes.is_empty() => Err(malformed_image(field, "the image is empty")),
        Err(_) => Err(unsupported()),
    }
}

fn malformed_image(field: &str, message: &str) -> ApiError {
    ApiError::new(
        StatusCode::BAD_REQUEST,
        "malformed_image",
        format!("the image cannot be decoded: {message}"),
    )
    .with_field(field)
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageEncoder, RgbImage};

    fn png(width: u32, height: u32) -> Vec<u8> {
        let img = RgbImage::from_fn(width, height, |x, y| image::Rgb([x as u8, y as u8, 7]));
        let mut out = Vec::new();
        image::codecs::png::PngEncoder::new(&mut out)
            .write_image(img.as_raw(), width, height, image::ExtendedColorType::Rgb8)
            .unwrap();
        out
    }

    #[test]
    fn png_roundtrips_through_base64_and_data_url() {
        let bytes = png(8, 6);
        let b64 = base64::engine::general_purpose::STANDARD.encode(&bytes);
        for text in [
            b64.clone(),
            format!("data:image/png;base64,{b64}"),
            b64.trim_end_matches('=').to_string(),
        ] {
            let raw = decode_base64("image", &text).unwrap();
            let img = decode_image("image", &raw, 1000).unwrap();
            assert_eq!((img.width(), img.height()), (8, 6));
            assert_eq!(img.to_rgb8().get_pixel(3, 2).0, [3, 2, 7]);
        }
    }

    /// CRC-32 (IEEE) as PNG chunks use it.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn pixel_limit_is_checked_from_the_header() {
        // A PNG header claiming 60000 x 60000 pixels followed by garbage: the
        // limit trips before any decode is attempted.
        let mut bomb = png(4, 4);
        bomb[16..20].copy_from_slice(&60000u32.to_be_bytes());
        bomb[20..24].copy_from_slice(&60000u32.to_be_bytes());
        let crc = crc32(&bomb[12..29]);
        bomb[29..33].copy_from_slice(&crc.to_be_bytes());
        let e = decode_image("image", &bomb, 4096 * 4096).unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (413, "image_too_large"));
        let e = decode_image("image", &png(10, 10), 99).unwrap_err();
        assert_eq!(e.status.as_u16(), 413);
        assert!(decode_image("image", &png(10, 10), 100).is_ok());
    }

    #[test]
    fn bad_inputs_are_4xx_naming_the_field() {
        let e = decode_base64("image_base64", "not base64 !!").unwrap_err();
        assert_eq!(
            (e.status.as_u16(), e.field.as_deref()),
            (400, Some("image_base64"))
        );
        let e = decode_base64("image", "data:image/png,abc").unwrap_err();
        assert_eq!(e.status.as_u16(), 400);
        let e = decode_image("image", b"GIF89a......", 100).unwrap_err();
        assert_eq!(e.status.as_u16(), 415);
        let e = decode_image("image", b"", 100).unwrap_err();
        assert_eq!(e.status.as_u16(), 400);
        let mut truncated = png(16, 16);
        truncated.truncate(40);
        let e = decode_image("image", &truncated, 1000).unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (400, "malformed_image"));
    }
}
