//! Image post-processing: optical blur, sensor noise, 8-bit conversion and
//! the target's white filled bounding box (the paper's network input).

use crate::synth::render::shading::Rgb;
use image::RgbImage;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// A floating-point RGB image (row-major).
#[derive(Clone, Debug)]
pub struct FloatImage {
    /// Width (px).
    pub width: usize,
    /// Height (px).
    pub height: usize,
    /// Pixels, values nominally in [0, 1].
    pub pixels: Vec<Rgb>,
}

impl FloatImage {
    /// A separable [1 2 1] / 4 blur (soft optics), edges clamped.
    pub fn blurred(&self) -> FloatImage {
        let (w, h) = (self.width, self.height);
        let pass = |src: &[Rgb], horizontal: bool| -> Vec<Rgb> {
            (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let (a, b) = if horizontal {
                        (y * w + x.saturating_sub(1), y * w + (x + 1).min(w - 1))
                    } else {
                        (y.saturating_sub(1) * w + x, (y + 1).min(h - 1) * w + x)
                    };
                    [0, 1, 2].map(|c| 0.25 * src[a][c] + 0.5 * src[i][c] + 0.25 * src[b][c])
                })
                .collect()
        };
        let tmp = pass(&self.pixels, true);
        FloatImage {
            width: w,
            height: h,
            pixels: pass(&tmp, false),
        }
    }

    /// 8-bit image with Gaussian sensor noise of `noise_std` (0..255 scale).
    pub fn to_rgb8_with_noise(&self, noise_std: f64, rng: &mut impl Rng) -> RgbImage {
        let normal = Normal::new(0.0f32, noise_std.max(0.0) as f32).ok();
        let mut img = RgbImage::new(self.width as u32, self.height as u32);
        for (p, c) in img.pixels_mut().zip(&self.pixels) {
            for k in 0..3 {
                let n = normal.map_or(0.0, |d| d.sample(rng));
                p.0[k] = (c[k] * 255.0 + n).round().clamp(0.0, 255.0) as u8;
            }
        }
        img
    }
}

/// Pixel index range `[x0, x1) x [y0, y1)` of the pixels a box
/// `[x1, y1, x2, y2]` (continuous pixel coordinates) touches, clipped to the image.
pub fn box_pixels(b: &[f64; 4], width: u32, height: u32) -> [u32; 4] {
    let clip = |v: f64, hi: u32| v.clamp(0.0, hi as f64) as u32;
    [
        clip(b[0].floor(), width),
        clip(b[1].floor(), height),
        clip(b[2].ceil(), width),
        clip(b[3].ceil(), height),
    ]
}

/// Paint the box white and filled.
pub fn paint_box(img: &mut RgbImage, b: &[f64; 4]) {
    let [x0, y0, x1, y1] = box_pixels(b, img.width(), img.height());
    for y in y0..y1 {
        for x in x0..x1 {
            img.put_pixel(x, y, image::Rgb([255, 255, 255]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn blur_preserves_constant_images_and_spreads_impulses() {
        let mut f = FloatImage {
            width: 5,
            height: 4,
            pixels: vec![[0.5; 3]; 20],
        };
        assert!(f.blurred().pixels.iter().all(|p| (p[0] - 0.5).abs() < 1e-6));
        f.pixels = vec![[0.0; 3]; 20];
        f.pixels[2 * 5 + 2] = [1.0; 3];
        let b = f.blurred();
        assert!((b.pixels[2 * 5 + 2][0] - 0.25).abs() < 1e-6);
        assert!((b.pixels.iter().map(|p| p[0]).sum::<f32>() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn noise_has_the_requested_spread_and_box_is_white() {
        let f = FloatImage {
            width: 100,
            height: 100,
            pixels: vec![[0.5; 3]; 10000],
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut img = f.to_rgb8_with_noise(4.0, &mut rng);
        let vals: Vec<f64> = img.pixels().map(|p| p.0[0] as f64).collect();
        let mean = vals.iter().sum::<f64>() / vals.len() as f64;
        let std = (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len() as f64).sqrt();
        assert!(
            (mean - 127.5).abs() < 0.5 && (std - 4.0).abs() < 0.3,
            "{mean} {std}"
        );
        paint_box(&mut img, &[10.2, 20.7, 30.1, 40.0]);
        assert_eq!(img.get_pixel(10, 20).0, [255; 3]);
        assert_eq!(img.get_pixel(30, 39).0, [255; 3]);
        assert_ne!(img.get_pixel(31, 39).0, [255; 3]);
        assert_eq!(
            box_pixels(&[-5.0, -1.0, 700.0, 10.0], 640, 480),
            [0, 0, 640, 10]
        );
    }
}
