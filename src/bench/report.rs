//! Aggregation of the runner's records into per-method and per-category
//! summaries, written as `report.json` (everything, including every record)
//! and `report.md` (the tables BENCHMARKS.md quotes).

use super::model_suite::MODEL_CATEGORY;
use super::problem_file::HARD_CATEGORY;
use super::problem_file::{write_atomic, CATEGORIES};
use super::runner::RunRecord;
use crate::{Error, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// p50 / p95 / max of a sample.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Default)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 95th percentile (nearest rank).
    pub p95: f64,
    /// Maximum.
    pub max: f64,
}

impl Percentiles {
    /// Percentiles of `values` (zeros when empty; NaN ignored).
    pub fn of(values: &[f64]) -> Percentiles {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
        if v.is_empty() {
            return Percentiles::default();
        }
        v.sort_by(f64::total_cmp);
        let rank = |q: f64| v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
        Percentiles {
            p50: rank(0.5),
            p95: rank(0.95),
            max: v[v.len() - 1],
        }
    }
}

/// One method over a set of records.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct MethodSummary {
    /// Method name.
    pub method: String,
    /// Category (`"all"` for the overall row).
    pub category: String,
    /// Problems run.
    pub problems: usize,
    /// Problems that errored.
    pub errors: usize,
    /// Correct answers / labelled problems (unknown labels count in none).
    pub success_rate: f64,
    /// Feasible problems solved with a verified trajectory.
    pub feasible_solved: usize,
    /// Feasible problems.
    pub feasible_total: usize,
    /// Infeasible problems answered with no trajectory.
    pub infeasible_identified: usize,
    /// Infeasible problems.
    pub infeasible_total: usize,
    /// Trajectories claimed feasible that fail the verification.
    pub false_feasible: usize,
    /// Median Mahalanobis cost over the verified trajectories.
    pub median_mahalanobis: Option<f64>,
    /// Smallest clearance over the verified trajectories (m).
    pub worst_clearance_m: Option<f64>,
    /// Wall-clock time per problem (ms).
    pub time_ms: Percentiles,
    /// Final-point TCP error against the problems' reference (model mode),
    /// over every returned trajectory, feasible or not (m); `None` when no
    /// problem has a reference.
    pub final_tcp_error_m: Option<Percentiles>,
}

/// Paired Mahalanobis comparison with `dpmp-qp` on problems both solved.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PairedCost {
    /// The other method.
    pub method: String,
    /// Problems both solved with verified trajectories.
    pub both_solved: usize,
    /// Of those, where dpmp-qp's cost is lower or equal (to 1e-9 relative).
    pub dpmp_lower_or_equal: usize,
    /// Median of other / dpmp-qp cost (dpmp-qp cost > 0 only).
    pub median_ratio: Option<f64>,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The command that produced it.
    pub command: String,
    /// Methods in run order.
    pub methods: Vec<String>,
    /// Overall row per method.
    pub summary: Vec<MethodSummary>,
    /// One row per (category, method).
    pub by_category: Vec<MethodSummary>,
    /// Paired cost comparisons against dpmp-qp.
    pub paired_cost: Vec<PairedCost>,
    /// Every record, sorted by problem then method order.
    pub records: Vec<RunRecord>,
}

