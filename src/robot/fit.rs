//! Fitting conservative capsules to a link's collision mesh.
//!
//! Used to produce the collision primitives in `models/panda/panda.urdf`
//! (see the comment there) and by the containment test. The method:
//!
//! 1. sample the mesh surface (every vertex plus a barycentric grid on each
//!    triangle), so that faces, not only vertices, end up inside;
//! 2. initialise `k` segments by k-means on the samples, each cluster's
//!    segment along its principal axis;
//! 3. for a set of segments, compute the smallest radii that contain every
//!    sample ([`containing_radii`]: each sample is assigned to the capsule
//!    that needs the least growth, iterated to a fixed point);
//! 4. hill-climb the segment end points (Gaussian steps, shrinking) to
//!    minimise the summed fourth powers of the radii plus a small length penalty, from several deterministic starts;
//! 5. add a safety margin to every radius.
//!
//! Everything is plain `[f64; 3]` arithmetic and deterministic for a seed.

/// A capsule: the set of points within `radius` of the segment `a`–`b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FittedCapsule {
    /// First end point of the axis segment.
    pub a: [f64; 3],
    /// Second end point of the axis segment.
    pub b: [f64; 3],
    /// Radius.
    pub radius: f64,
}

/// Settings of [`fit_capsules`].
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Number of capsules.
    pub capsules: usize,
    /// Safety margin added to every radius (m).
    pub margin_m: f64,
    /// Hill-climbing steps per start.
    pub iterations: usize,
    /// Number of deterministic starts (the best one wins).
    pub restarts: usize,
    /// Seed of the deterministic random steps.
    pub seed: u64,
    /// Hand-chosen starting segments, tried first when given (their count
    /// overrides `capsules`).
    pub initial: Option<Vec<[[f64; 3]; 2]>>,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            capsules: 2,
            margin_m: 0.003,
            iterations: 6000,
            restarts: 4,
            seed: 7,
            initial: None,
        }
    }
}

/// Every vertex of `triangles` plus a barycentric grid of `subdivisions`
/// steps per edge on each triangle (0 = vertices only), de-duplicated.
pub fn surface_samples(triangles: &[[[f64; 3]; 3]], subdivisions: usize) -> Vec<[f64; 3]> {
    let m = subdivisions.max(1);
    let mut out: Vec<[f64; 3]> = Vec::new();
    for [a, b, c] in triangles {
        for i in 0..=m {
            for j in 0..=(m - i) {
                let k = m - i - j;
                let (wi, wj, wk) = (
                    i as f64 / m as f64,
                    j as f64 / m as f64,
                    k as f64 / m as f64,
                );
                out.push([0, 1, 2].map(|t| wi * a[t] + wj * b[t] + wk * c[t]));
            }
        }
    }
    out.sort_by(|p, q| p.partial_cmp(q).unwrap_or(std::cmp::Ordering::Equal));
    out.dedup_by(|p, q| dist(p, q) < 1e-9);
    out
}

/// Distance from `p` to the segment `a`–`b`.
pub fn segment_distance(p: &[f64; 3], a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let ab = sub(b, a);
    let ap = sub(p, a);
    let len2 = dot(&ab, &ab);
    let t = if len2 < 1e-18 {
        0.0
    } else {
        (dot(&ab, &ap) / len2).clamp(0.0, 1.0)
    };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
    dot(&d, &d).sqrt()
}

/// The smallest radii (one per segment) such that every point lies in at
/// least one capsule: each point is assigned to the capsule that needs the
/// least growth to contain it, iterated until the assignment is stable.
pub fn containing_radii(points: &[[f64; 3]], segments: &[[[f64; 3]; 2]]) -> Vec<f64> {
    let distances: Vec<Vec<f64>> = points
        .iter()
        .map(|p| {
            segments
                .iter()
                .map(|s| segment_distance(p, &s[0], &s[1]))
                .collect()
        })
        .collect();
    let mut radii = vec![0.0; segments.len()];
    for round in 0..12 {
        let mut next = vec![0.0_f64; segments.len()];
        for d in &distances {
            let k = argmin(
                d.iter()
                    .zip(&radii)
                    .map(|(di, ri)| if round == 0 { *di } else { di - ri }),
            );
            next[k] = next[k].max(d[k]);
        }
        if next == radii {
            break;
        }
        radii = next;
    }
    radii
}

