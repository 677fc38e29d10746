//! `dpmp bench moveit`: MotionBenchMaker's problems (pairs of
//! `sceneNNNN.yaml` / `requestNNNN.yaml`, one folder per scene family, or
//! one family's folder) planned with [`crate::moveit::plan_moveit`] on
//! default options, one after the other (the solver uses the cores).
//!
//! Per family and in all: problems, valid ones (start and goal within the
//! joint limits and clear by the clearance asked: the MoveIt error code is
//! not one of the start/goal codes and the request was readable), valid
//! ones answered `optimal`, and the plan time (wall, the whole
//! [`plan_moveit`] call) median and p98 over the valid problems. Written:
//! `report.json` (every problem's row and the table), `report.md`, each
//! answer as `answers/<family>/<NNNN>.json`, and `plan_time.png` (plan
//! time per problem by outcome).

use crate::moveit::{plan_moveit, MoveItErrorCode, MoveItPlanOptions, MoveItQuery};
use crate::optim::SolveControl;
use crate::plot::{register_font, write_via_temp};
use crate::robot::Robot;
use crate::{Error, Result};
use plotters::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// One problem's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct MoveItRow {
    /// Scene family (the folder's name).
    pub family: String,
    /// The problem's number (`NNNN`).
    pub index: String,
    /// Start and goal within the limits and clear by the clearance.
    pub valid: bool,
    /// The optimiser's status (`optimal`, ...); absent when the request
    /// could not be read.
    pub status: Option<String>,
    /// The optimiser's stop reason.
    pub stop_reason: Option<String>,
    /// MoveIt's error code name.
    pub error_code: String,
    /// Wall time of the plan (ms).
    pub plan_ms: f64,
    /// The duration the answer used (s).
    pub duration_s: Option<f64>,
    /// Smallest clearance of the answer (m).
    pub min_clearance_m: Option<f64>,
    /// Why it is not `optimal` (or why it was not read).
    pub reason: Option<String>,
}

/// One family's line of the table (or `all`).
#[derive(Clone, Debug, Serialize)]
pub struct MoveItSummary {
    /// Family, or `all`.
    pub family: String,
    /// Problems run.
    pub problems: usize,
    /// Valid problems.
    pub valid: usize,
    /// Valid problems answered `optimal`.
    pub optimal: usize,
    /// Median plan time over the valid problems (ms).
    pub median_ms: f64,
    /// 98th percentile plan time over the valid problems (ms).
    pub p98_ms: f64,
}

/// The benchmark's report.
#[derive(Clone, Debug, Serialize)]
pub struct MoveItReport {
    /// Per family, then `all`.
    pub summary: Vec<MoveItSummary>,
    /// Every problem.
    pub rows: Vec<MoveItRow>,
}

/// One problem on disk.
#[derive(Clone, Debug)]
pub struct MoveItProblem {
    /// Scene family.
    pub family: String,
    /// `NNNN`.
    pub index: String,
    /// The `PlanningScene` file.
    pub scene: PathBuf,
    /// The `MotionPlanRequest` file.
    pub request: PathBuf,
}

/// The problems under `dir`: its own `sceneNNNN.yaml` / `requestNNNN.yaml`
/// pairs, else those of each sub-folder (a family each), sorted.
pub fn find_problems(dir: &Path) -> Result<Vec<MoveItProblem>> {
    let own = pairs_in(dir)?;
    if !own.is_empty() {
        return Ok(own);
    }
    let mut families: Vec<PathBuf> = read_dir(dir)?.into_iter().filter(|p| p.is_dir()).collect();
    families.sort();
    let mut all = Vec::new();
    for family in families {
        all.extend(pairs_in(&family)?);
    }
    if all.is_empty() {
        return Err(Error::invalid(
            "--problems",
            format!(
                "{}: no sceneNNNN.yaml / requestNNNN.yaml pairs in it or its sub-folders",
                dir.display()
            ),
        ));
    }
    Ok(all)
}

fn read_dir(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    Ok(entries.filter_map(|e| e.ok().map(|e| e.path())).collect())
}

/// The `sceneNNNN.yaml` files of `dir` that have a `requestNNNN.yaml`.
fn pairs_in(dir: &Path) -> Result<Vec<MoveItProblem>> {
    let family = dir
        .file_name()
        .map_or("problems".into(), |n| n.to_string_lossy().into_owned());
    let mut found: Vec<MoveItProblem> = read_dir(dir)?
        .into_iter()
        .filter_map(|path| {
            let name = path.file_name()?.to_str()?;
            let index = name
                .strip_prefix("scene")?
                .strip_suffix(".yaml")?
                .to_string();
            let request = dir.join(format!("request{index}.yaml"));
            request.is_file().then(|| MoveItProblem {
                family: family.clone(),
                index,
                scene: path.clone(),
                request,
            })
        })
        .collect();
    found.sort_by(|a, b| a.index.cmp(&b.index));
    Ok(found)
}