impl Report {
    /// Aggregate `records` of `methods`.
    pub fn new(command: &str, methods: &[String], mut records: Vec<RunRecord>) -> Report {
        let order = |m: &str| methods.iter().position(|x| x == m).unwrap_or(usize::MAX);
        records.sort_by(|a, b| {
            a.problem
                .cmp(&b.problem)
                .then(order(&a.method).cmp(&order(&b.method)))
        });
        let summary = methods
            .iter()
            .map(|m| summarise(m, "all", records.iter().filter(|r| &r.method == m)))
            .collect();
        let mut by_category = Vec::new();
        for c in CATEGORIES
            .iter()
            .copied()
            .chain([HARD_CATEGORY, MODEL_CATEGORY, "unknown"])
        {
            for m in methods {
                let rows: Vec<&RunRecord> = records
                    .iter()
                    .filter(|r| &r.method == m && r.category == c)
                    .collect();
                if !rows.is_empty() {
                    by_category.push(summarise(m, c, rows.into_iter()));
                }
            }
        }
        let paired_cost = methods
            .iter()
            .filter(|m| m.as_str() != "dpmp-qp" && methods.iter().any(|x| x == "dpmp-qp"))
            .map(|m| paired(m, &records))
            .collect();
        Report {
            command: command.to_string(),
            methods: methods.to_vec(),
            summary,
            by_category,
            paired_cost,
            records,
        }
    }

    /// Write `report.json` and `report.md` into `dir` (atomically).
    pub fn write(&self, dir: &Path) -> Result<()> {
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Numerical(format!("cannot serialise the report: {e}")))?;
        write_atomic(&dir.join("report.json"), json.as_bytes())?;
        write_atomic(&dir.join("report.md"), self.markdown().as_bytes())
    }

    /// The summary tables as Markdown.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# Benchmark report\n\nCommand: `{}`\n", self.command);
        let _ = writeln!(s, "## Overall\n");
        table(&mut s, &self.summary, false);
        let _ = writeln!(s, "\n## By category\n");
        table(&mut s, &self.by_category, true);
        if self.summary.iter().any(|r| r.final_tcp_error_m.is_some()) {
            final_tcp_table(&mut s, &self.summary);
        }
        if !self.paired_cost.is_empty() {
            let _ = writeln!(
                s,
                "\n## Mahalanobis cost vs dpmp-qp (problems both solved)\n"
            );
            let _ = writeln!(s, "| method | both solved | dpmp-qp lower or equal | median cost ratio (method / dpmp-qp) |");
            let _ = writeln!(s, "|---|---|---|---|");
            for p in &self.paired_cost {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} |",
                    p.method,
                    p.both_solved,
                    p.dpmp_lower_or_equal,
                    opt(p.median_ratio, 2)
                );
            }
        }
        let errors: Vec<&RunRecord> = self.records.iter().filter(|r| r.error.is_some()).collect();
        if !errors.is_empty() {
            let _ = writeln!(s, "\n## Errors\n");
            for r in errors {
                let _ = writeln!(
                    s,
                    "- {} / {}: {}",
                    r.problem,
                    r.method,
                    r.error.as_deref().unwrap_or("")
                );
            }
        }
        s
    }
}

fn table(s: &mut String, rows: &[MethodSummary], with_category: bool) {
    let head = "| method | success | feasible solved | infeasible identified | false feasible | errors | median Mahalanobis | worst clearance (mm) | time p50 / p95 / max (ms) |";
    let _ = writeln!(
        s,
        "{}{head}",
        if with_category { "| category " } else { "" }
    );
    let _ = writeln!(
        s,
        "{}|---|---|---|---|---|---|---|---|---|",
        if with_category { "|---" } else { "" }
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{}| {} | {:.0} % | {}/{} | {}/{} | {} | {} | {} | {} | {:.1} / {:.1} / {:.1} |",
            if with_category {
                format!("| {} ", r.category)
            } else {
                String::new()
            },
            r.method,
            100.0 * r.success_rate,
            r.feasible_solved,
            r.feasible_total,
            r.infeasible_identified,
            r.infeasible_total,
            r.false_feasible,
            r.errors,
            opt(r.median_mahalanobis, 2),
            opt(r.worst_clearance_m.map(|c| c * 1e3), 1),
            r.time_ms.p50,
            r.time_ms.p95,
            r.time_ms.max,
        );
    }
}

