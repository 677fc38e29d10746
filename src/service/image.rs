//! Image input for `/v1/plan`: base64 (optionally a `data:` URL) or raw
//! multipart bytes, PNG or JPEG only, with the pixel limit checked from the
//! image header before any pixel is decoded (decompression bombs), truncated
//! JPEGs refused, decoder limits set for the full decode, and the decoded
//! bytes held at once across requests bounded ([`DecodeBudget`]).

use super::error::ApiError;
use axum::http::StatusCode;
use base64::Engine as _;
use image::{DynamicImage, ImageDecoder, ImageFormat, ImageReader, Limits};
use std::io::Cursor;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

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
/// `malformed_image` (also for a JPEG cut short: one that does not end with
/// its end-of-image marker, which the decoder itself would fill in grey).
pub fn decode_image(field: &str, bytes: &[u8], max_pixels: u64) -> Result<DynamicImage, ApiError> {
    let header = read_header(field, bytes, max_pixels)?;
    decode_with(field, bytes, &header)
}

/// [`decode_image`] holding room for the decoded bytes in `budget` until
/// `deadline` (see [`DecodeBudget`]); the reservation must live as long as
/// the image.
pub fn decode_image_within(
    field: &str,
    bytes: &[u8],
    max_pixels: u64,
    budget: &Arc<DecodeBudget>,
    deadline: Instant,
) -> Result<(DynamicImage, Reservation), ApiError> {
    let header = read_header(field, bytes, max_pixels)?;
    let reservation = budget.reserve(field, 2 * header.decoded_bytes, deadline)?;
    Ok((decode_with(field, bytes, &header)?, reservation))
}

/// What the header says, before any pixel is decoded.
#[derive(Clone, Copy, Debug)]
pub struct ImageHeader {
    /// Container format (PNG or JPEG).
    pub format: ImageFormat,
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// Bytes of the decoded pixel buffer.
    pub decoded_bytes: u64,
}

/// The format, size and decoded size of PNG or JPEG `bytes`, with the
/// pixel limit and the JPEG end marker checked.
pub fn read_header(field: &str, bytes: &[u8], max_pixels: u64) -> Result<ImageHeader, ApiError> {
    let format = guess_format(field, bytes)?;
    if format == ImageFormat::Jpeg && !ends_with_jpeg_eoi(bytes) {
        return Err(malformed_image(
            field,
            "the JPEG is truncated: it does not end with the end-of-image marker (FF D9)",
        ));
    }
    let decoder = ImageReader::with_format(Cursor::new(bytes), format)
        .into_decoder()
        .map_err(|e| malformed_image(field, crate::perception::image_error_words(&e)))?;
    let (width, height) = decoder.dimensions();
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
    Ok(ImageHeader {
        format,
        width,
        height,
        decoded_bytes: decoder.total_bytes(),
    })
}

/// Decode the pixels, the decoder limited to what the header declared.
fn decode_with(field: &str, bytes: &[u8], header: &ImageHeader) -> Result<DynamicImage, ApiError> {
    let mut reader = ImageReader::with_format(Cursor::new(bytes), header.format);
    let mut limits = Limits::default();
    limits.max_image_width = Some(header.width);
    limits.max_image_height = Some(header.height);
    // RGBA f32 is the widest buffer a PNG/JPEG decoder produces, plus slack.
    let pixels = u64::from(header.width) * u64::from(header.height);
    limits.max_alloc = Some(pixels.saturating_mul(16).saturating_add(1 << 20));
    reader.limits(limits);
    reader
        .decode()
        .map_err(|e| malformed_image(field, crate::perception::image_error_words(&e)))
}

/// Whether a JPEG ends with its EOI marker (trailing zero padding allowed).
fn ends_with_jpeg_eoi(bytes: &[u8]) -> bool {
    let end = bytes.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
    bytes[..end].ends_with(&[0xFF, 0xD9])
}

/// Decoded image bytes held at once across requests (`max_decoded_bytes`).
///
/// Decoding runs inside each request's job, so at most `max_concurrency`
/// decodes run at once; the budget bounds the memory they hold whatever
/// the concurrency, and a request waits for room until its deadline.
#[derive(Debug)]
pub struct DecodeBudget {
    capacity: u64,
    used: Mutex<u64>,
    freed: Condvar,
}