/// Plan every problem with `options`, writing the answers under `out`.
pub fn run_moveit_bench(
    problems: &[MoveItProblem],
    options: &MoveItPlanOptions,
    robot: &Robot,
    out: &Path,
    progress: &crate::progress::Progress,
) -> Result<MoveItReport> {
    let mut rows = Vec::with_capacity(problems.len());
    for problem in problems {
        rows.push(run_one(problem, options, robot, out)?);
        progress.inc(1);
    }
    Ok(MoveItReport {
        summary: summarise(&rows),
        rows,
    })
}

fn run_one(
    problem: &MoveItProblem,
    options: &MoveItPlanOptions,
    robot: &Robot,
    out: &Path,
) -> Result<MoveItRow> {
    let read = |p: &Path| std::fs::read_to_string(p).map_err(|e| Error::file(p, e.to_string()));
    let (scene, request) = (read(&problem.scene)?, read(&problem.request)?);
    let started = std::time::Instant::now();
    let planned = MoveItQuery::read(&scene, &request, robot)
        .and_then(|q| plan_moveit(&q, options, robot, &SolveControl::default()));
    let plan_ms = started.elapsed().as_secs_f64() * 1e3;
    let mut row = MoveItRow {
        family: problem.family.clone(),
        index: problem.index.clone(),
        valid: false,
        status: None,
        stop_reason: None,
        error_code: MoveItErrorCode::InvalidGoalConstraints.name().into(),
        plan_ms,
        duration_s: None,
        min_clearance_m: None,
        reason: None,
    };
    match planned {
        Err(e) => {
            row.reason = Some(e.to_string());
            if !e.to_string().contains("INVALID_GOAL_CONSTRAINTS") {
                row.error_code = "UNREADABLE".into();
            }
        }
        Ok(answer) => {
            let path = out
                .join("answers")
                .join(&problem.family)
                .join(format!("{}.json", problem.index));
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| Error::file(parent, e.to_string()))?;
            }
            let text = serde_json::to_string(&answer)
                .map_err(|e| Error::Numerical(format!("cannot serialise an answer: {e}")))?;
            crate::fsio::write_atomic(&path, text.as_bytes())?;
            let r = &answer.result;
            row.valid = !is_invalid_query(answer.moveit.error_code.val);
            row.status = Some(r.status.as_str().into());
            row.stop_reason = Some(r.stop_reason.as_str().into());
            row.error_code = answer.moveit.error_code_name.into();
            row.duration_s = Some(r.duration_s);
            row.min_clearance_m = r.report.min_clearance_m;
            row.reason = r.reason.clone();
        }
    }
    Ok(row)
}

/// Whether a code says the query's start or goal is not valid.
fn is_invalid_query(val: i32) -> bool {
    [
        MoveItErrorCode::StartStateInCollision,
        MoveItErrorCode::StartStateInvalid,
        MoveItErrorCode::GoalInCollision,
        MoveItErrorCode::InvalidGoalConstraints,
    ]
    .iter()
    .any(|c| c.val() == val)
}

/// The table: per family in order of appearance, then `all`.
pub fn summarise(rows: &[MoveItRow]) -> Vec<MoveItSummary> {
    let mut families: Vec<String> = Vec::new();
    for r in rows {
        if !families.contains(&r.family) {
            families.push(r.family.clone());
        }
    }
    let mut summary: Vec<MoveItSummary> = families
        .iter()
        .map(|f| line(f, rows.iter().filter(|r| &r.family == f)))
        .collect();
    summary.push(line("all", rows.iter()));
    summary
}

fn line<'a>(family: &str, rows: impl Iterator<Item = &'a MoveItRow>) -> MoveItSummary {
    let rows: Vec<&MoveItRow> = rows.collect();
    let valid: Vec<&&MoveItRow> = rows.iter().filter(|r| r.valid).collect();
    let mut times: Vec<f64> = valid.iter().map(|r| r.plan_ms).collect();
    times.sort_by(f64::total_cmp);
    MoveItSummary {
        family: family.into(),
        problems: rows.len(),
        valid: valid.len(),
        optimal: valid
            .iter()
            .filter(|r| r.status.as_deref() == Some("optimal"))
            .count(),
        median_ms: percentile(&times, 0.5),
        p98_ms: percentile(&times, 0.98),
    }
}