fn final_tcp_table(s: &mut String, rows: &[MethodSummary]) {
    let _ = writeln!(
        s,
        "\n## Final TCP error vs the demonstrations' mean final TCP (mm)\n"
    );
    let _ = writeln!(s, "| method | p50 | p95 | max |");
    let _ = writeln!(s, "|---|---|---|---|");
    for r in rows {
        if let Some(p) = r.final_tcp_error_m {
            let _ = writeln!(
                s,
                "| {} | {:.1} | {:.1} | {:.1} |",
                r.method,
                p.p50 * 1e3,
                p.p95 * 1e3,
                p.max * 1e3
            );
        }
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |x| format!("{x:.digits$}"))
}

fn median(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| Percentiles::of(values).p50)
}

/// Summary of one method's records.
pub fn summarise<'a>(
    method: &str,
    category: &str,
    rows: impl Iterator<Item = &'a RunRecord>,
) -> MethodSummary {
    let rows: Vec<&RunRecord> = rows.collect();
    let solved: Vec<&&RunRecord> = rows
        .iter()
        .filter(|r| r.found && r.verified_feasible)
        .collect();
    let feasible_total = rows
        .iter()
        .filter(|r| r.expect_feasible == Some(true))
        .count();
    let infeasible_total = rows
        .iter()
        .filter(|r| r.expect_feasible == Some(false))
        .count();
    let labelled = feasible_total + infeasible_total;
    let n = rows.len();
    MethodSummary {
        method: method.to_string(),
        category: category.to_string(),
        problems: n,
        errors: rows.iter().filter(|r| r.error.is_some()).count(),
        success_rate: if labelled == 0 {
            0.0
        } else {
            rows.iter().filter(|r| r.success).count() as f64 / labelled as f64
        },
        feasible_solved: rows
            .iter()
            .filter(|r| r.expect_feasible == Some(true) && r.success)
            .count(),
        feasible_total,
        infeasible_identified: rows
            .iter()
            .filter(|r| r.expect_feasible == Some(false) && r.success)
            .count(),
        infeasible_total,
        false_feasible: rows
            .iter()
            .filter(|r| r.found && !r.verified_feasible)
            .count(),
        median_mahalanobis: median(
            &solved
                .iter()
                .filter_map(|r| r.mahalanobis)
                .collect::<Vec<_>>(),
        ),
        worst_clearance_m: solved
            .iter()
            .filter_map(|r| r.min_clearance_m)
            .reduce(f64::min),
        time_ms: Percentiles::of(
            &rows
                .iter()
                .filter(|r| r.error.is_none())
                .map(|r| r.time_ms)
                .collect::<Vec<_>>(),
        ),
        final_tcp_error_m: {
            let e: Vec<f64> = rows.iter().filter_map(|r| r.final_tcp_error_m).collect();
            (!e.is_empty()).then(|| Percentiles::of(&e))
        },
    }
}

fn paired(method: &str, records: &[RunRecord]) -> PairedCost {
    let solved = |r: &RunRecord| r.found && r.verified_feasible;
    let mut both = 0;
    let mut lower = 0;
    let mut ratios = Vec::new();
    for r in records.iter().filter(|r| r.method == method && solved(r)) {
        let Some(q) = records
            .iter()
            .find(|x| x.problem == r.problem && x.method == "dpmp-qp" && solved(x))
        else {
            continue;
        };
        let (Some(a), Some(b)) = (r.mahalanobis, q.mahalanobis) else {
            continue;
        };
        both += 1;
        if b <= a * (1.0 + 1e-9) + 1e-12 {
            lower += 1;
        }
        if b > 0.0 {
            ratios.push(a / b);
        }
    }
    PairedCost {
        method: method.to_string(),
        both_solved: both,
        dpmp_lower_or_equal: lower,
        median_ratio: median(&ratios),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        let p = Percentiles::of(&v);
        assert_eq!((p.p50, p.p95, p.max), (50.0, 95.0, 100.0));
        assert_eq!(Percentiles::of(&[]), Percentiles::default());
        assert_eq!(Percentiles::of(&[3.0, f64::NAN]).max, 3.0);
    }
}
