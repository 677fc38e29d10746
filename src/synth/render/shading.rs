//! Materials, lighting and procedural textures: glossy seeded berries,
//! veined leaflets, stems, tray plastic and an out-of-focus foliage
//! background. Colours are linear-ish RGB in [0, 1].

use crate::synth::plant::{Ripeness, StemKind};
use crate::synth::render::noise::{fbm2, hash01, value2};
use crate::synth::render::primitives::Hit;
use nalgebra::Vector3;

/// RGB colour.
pub type Rgb = [f32; 3];

/// What a primitive is made of.
#[derive(Clone, Copy, Debug)]
pub enum Material {
    /// Berry flesh; `r_top` scales the seed pattern.
    Berry {
        /// Colour class.
        ripeness: Ripeness,
        /// Shoulder radius (m).
        r_top: f64,
        /// Axis length between the sphere centres (m).
        length: f64,
    },
    /// Calyx sepal.
    Sepal,
    /// Stem, peduncle or petiole.
    Stem(StemKind),
    /// Leaflet of a given green shade.
    Leaf(f64),
    /// Tray (table top) of a given brightness.
    Tray(f64),
}

/// Light and per-scene colour randomisation.
#[derive(Clone, Debug)]
pub struct Lighting {
    /// Unit direction towards the key light.
    pub key_dir: Vector3<f64>,
    /// Key light intensity.
    pub key: f32,
    /// Ambient level.
    pub ambient: f32,
    /// Multiplicative white balance / colour jitter.
    pub tint: Rgb,
    /// Per-material colour jitter factors (berry, leaf, stem, background).
    pub jitter: [Rgb; 4],
    /// Seed of the procedural textures.
    pub seed: u32,
    /// Draw berry seeds.
    pub seeds: bool,
}

fn mul(a: Rgb, b: Rgb) -> Rgb {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}

fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