/// The `q` quantile of sorted `v` (nearest rank; 0 when empty).
fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// The table as Markdown.
pub fn markdown(report: &MoveItReport) -> String {
    let mut text = String::from(
        "| scene | problems | valid | optimal | optimal / valid | median plan (ms) | p98 plan (ms) |\n|---|---:|---:|---:|---:|---:|---:|\n",
    );
    for s in &report.summary {
        let share = if s.valid > 0 {
            format!("{:.0} %", 100.0 * s.optimal as f64 / s.valid as f64)
        } else {
            "-".into()
        };
        text.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.0} | {:.0} |\n",
            s.family, s.problems, s.valid, s.optimal, share, s.median_ms, s.p98_ms
        ));
    }
    text
}

/// Write `report.json`, `report.md` and `plan_time.png` into `out`.
pub fn write_report(report: &MoveItReport, out: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::Numerical(format!("cannot serialise the report: {e}")))?;
    crate::fsio::write_atomic(&out.join("report.json"), json.as_bytes())?;
    crate::fsio::write_atomic(&out.join("report.md"), markdown(report).as_bytes())?;
    register_font();
    write_via_temp(&out.join("plan_time.png"), |p: &Path| {
        plan_time_plot(report, p)
    })
}

/// A plot series: its label, colour and which rows it holds.
type Outcome = (&'static str, RGBColor, fn(&MoveItRow) -> bool);

/// Plan time per problem (log10 ms), problems in order, coloured by
/// outcome: optimal, valid but not optimal, not valid.
fn plan_time_plot(report: &MoveItReport, path: &Path) -> Result<()> {
    let err = |e: &dyn std::fmt::Debug| Error::Numerical(format!("plotting failed: {e:?}"));
    let root = BitMapBackend::new(path, (960, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let n = report.rows.len().max(1) as f64;
    let value = |r: &MoveItRow| r.plan_ms.max(1e-3).log10();
    let hi = report.rows.iter().map(value).fold(1.0, f64::max) + 0.3;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "MoveIt problems: log10(plan time, ms) by outcome",
            ("sans-serif", 20),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..n, -1.0..hi)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("problem (families in order)")
        .draw()
        .map_err(|e| err(&e))?;
    let groups: [Outcome; 3] = [
        ("optimal", GREEN, |r| {
            r.valid && r.status.as_deref() == Some("optimal")
        }),
        ("valid, not optimal", RED, |r| {
            r.valid && r.status.as_deref() != Some("optimal")
        }),
        ("not valid", RGBColor(150, 150, 150), |r| !r.valid),
    ];
    for (label, colour, keep) in groups {
        let points = report
            .rows
            .iter()
            .enumerate()
            .filter(|(_, r)| keep(r))
            .map(|(i, r)| Circle::new((i as f64 + 0.5, value(r)), 3, colour.filled()));
        chart
            .draw_series(points)
            .map_err(|e| err(&e))?
            .label(label)
            .legend(move |(x, y)| Circle::new((x, y), 3, colour.filled()));
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(family: &str, valid: bool, status: &str, ms: f64) -> MoveItRow {
        MoveItRow {
            family: family.into(),
            index: "0001".into(),
            valid,
            status: Some(status.into()),
            stop_reason: None,
            error_code: String::new(),
            plan_ms: ms,
            duration_s: None,
            min_clearance_m: None,
            reason: None,
        }
    }

    #[test]
    fn the_table_counts_valid_and_optimal_and_times_the_valid_problems() {
        let rows = vec![
            row("a", true, "optimal", 10.0),
            row("a", true, "max_iterations", 30.0),
            row("a", false, "infeasible", 1.0),
            row("b", true, "optimal", 20.0),
        ];
        let s = summarise(&rows);
        assert_eq!(s.len(), 3);
        assert_eq!((s[0].problems, s[0].valid, s[0].optimal), (3, 2, 1));
        assert_eq!((s[0].median_ms, s[0].p98_ms), (10.0, 30.0));
        assert_eq!(s[2].family, "all");
        assert_eq!((s[2].problems, s[2].valid, s[2].optimal), (4, 3, 2));
        assert_eq!(s[2].median_ms, 20.0);
        assert!(markdown(&MoveItReport { summary: s, rows }).contains("| all | 4 | 3 | 2 | 67 % |"));
    }
}