/// Room held in a [`DecodeBudget`]; given back when dropped.
#[derive(Debug)]
pub struct Reservation {
    budget: Arc<DecodeBudget>,
    bytes: u64,
}

impl Drop for Reservation {
    fn drop(&mut self) {
        let mut used = self.budget.lock();
        *used = used.saturating_sub(self.bytes);
        self.budget.freed.notify_all();
    }
}

/// How often a request waiting for room looks at its deadline.
const BUDGET_WAIT: Duration = Duration::from_millis(10);

impl DecodeBudget {
    /// A budget of `capacity` bytes.
    pub fn new(capacity: u64) -> DecodeBudget {
        DecodeBudget {
            capacity,
            used: Mutex::new(0),
            freed: Condvar::new(),
        }
    }

    /// Bytes held now.
    pub fn used(&self) -> u64 {
        *self.lock()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, u64> {
        self.used.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Hold `bytes` until the reservation drops, waiting for room until
    /// `deadline` (then 503); more than the whole budget → 413 naming
    /// `field`.
    pub fn reserve(
        self: &Arc<Self>,
        field: &str,
        bytes: u64,
        deadline: Instant,
    ) -> Result<Reservation, ApiError> {
        if bytes > self.capacity {
            return Err(ApiError::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "image_too_large",
                format!(
                    "decoding needs {bytes} bytes, more than the server's budget of {} (max_decoded_bytes)",
                    self.capacity
                ),
            )
            .with_field(field));
        }
        let mut used = self.lock();
        while *used + bytes > self.capacity {
            let now = Instant::now();
            if now >= deadline {
                return Err(ApiError::deadline_exceeded(
                    "the deadline passed while waiting for room to decode the image",
                ));
            }
            let wait = (deadline - now).min(BUDGET_WAIT);
            used = self
                .freed
                .wait_timeout(used, wait)
                .map_or_else(|e| e.into_inner().0, |(g, _)| g);
        }
        *used += bytes;
        Ok(Reservation {
            budget: self.clone(),
            bytes,
        })
    }
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

    fn jpeg(width: u32, height: u32) -> Vec<u8> {
        let img = RgbImage::from_fn(width, height, |x, y| image::Rgb([x as u8, y as u8, 90]));
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .write_image(img.as_raw(), width, height, image::ExtendedColorType::Rgb8)
            .unwrap();
        out
    }

    #[test]
    fn truncated_jpegs_are_refused_and_whole_ones_decode() {
        let whole = jpeg(64, 48);
        assert!(decode_image("image", &whole, 1 << 20).is_ok());
        let mut padded = whole.clone();
        padded.extend_from_slice(&[0, 0]);
        assert!(decode_image("image", &padded, 1 << 20).is_ok());
        for keep in [whole.len() / 4, whole.len() / 2, whole.len() - 2] {
            let e = decode_image("image", &whole[..keep], 1 << 20).unwrap_err();
            assert_eq!(
                (e.status.as_u16(), e.code),
                (400, "malformed_image"),
                "{keep}"
            );
            assert!(e.message.contains("truncated"), "{}", e.message);
        }
    }

    #[test]
    fn the_budget_bounds_bytes_in_flight_and_waits_until_the_deadline() {
        let budget = Arc::new(DecodeBudget::new(1000));
        let soon = Instant::now() + Duration::from_millis(30);
        let a = budget.reserve("image", 600, soon).unwrap();
        assert_eq!(budget.used(), 600);
        let e = budget.reserve("image", 600, soon).unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (503, "deadline_exceeded"));
        let e = budget.reserve("depth", 1001, soon).unwrap_err();
        assert_eq!(
            (e.status.as_u16(), e.field.as_deref()),
            (413, Some("depth"))
        );
        // Room freed by another request lets a waiting one in.
        let waiter = {
            let budget = budget.clone();
            std::thread::spawn(move || {
                let later = Instant::now() + Duration::from_secs(5);
                budget.reserve("image", 600, later).map(|r| r.bytes)
            })
        };
        std::thread::sleep(Duration::from_millis(20));
        drop(a);
        assert_eq!(waiter.join().unwrap().unwrap(), 600);
        assert_eq!(budget.used(), 0);
        let (img, held) = decode_image_within("image", &png(10, 10), 1000, &budget, soon).unwrap();
        assert_eq!(img.width(), 10);
        assert_eq!(budget.used(), 2 * 10 * 10 * 3);
        drop(held);
        assert_eq!(budget.used(), 0);
    }
}