/// Smallest slack of any point: `min_p max_k (r_k - d_k(p))`. Positive when
/// every point is inside the union of capsules by at least that much.
pub fn containment_margin(points: &[[f64; 3]], capsules: &[FittedCapsule]) -> f64 {
    points
        .iter()
        .map(|p| {
            capsules
                .iter()
                .map(|c| c.radius - segment_distance(p, &c.a, &c.b))
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Fit `options.capsules` capsules that contain every point with at least
/// `options.margin_m` to spare, minimising their summed fourth powers of the radii (plus a small length penalty).
pub fn fit_capsules(points: &[[f64; 3]], options: &FitOptions) -> Vec<FittedCapsule> {
    let k = match &options.initial {
        Some(init) if !init.is_empty() => init.len(),
        _ => options.capsules.clamp(1, points.len().max(1)),
    };
    let mut rng = SplitMix(options.seed);
    let mut best: Option<(Vec<[[f64; 3]; 2]>, f64)> = None;
    for start in 0..options.restarts.max(1) {
        let init = match &options.initial {
            Some(init) if start == 0 && !init.is_empty() => init.clone(),
            _ => initial_segments(points, k, &mut rng, start == 1),
        };
        let (segments, volume) = hill_climb(points, init, options.iterations, &mut rng);
        if best.as_ref().is_none_or(|(_, v)| volume < *v) {
            best = Some((segments, volume));
        }
    }
    let segments = best.map(|(s, _)| s).unwrap_or_default();
    let radii = containing_radii(points, &segments);
    segments
        .iter()
        .zip(radii)
        .map(|(s, r)| FittedCapsule {
            a: s[0],
            b: s[1],
            radius: r + options.margin_m,
        })
        .collect()
}

/// Fit cost: summed fourth powers of the radii (lateral excess is what costs clearance; an axis
/// that overshoots a flat end into the neighbouring link costs little) plus
/// a small penalty on segment length.
fn fit_cost(segments: &[[[f64; 3]; 2]], radii: &[f64]) -> f64 {
    segments
        .iter()
        .zip(radii)
        .map(|(s, r)| r.powi(4) + LENGTH_WEIGHT * dist(&s[0], &s[1]))
        .sum()
}

/// Weight of the segment length in [`fit_cost`].
const LENGTH_WEIGHT: f64 = 2e-6;

fn hill_climb(
    points: &[[f64; 3]],
    mut segments: Vec<[[f64; 3]; 2]>,
    iterations: usize,
    rng: &mut SplitMix,
) -> (Vec<[[f64; 3]; 2]>, f64) {
    let mut volume = fit_cost(&segments, &containing_radii(points, &segments));
    let mut step = 0.02;
    for it in 0..iterations {
        let mut trial = segments.clone();
        let which = rng.below(trial.len());
        let end = rng.below(3);
        for t in 0..3 {
            let delta = step * rng.gaussian();
            // end 2 = move the whole segment
            if end == 2 {
                trial[which][0][t] += delta;
                trial[which][1][t] += delta;
            } else {
                trial[which][end][t] += delta;
            }
        }
        let v = fit_cost(&trial, &containing_radii(points, &trial));
        if v < volume {
            segments = trial;
            volume = v;
        }
        if (it + 1) % (iterations / 8).max(1) == 0 {
            step *= 0.6;
        }
    }
    (segments, volume)
}

fn initial_segments(
    points: &[[f64; 3]],
    k: usize,
    rng: &mut SplitMix,
    kmeans_pp: bool,
) -> Vec<[[f64; 3]; 2]> {
    let mut centres: Vec<[f64; 3]> = (0..k).map(|_| points[rng.below(points.len())]).collect();
    if kmeans_pp {
        centres = farthest_point_centres(points, k);
    }
    let mut groups: Vec<Vec<[f64; 3]>> = vec![Vec::new(); k];
    for _ in 0..30 {
        groups = vec![Vec::new(); k];
        for p in points {
            let i = argmin(centres.iter().map(|c| dist(p, c)));
            groups[i].push(*p);
        }
        for (c, g) in centres.iter_mut().zip(&groups) {
            if !g.is_empty() {
                *c = mean(g);
            }
        }
    }
    groups
        .iter()
        .zip(&centres)
        .map(|(g, c)| principal_segment(g, c))
        .collect()
}

fn farthest_point_centres(points: &[[f64; 3]], k: usize) -> Vec<[f64; 3]> {
    let mut centres = vec![mean(points)];
    while centres.len() < k {
        let far = argmin(points.iter().map(|p| {
            -centres
                .iter()
                .map(|c| dist(p, c))
                .fold(f64::INFINITY, f64::min)
        }));
        centres.push(points[far]);
    }
    centres
}

fn principal_segment(group: &[[f64; 3]], centre: &[f64; 3]) -> [[f64; 3]; 2] {
    if group.len() < 2 {
        return [*centre, *centre];
    }
    let mut cov = [[0.0; 3]; 3];
    for p in group {
        let d = sub(p, centre);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j];
            }
        }
    }
    let mut v = [1.0, 0.37, 0.11];
    for _ in 0..60 {
        let w = [0, 1, 2].map(|i| dot(&cov[i], &v));
        let n = dot(&w, &w).sqrt();
        if n < 1e-18 {
            break;
        }
        v = w.map(|x| x / n);
    }
    let proj = group.iter().map(|p| dot(&sub(p, centre), &v));
    let (lo, hi) = proj.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
        (lo.min(t), hi.max(t))
    });
    let at = |t: f64| [0, 1, 2].map(|i| centre[i] + 0.6 * t * v[i]);
    [at(lo), at(hi)]
}

fn argmin(values: impl Iterator<Item = f64>) -> usize {
    values
        .enumerate()
        .fold(
            (0, f64::INFINITY),
            |(bi, bv), (i, v)| if v < bv { (i, v) } else { (bi, bv) },
        )
        .0
}

fn mean(points: &[[f64; 3]]) -> [f64; 3] {
    let n = points.len().max(1) as f64;
    let s = points.iter().fold([0.0; 3], |acc, p| {
        [acc[0] + p[0], acc[1] + p[1], acc[2] + p[2]]
    });
    s.map(|x| x / n)
}

fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let d = sub(a, b);
    dot(&d, &d).sqrt()
}

/// A tiny deterministic generator (SplitMix64) so fits reproduce exactly.
struct SplitMix(u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn below(&mut self, n: usize) -> usize {
        ((self.uniform() * n as f64) as usize).min(n.saturating_sub(1))
    }

    fn gaussian(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}
