//! Deterministic procedural noise: integer hashing, value noise and fractal
//! sums, used for textures (background foliage, leaf and tray grain).

/// A 32-bit integer hash of three lattice coordinates and a seed.
pub fn hash3(x: i32, y: i32, z: i32, seed: u32) -> u32 {
    let mut h = seed ^ 0x9E37_79B9;
    for v in [x as u32, y as u32, z as u32] {
        h ^= v.wrapping_mul(0x85EB_CA6B);
        h = h.rotate_left(13).wrapping_mul(0xC2B2_AE35);
        h ^= h >> 16;
    }
    h
}

/// Hash mapped to [0, 1).
pub fn hash01(x: i32, y: i32, z: i32, seed: u32) -> f32 {
    (hash3(x, y, z, seed) >> 8) as f32 / (1u32 << 24) as f32
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Smooth 2-D value noise in [0, 1).
pub fn value2(x: f32, y: f32, seed: u32) -> f32 {
    let (xf, yf) = (x.floor(), y.floor());
    let (xi, yi) = (xf as i32, yf as i32);
    let (tx, ty) = (smooth(x - xf), smooth(y - yf));
    let a = lerp(hash01(xi, yi, 0, seed), hash01(xi + 1, yi, 0, seed), tx);
    let b = lerp(
        hash01(xi, yi + 1, 0, seed),
        hash01(xi + 1, yi + 1, 0, seed),
        tx,
    );
    lerp(a, b, ty)
}

/// Fractal (fBm) sum of `octaves` value-noise layers, normalised to [0, 1).
pub fn fbm2(x: f32, y: f32, octaves: u32, seed: u32) -> f32 {
    let (mut sum, mut amp, mut norm, mut f) = (0.0, 1.0, 0.0, 1.0);
    for o in 0..octaves {
        sum += amp * value2(x * f, y * f, seed.wrapping_add(o * 7919));
        norm += amp;
        amp *= 0.5;
        f *= 2.0;
    }
    sum / norm
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_deterministic_and_continuous() {
        let mut prev = value2(0.0, 0.3, 5);
        for i in 1..2000 {
            let x = i as f32 * 0.001;
            let v = value2(x, 0.3, 5);
            assert!((0.0..1.0).contains(&v));
            assert!((v - prev).abs() < 0.01, "jump at {x}");
            prev = v;
            assert_eq!(fbm2(x, 1.7, 4, 9), fbm2(x, 1.7, 4, 9));
        }
        assert_ne!(hash3(1, 2, 3, 0), hash3(1, 2, 3, 1));
    }
}
