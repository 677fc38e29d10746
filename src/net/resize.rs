//! Exact area-averaging resize of an RGB8 image straight to the network's
//! normalised channel-major `f32` input, in two separable passes (vertical first, on whole rows), with the
//! target box painted on the fly (no copy of the full-size image). Each
//! output pixel is the mean of the source area it covers (fractional
//! coverage at its edges), so down- and up-scaling by any factor keep a
//! constant image constant and the total intensity.

use image::RgbImage;

/// Source pixels (first index and one weight per covered pixel, summing to
/// one) of every output position along one axis.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisTaps {
    taps: Vec<(usize, Vec<f32>)>,
}

impl AxisTaps {
    /// Taps resampling `src` pixels onto `dst` (both at least 1).
    pub fn new(src: usize, dst: usize) -> AxisTaps {
        let step = src as f64 / dst as f64;
        let taps = (0..dst)
            .map(|i| {
                let (a, b) = (i as f64 * step, (i + 1) as f64 * step);
                let first = (a.floor() as usize).min(src - 1);
                let last = ((b.ceil() as usize).max(first + 1)).min(src);
                let weights = (first..last)
                    .map(|k| {
                        let overlap = (b.min(k as f64 + 1.0) - a.max(k as f64)).max(0.0);
                        (overlap / step) as f32
                    })
                    .collect();
                (first, weights)
            })
            .collect();
        AxisTaps { taps }
    }

    /// The taps of output position `i`.
    pub fn get(&self, i: usize) -> (usize, &[f32]) {
        let (first, weights) = &self.taps[i];
        (*first, weights)
    }
}

/// Pixel ranges `[x0, x1) x [y0, y1)` whose centres lie inside a box.
pub fn box_pixels(target_box: [f64; 4], width: u32, height: u32) -> [usize; 4] {
    let lo = |v: f64| (v - 0.5).ceil().max(0.0) as usize;
    let hi = |v: f64, n: u32| ((v - 0.5).floor().max(-1.0) as i64 + 1).min(i64::from(n)) as usize;
    [
        lo(target_box[0]),
        lo(target_box[1]),
        hi(target_box[2], width),
        hi(target_box[3], height),
    ]
}

/// What to paint over the image before averaging.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Paint {
    /// `[x0, y0, x1, y1)` pixel ranges (see [`box_pixels`]).
    pub pixels: [usize; 4],
    /// RGB colour.
    pub colour: [u8; 3],
}

/// Area-average `image` (optionally with `paint`) to `side x side` and map
/// each channel value `v` to `v / 255 * scale + shift`; channel-major
/// `3 x side x side`.
pub fn resize_normalise(
    image: &RgbImage,
    side: usize,
    paint: Option<Paint>,
    scale: f32,
    shift: f32,
) -> Vec<f32> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let xs = AxisTaps::new(w, side);
    let ys = AxisTaps::new(h, side);
    let raw = image.as_raw();
    let row_len = w * 3;
    // Vertical pass first (whole interleaved rows, vectorisable): side x w x 3.
    let mut rows = vec![0f32; side * row_len];
    let mut painted_row = Vec::new();
    for (oy, acc) in rows.chunks_exact_mut(row_len).enumerate() {
        let (first, weights) = ys.get(oy);
        for (k, &wk) in weights.iter().enumerate() {
            let y = first + k;
            let src = source_row(raw, row_len, y, paint, &mut painted_row);
            for (a, &v) in acc.iter_mut().zip(src) {
                *a += wk * f32::from(v);
            }
        }
    }
    // Horizontal pass, normalisation and the channel-major layout.
    let plane = side * side;
    let mut out = vec![0f32; 3 * plane];
    let gain = scale / 255.0;
    for (oy, row) in rows.chunks_exact(row_len).enumerate() {
        for ox in 0..side {
            let (first, weights) = xs.get(ox);
            let mut acc = [0f32; 3];
            for (px, &wk) in row[first * 3..].chunks_exact(3).zip(weights) {
                acc[0] += wk * px[0];
                acc[1] += wk * px[1];
                acc[2] += wk * px[2];
            }
            for (c, a) in acc.iter().enumerate() {
                out[c * plane + oy * side + ox] = a * gain + shift;
            }
        }
    }
    out
}