fn scale(a: Rgb, s: f32) -> Rgb {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Shade one hit seen along `view` (unit, from camera to the point).
pub fn shade(material: &Material, hit: &Hit, view: &Vector3<f64>, light: &Lighting) -> Rgb {
    let n = hit.normal;
    let (albedo, gloss, two_sided) = match material {
        Material::Berry {
            ripeness,
            r_top,
            length,
        } => (
            berry_albedo(*ripeness, *r_top, *length, hit, light),
            0.55,
            false,
        ),
        Material::Sepal => (mul([0.16, 0.36, 0.09], light.jitter[1]), 0.05, true),
        Material::Stem(kind) => (stem_albedo(*kind, hit, light), 0.05, false),
        Material::Leaf(shade) => (leaf_albedo(*shade, hit, light), 0.15, true),
        Material::Tray(shade) => (tray_albedo(*shade, hit, light), 0.12, false),
    };
    let l = light.key_dir;
    let ndl = n.dot(&l);
    let diffuse = (if two_sided {
        ndl.abs() * 0.85
    } else {
        ndl.max(0.0)
    }) as f32;
    let half = (l - view).normalize();
    let spec = if gloss > 0.0 && ndl > 0.0 {
        gloss
            * n.dot(&half)
                .max(0.0)
                .powf(if gloss > 0.3 { 70.0 } else { 12.0 }) as f32
    } else {
        0.0
    };
    let lit = scale(albedo, light.ambient + light.key * diffuse);
    mul(
        [
            lit[0] + spec * light.key,
            lit[1] + spec * light.key,
            lit[2] + spec * light.key,
        ],
        light.tint,
    )
}

fn berry_albedo(ripeness: Ripeness, r_top: f64, length: f64, hit: &Hit, light: &Lighting) -> Rgb {
    let [s, phi] = hit.local;
    // s runs from the shoulder centre (0) towards the tip (length); the
    // shoulders are paler, the tip slightly darker.
    let along = ((s + r_top) / (length + 2.0 * r_top)).clamp(0.0, 1.0) as f32;
    let (flesh, seed_col, pale) = match ripeness {
        Ripeness::Ripe => ([0.70, 0.035, 0.045], [0.85, 0.68, 0.25], [0.85, 0.35, 0.22]),
        Ripeness::Unripe(w) => (
            mix([0.50, 0.68, 0.26], [0.88, 0.86, 0.70], w as f32),
            [0.75, 0.72, 0.35],
            [0.75, 0.85, 0.55],
        ),
    };
    let flesh = mul(flesh, light.jitter[0]);
    let mut c = mix(pale, flesh, (along * 4.0 - 0.15).clamp(0.0, 1.0));
    c = scale(c, 1.0 - 0.25 * (along - 0.5).max(0.0));
    if light.seeds {
        match seed_at(s, phi, r_top, light.seed) {
            SeedHit::Seed => c = seed_col,
            SeedHit::Pit => c = scale(c, 0.6),
            SeedHit::None => {}
        }
    }
    c
}

enum SeedHit {
    Seed,
    Pit,
    None,
}

/// Seeds on a jittered, row-offset lattice in (arc length, axis) space.
fn seed_at(s: f64, phi: f64, r_top: f64, seed: u32) -> SeedHit {
    let spacing = 0.0036;
    let n_around = ((2.0 * std::f64::consts::PI * r_top / spacing).round()).max(6.0);
    let row_f = s / (spacing * 0.85);
    let row = row_f.round();
    if row < 0.0 {
        return SeedHit::None;
    }
    let offset = if (row as i64) % 2 == 0 { 0.0 } else { 0.5 };
    let col_f = (phi / (2.0 * std::f64::consts::PI)).rem_euclid(1.0) * n_around - offset;
    let col = col_f.round();
    let jx = hash01(row as i32, col as i32, 1, seed) as f64 - 0.5;
    let jy = hash01(row as i32, col as i32, 2, seed) as f64 - 0.5;
    let du = (col_f - col - 0.3 * jx) * spacing;
    let dv = (row_f - row - 0.3 * jy) * spacing * 0.85;
    let d = (du * du + dv * dv).sqrt();
    if d < 0.00055 {
        SeedHit::Seed
    } else if d < 0.0009 {
        SeedHit::Pit
    } else {
        SeedHit::None
    }
}

fn stem_albedo(kind: StemKind, hit: &Hit, light: &Lighting) -> Rgb {
    let base = match kind {
        StemKind::Stem => [0.36, 0.50, 0.18],
        StemKind::Peduncle => [0.40, 0.46, 0.20],
        StemKind::Petiole => [0.30, 0.45, 0.15],
    };
    let grain = 0.9 + 0.2 * value2(hit.local[0] as f32 * 60.0, 0.0, light.seed ^ 77);
    scale(mul(base, light.jitter[2]), grain)
}

fn leaf_albedo(shade: f64, hit: &Hit, light: &Lighting) -> Rgb {
    let [a, b] = hit.local;
    let base = mix([0.07, 0.20, 0.05], [0.22, 0.45, 0.12], shade as f32);
    let base = mul(base, light.jitter[1]);
    let midrib = (1.0 - (b.abs() / 0.035)).max(0.0) as f32;
    let side = ((a - 0.55 * b.abs()) * 6.0).rem_euclid(1.0);
    let vein = if b.abs() > 0.05 {
        (1.0 - (side - 0.5).abs() * 12.0).max(0.0) as f32 * 0.5
    } else {
        0.0
    };
    let blotch = 0.85 + 0.3 * value2(a as f32 * 5.0 + 17.0, b as f32 * 5.0, light.seed ^ 5);
    // Quilted look: each inter-vein band is slightly domed (darker at the veins).
    let quilt = 0.9 + 0.1 * ((side * std::f64::consts::PI).sin() as f32);
    let c = mix(base, [0.45, 0.62, 0.30], (midrib + vein) * 0.6);
    scale(c, blotch * quilt)
}

/// The out-of-focus background at normalised image coordinates `(x, y)` in [0, 1].
pub fn background(x: f32, y: f32, light: &Lighting) -> Rgb {
    let seed = light.seed ^ 0xBAC6;
    let foliage = fbm2(x * 5.0, y * 4.0, 4, seed);
    let fine = fbm2(x * 40.0, y * 32.0, 2, seed ^ 3);
    let sky = fbm2(x * 2.0 + 3.0, y * 2.0, 3, seed ^ 9);
    let dark = [0.04, 0.09, 0.04];
    let green = [0.17, 0.30, 0.10];
    let light_green = [0.40, 0.52, 0.25];
    let bright = [0.80, 0.84, 0.82];
    let mut c = mix(dark, green, (foliage - 0.3) * 2.5);
    c = mix(c, light_green, (foliage - 0.62) * 4.0);
    // Greenhouse roof / gaps: bright patches, more likely near the top.
    let gap = (sky - 0.55 + 0.35 * (0.5 - y)) * 4.0;
    c = mix(c, bright, gap.clamp(0.0, 0.85));
    let c = scale(c, 0.85 + 0.3 * fine);
    mul(mul(c, light.jitter[3]), light.tint)
}

/// Light wood-like tray top: grain along x, plank seams every 9 cm along y
/// (shape-local coordinates in metres), tinted beige.
fn tray_albedo(shade: f64, hit: &Hit, light: &Lighting) -> [f32; 3] {
    let (x, y) = (hit.local[0] as f32, hit.local[1] as f32);
    let grain = 0.86 + 0.22 * fbm2(x * 18.0, y * 260.0, 3, light.seed ^ 0x7a7);
    let seam = if (y / 0.09).rem_euclid(1.0) < 0.04 {
        0.6
    } else {
        1.0
    };
    let g = shade as f32 * grain * seam;
    [g, g * 0.9, g * 0.76]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light() -> Lighting {
        Lighting {
            key_dir: Vector3::new(-1.0, 0.0, 1.0).normalize(),
            key: 0.9,
            ambient: 0.3,
            tint: [1.0; 3],
            jitter: [[1.0; 3]; 4],
            seed: 3,
            seeds: true,
        }
    }

    #[test]
    fn ripe_berries_are_red_and_lit_faces_are_brighter() {
        let m = Material::Berry {
            ripeness: Ripeness::Ripe,
            r_top: 0.014,
            length: 0.016,
        };
        let view = Vector3::x();
        let lit = Hit {
            t: 1.0,
            normal: Vector3::new(-1.0, 0.0, 1.0).normalize(),
            local: [0.01, 0.0001],
        };
        let dark = Hit {
            normal: Vector3::new(-1.0, 0.0, -1.0).normalize(),
            ..lit
        };
        let light = Lighting {
            seeds: false,
            ..light()
        };
        let a = shade(&m, &lit, &view, &light);
        let b = shade(&m, &dark, &view, &light);
        assert!(a[0] > 2.0 * a[1] && a[0] > 2.0 * a[2], "{a:?}");
        assert!(a[0] > b[0]);
    }

    #[test]
    fn seeds_cover_a_plausible_fraction_of_the_surface() {
        let mut seeds = 0;
        let n = 200;
        for i in 0..n {
            for j in 0..n {
                let s = 0.02 * i as f64 / n as f64;
                let phi = std::f64::consts::TAU * (j as f64 / n as f64 - 0.5);
                if matches!(seed_at(s, phi, 0.014, 1), SeedHit::Seed) {
                    seeds += 1;
                }
            }
        }
        let frac = seeds as f64 / (n * n) as f64;
        assert!((0.03..0.25).contains(&frac), "seed fraction {frac}");
    }

    #[test]
    fn background_is_mostly_green_or_bright() {
        let l = light();
        let mut green = 0;
        for i in 0..100 {
            let c = background(i as f32 / 100.0, 0.7, &l);
            assert!(c.iter().all(|v| v.is_finite() && *v >= 0.0));
            if c[1] >= c[0] {
                green += 1;
            }
        }
        assert!(green > 60);
    }
}
