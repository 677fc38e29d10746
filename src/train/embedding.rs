//! Table II of the paper: a 2-D embedding of the latent vectors (exact
//! t-SNE from the `bhtsne` crate, initialised deterministically with the
//! PCA projection; PCA alone when there are too few points for t-SNE), the
//! Davies–Bouldin index of that embedding labelled by plant configuration,
//! and a scatter plot of it.

use crate::{Error, Result};
use nalgebra::DMatrix;
use plotters::prelude::*;
use serde::Serialize;
use std::path::Path;

/// Fewest points for which t-SNE runs (perplexity needs `n - 1 >= 3 p`, p >= 2).
pub const MIN_TSNE_POINTS: usize = 7;

/// A 2-D embedding of labelled points.
#[derive(Clone, Debug, Serialize)]
pub struct Embedding {
    /// `"t-SNE (bhtsne exact, PCA init, perplexity P)"` or `"PCA"`.
    pub method: String,
    /// One `[x, y]` per point.
    pub points: Vec<[f64; 2]>,
    /// Cluster label per point (plant configuration).
    pub labels: Vec<usize>,
}

/// Project rows of `data` (n x d) onto their first two principal axes.
pub fn pca_2d(data: &[Vec<f32>]) -> Vec<[f64; 2]> {
    let n = data.len();
    let d = data.first().map_or(0, Vec::len);
    if n == 0 || d == 0 {
        return vec![[0.0, 0.0]; n];
    }
    let mut x = DMatrix::from_fn(n, d, |r, c| f64::from(data[r][c]));
    for c in 0..d {
        let mean = x.column(c).mean();
        x.column_mut(c).add_scalar_mut(-mean);
    }
    let svd = x.clone().svd(false, true);
    let Some(v_t) = svd.v_t else {
        return vec![[0.0, 0.0]; n];
    };
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let axis = |k: usize| order.get(k).map(|&i| v_t.row(i).transpose());
    let project = |r: usize, k: usize| axis(k).map_or(0.0, |a| x.row(r).transpose().dot(&a));
    (0..n).map(|r| [project(r, 0), project(r, 1)]).collect()
}

/// Embed latent vectors in 2-D: t-SNE when there are enough points, else PCA.
pub fn embed(latents: &[Vec<f32>], labels: &[usize]) -> Embedding {
    let pca = pca_2d(latents);
    let n = latents.len();
    if n < MIN_TSNE_POINTS {
        return Embedding {
            method: "PCA".into(),
            points: pca,
            labels: labels.to_vec(),
        };
    }
    let perplexity = (((n - 1) / 3) as f64).min(30.0);
    let spread = pca
        .iter()
        .flat_map(|p| p.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(1e-12);
    let init: Vec<f64> = pca
        .iter()
        .flat_map(|p| [p[0] / spread * 1e-2, p[1] / spread * 1e-2])
        .collect();
    let rows: Vec<Vec<f64>> = latents
        .iter()
        .map(|r| r.iter().map(|&v| f64::from(v)).collect())
        .collect();
    let mut tsne: bhtsne::tSNE<f64, Vec<f64>> = bhtsne::tSNE::new(&rows);
    tsne.perplexity(perplexity)
        .epochs(1000)
        .initial_embedding(init)
        .exact(|a, b| a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>());
    let flat = tsne.embedding();
    let points = flat.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    Embedding {
        method: format!("t-SNE (bhtsne exact, PCA init, perplexity {perplexity})"),
        points,
        labels: labels.to_vec(),
    }
}

/// Davies–Bouldin index of labelled points (lower is better clustered);
/// `None` with fewer than two clusters.
pub fn davies_bouldin(points: &[[f64; 2]], labels: &[usize]) -> Option<f64> {
    let mut clusters: Vec<usize> = labels.to_vec();
    clusters.sort_unstable();
    clusters.dedup();
    if clusters.len() < 2 {
        return None;
    }
    let centroid = |c: usize| {
        let members: Vec<&[f64; 2]> = points
            .iter()
            .zip(labels)
            .filter(|(_, &l)| l == c)
            .map(|(p, _)| p)
            .collect();
        let k = members.len() as f64;
        let sum = members
            .iter()
            .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
        let centre = [sum[0] / k, sum[1] / k];
        let scatter = members.iter().map(|p| dist(p, &centre)).sum::<f64>() / k;
        (centre, scatter)
    };
    let stats: Vec<([f64; 2], f64)> = clusters.iter().map(|&c| centroid(c)).collect();
    let mut total = 0.0;
    for (i, (ci, si)) in stats.iter().enumerate() {
        let worst = stats
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, (cj, sj))| {
                let d = dist(ci, cj);
                if d > 0.0 {
                    (si + sj) / d
                } else {
                    f64::INFINITY
                }
            })
            .fold(0.0, f64::max);
        total += worst;
    }
    Some(total / stats.len() as f64)
}