/// Row `y` of the interleaved RGB8 buffer, with the paint applied (into
/// `scratch`) when the row crosses the painted box.
fn source_row<'a>(
    raw: &'a [u8],
    row_len: usize,
    y: usize,
    paint: Option<Paint>,
    scratch: &'a mut Vec<u8>,
) -> &'a [u8] {
    let src = &raw[y * row_len..(y + 1) * row_len];
    let Some(p) = paint else {
        return src;
    };
    let [x0, y0, x1, y1] = p.pixels;
    if !(y0..y1).contains(&y) || x0 >= x1 {
        return src;
    }
    scratch.clear();
    scratch.extend_from_slice(src);
    for px in scratch[x0 * 3..x1 * 3].chunks_mut(3) {
        px.copy_from_slice(&p.colour);
    }
    scratch
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;
    use proptest::prelude::*;

    fn sum_of_weights(t: &AxisTaps, n: usize) -> Vec<f32> {
        (0..n).map(|i| t.get(i).1.iter().sum()).collect()
    }

    #[test]
    fn taps_cover_the_source_exactly() {
        for &(src, dst) in &[(640, 128), (480, 128), (7, 3), (3, 7), (1, 4), (5, 5)] {
            let t = AxisTaps::new(src, dst);
            for s in sum_of_weights(&t, dst) {
                assert!((s - 1.0).abs() < 1e-5, "{src}->{dst}: {s}");
            }
            // Every source pixel contributes dst/src in total.
            let mut per_source = vec![0f64; src];
            for i in 0..dst {
                let (first, w) = t.get(i);
                for (k, &wk) in w.iter().enumerate() {
                    per_source[first + k] += f64::from(wk);
                }
            }
            for v in per_source {
                assert!((v - dst as f64 / src as f64).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn five_to_one_is_the_block_mean() {
        let image = RgbImage::from_fn(10, 5, |x, _| Rgb([(x * 10) as u8, 0, 255]));
        let out = resize_normalise(&image, 2, None, 255.0, 0.0);
        // 10 -> 2 columns: means of x*10 over 0..5 (20) and 5..10 (70).
        assert!((out[0] - 20.0).abs() < 1e-3);
        assert!((out[1] - 70.0).abs() < 1e-3);
        assert!(out[4..8].iter().all(|&v| v.abs() < 1e-3));
        assert!(out[8..12].iter().all(|&v| (v - 255.0).abs() < 1e-3));
    }

    proptest! {
        #[test]
        fn painting_on_the_fly_equals_painting_first(
            w in 1u32..40, h in 1u32..40, side in 1usize..12,
            bx in 0.0f64..1.0, by in 0.0f64..1.0, bw in 0.0f64..1.0, bh in 0.0f64..1.0,
            seed in 0u32..1000,
        ) {
            let image = RgbImage::from_fn(w, h, |x, y| {
                let v = (x * 31 + y * 17 + seed) % 256;
                Rgb([v as u8, (255 - v) as u8, ((v * 7) % 256) as u8])
            });
            let (fw, fh) = (f64::from(w), f64::from(h));
            let b = [bx * fw, by * fh, (bx + bw * (1.0 - bx)) * fw, (by + bh * (1.0 - by)) * fh];
            let paint = Paint { pixels: box_pixels(b, w, h), colour: [255, 255, 255] };
            let mut painted = image.clone();
            let [x0, y0, x1, y1] = paint.pixels;
            for y in y0..y1 {
                for x in x0..x1 {
                    painted.put_pixel(x as u32, y as u32, Rgb([255, 255, 255]));
                }
            }
            let a = resize_normalise(&image, side, Some(paint), 2.0, -1.0);
            let b = resize_normalise(&painted, side, None, 2.0, -1.0);
            prop_assert_eq!(a.len(), 3 * side * side);
            for (x, y) in a.iter().zip(&b) {
                prop_assert!((x - y).abs() < 1e-5);
                prop_assert!((-1.0 - 1e-5..=1.0 + 1e-5).contains(x));
            }
            // The mean intensity is preserved.
            let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
            let channel = |img: &RgbImage, c: usize| img.pixels().map(|p| f64::from(p.0[c]) / 255.0 * 2.0 - 1.0).sum::<f64>() / f64::from(w * h);
            for c in 0..3 {
                let plane = &b[c * side * side..(c + 1) * side * side];
                prop_assert!((mean(plane) - channel(&painted, c)).abs() < 1e-4);
            }
        }
    }
}
