//! Dataset statistics, comparable with the real annotation data:
//! final-time standard deviation per joint (median over targets, from each
//! target's weight distribution as in REFERENCE.md), the region of the final
//! TCP positions, berry spacing within a configuration and the start spread.

use crate::promp::{Basis, PrompConfig, WeightDistribution};
use crate::robot::Robot;
use crate::synth::dataset::TargetRecord;
use crate::synth::plant::pairwise_distances;
use crate::Result;
use serde::Serialize;
use std::collections::BTreeMap;

/// Statistics of one set of targets.
#[derive(Clone, Debug, Serialize)]
pub struct DatasetStats {
    /// Number of targets.
    pub targets: usize,
    /// Final-time std per joint, median over targets (rad).
    pub final_std_median: Vec<f64>,
    /// Final-time std per joint, maximum over targets (rad).
    pub final_std_max: Vec<f64>,
    /// Lower corner of the final TCP positions (m).
    pub final_tcp_min: [f64; 3],
    /// Upper corner of the final TCP positions (m).
    pub final_tcp_max: [f64; 3],
    /// Smallest distance between two targets of one configuration (m).
    pub spacing_min: f64,
    /// Largest distance between two targets of one configuration (m).
    pub spacing_max: f64,
    /// Largest deviation of a mean start from the robot's home (rad).
    pub start_spread_max: f64,
}

/// One target reduced to what the statistics need.
#[derive(Clone, Debug)]
pub struct TargetSummary {
    /// Configuration the target belongs to.
    pub config: usize,
    /// Weight distribution.
    pub distribution: WeightDistribution,
    /// Final TCP position (m).
    pub final_tcp: [f64; 3],
    /// Start configuration.
    pub start: Vec<f64>,
}

impl TargetSummary {
    /// From a dataset record (final TCP = the record's mean final pose).
    pub fn from_record(r: &TargetRecord) -> Result<TargetSummary> {
        Ok(TargetSummary {
            config: r.config,
            distribution: r.weight_distribution()?,
            final_tcp: r.final_tcp.position,
            start: r.start.clone(),
        })
    }

    /// From a real annotation prior (final TCP = FK of the mean trajectory's last sample).
    pub fn from_prior(
        config: usize,
        distribution: WeightDistribution,
        robot: &Robot,
        basis: &Basis,
    ) -> TargetSummary {
        let mean = distribution.trajectory_mean(basis);
        let row = |k: usize| -> Vec<f64> { mean.row(k).iter().copied().collect() };
        let last = row(mean.nrows() - 1);
        let p = robot.tcp_pose(&last).translation.vector;
        TargetSummary {
            config,
            distribution,
            final_tcp: [p.x, p.y, p.z],
            start: row(0),
        }
    }
}

/// Median of a non-empty slice (NaN-free input).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Compute the statistics of `targets`.
pub fn dataset_stats(targets: &[TargetSummary], basis: &Basis, home: &[f64]) -> DatasetStats {
    let n_joints = home.len();
    let finals: Vec<Vec<f64>> = targets
        .iter()
        .map(|t| {
            let std = t.distribution.trajectory_std(basis, 0.0);
            std.row(std.nrows() - 1).iter().copied().collect()
        })
        .collect();
    let per_joint = |j: usize| -> Vec<f64> { finals.iter().map(|f| f[j]).collect() };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for t in targets {
        for k in 0..3 {
            lo[k] = lo[k].min(t.final_tcp[k]);
            hi[k] = hi[k].max(t.final_tcp[k]);
        }
    }
    let mut by_config: BTreeMap<usize, Vec<[f64; 3]>> = BTreeMap::new();
    for t in targets {
        by_config.entry(t.config).or_default().push(t.final_tcp);
    }
    let spacing: Vec<f64> = by_config
        .values()
        .flat_map(|c| pairwise_distances(c))
        .collect();
    DatasetStats {
        targets: targets.len(),
        final_std_median: (0..n_joints).map(|j| median(&per_joint(j))).collect(),
        final_std_max: (0..n_joints)
            .map(|j| per_joint(j).into_iter().fold(0.0, f64::max))
            .collect(),
        final_tcp_min: lo,
        final_tcp_max: hi,
        spacing_min: spacing.iter().copied().fold(f64::INFINITY, f64::min),
        spacing_max: spacing.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        start_spread_max: targets
            .iter()
            .flat_map(|t| t.start.iter().zip(home).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max),
    }
}

/// The default ProMP basis (the records' and the annotations').
pub fn default_basis() -> Result<Basis> {
    Basis::new(&PrompConfig::default())
}

fn fmt_vec(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x:.3}")).collect();
    format!("[{}]", items.join(", "))
}

fn fmt_region(lo: &[f64; 3], hi: &[f64; 3]) -> String {
    format!(
        "x {:.3}..{:.3}, y {:.3}..{:.3}, z {:.3}..{:.3}",
        lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
    )
}

/// A side-by-side text table (`reference` optional).
pub fn format_table(synthetic: &DatasetStats, reference: Option<&DatasetStats>) -> String {
    let rows: Vec<(&str, Box<dyn Fn(&DatasetStats) -> String>)> = vec![
        (
            "targets",
            Box::new(|s: &DatasetStats| s.targets.to_string()),
        ),
        (
            "final std / joint, median (rad)",
            Box::new(|s: &DatasetStats| fmt_vec(&s.final_std_median)),
        ),
        (
            "final std / joint, max (rad)",
            Box::new(|s: &DatasetStats| fmt_vec(&s.final_std_max)),
        ),
        (
            "final TCP region (m)",
            Box::new(|s: &DatasetStats| fmt_region(&s.final_tcp_min, &s.final_tcp_max)),
        ),
        (
            "target spacing in a config (m)",
            Box::new(|s: &DatasetStats| format!("{:.3}..{:.3}", s.spacing_min, s.spacing_max)),
        ),
        (
            "start spread from home, max (rad)",
            Box::new(|s: &DatasetStats| format!("{:.4}", s.start_spread_max)),
        ),
    ];
    let mut out = String::new();
    out.push_str(&format!("{:<36} {:<58}", "statistic", "synthetic"));
    if reference.is_some() {
        out.push_str(" reference");
    }
    out.push('\n');
    for (name, f) in &rows {
        out.push_str(&format!("{name:<36} {:<58}", f(synthetic)));
        if let Some(r) = reference {
            out.push_str(&format!(" {}", f(r)));
        }
        out.push('\n');
    }
    if let Some(r) = reference {
        let ratios: Vec<f64> = synthetic
            .final_std_median
            .iter()
            .zip(&r.final_std_median)
            .map(|(a, b)| a / b)
            .collect();
        out.push_str(&format!(
            "{:<36} {}\n",
            "final std ratio synthetic/reference",
            fmt_vec(&ratios)
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_sets() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }
}