fn dist(a: &[f64; 2], b: &[f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Scatter plot of the embedding, one colour per label (PNG, atomic).
pub fn plot_embedding(embedding: &Embedding, title: &str, path: &Path) -> Result<()> {
    crate::plot::write_via_temp(path, |tmp| {
        draw(embedding, title, tmp).map_err(|e| Error::write(path, format!("cannot plot: {e}")))
    })
}

fn draw(
    embedding: &Embedding,
    title: &str,
    path: &Path,
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    crate::plot::register_font();
    let root = BitMapBackend::new(path, (640, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in &embedding.points {
        x0 = x0.min(p[0]);
        x1 = x1.max(p[0]);
        y0 = y0.min(p[1]);
        y1 = y1.max(p[1]);
    }
    if x1.partial_cmp(&x0) != Some(std::cmp::Ordering::Greater) {
        (x0, x1) = (x0 - 1.0, x0 + 1.0);
    }
    if y1.partial_cmp(&y0) != Some(std::cmp::Ordering::Greater) {
        (y0, y1) = (y0 - 1.0, y0 + 1.0);
    }
    let (px, py) = (0.05 * (x1 - x0), 0.05 * (y1 - y0));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(x0 - px..x1 + px, y0 - py..y1 + py)?;
    chart.configure_mesh().draw()?;
    chart.draw_series(
        embedding
            .points
            .iter()
            .zip(&embedding.labels)
            .map(|(p, &l)| {
                let colour = Palette99::pick(l).to_rgba();
                Circle::new((p[0], p[1]), 4, colour.filled())
            }),
    )?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn davies_bouldin_matches_hand_computation() {
        // Two clusters: scatter 1 each, centres 4 apart -> (1 + 1) / 4 = 0.5.
        let points = [[-1.0, 0.0], [1.0, 0.0], [3.0, 0.0], [5.0, 0.0]];
        let labels = [0, 0, 1, 1];
        assert!((davies_bouldin(&points, &labels).unwrap() - 0.5).abs() < 1e-12);
        assert!(davies_bouldin(&points, &[0, 0, 0, 0]).is_none());
    }

    #[test]
    fn pca_recovers_the_dominant_axis() {
        let data: Vec<Vec<f32>> = (0..10)
            .map(|i| vec![i as f32, 2.0 * i as f32, 0.5])
            .collect();
        let p = pca_2d(&data);
        // All variance on one axis: second coordinate ~0, first spans sqrt(5) * 9.
        assert!(p.iter().all(|q| q[1].abs() < 1e-4));
        let span = p.iter().map(|q| q[0]).fold(f64::MIN, f64::max)
            - p.iter().map(|q| q[0]).fold(f64::MAX, f64::min);
        assert!((span - 5f64.sqrt() * 9.0).abs() < 1e-3);
    }

    #[test]
    fn tsne_separates_two_far_clusters() {
        let mut data = Vec::new();
        let mut labels = Vec::new();
        for i in 0..20 {
            let offset = if i < 10 { 0.0 } else { 50.0 };
            data.push(vec![
                offset + (i % 10) as f32 * 0.1,
                (i % 3) as f32 * 0.1,
                0.0,
            ]);
            labels.push(usize::from(i >= 10));
        }
        let e = embed(&data, &labels);
        assert!(e.method.starts_with("t-SNE"));
        let db = davies_bouldin(&e.points, &e.labels).unwrap();
        assert!(db < 0.3, "db {db}");
    }
}
