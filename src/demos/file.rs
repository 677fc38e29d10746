//! Demonstration files: a `time` column and one column per joint, named as
//! in the robot's URDF, as CSV (header row; extra columns ignored) or JSON
//! (`{"time": [...], "panda_joint1": [...], ...}`; extra keys ignored).
//! Every cell is checked: a missing joint column, a non-numeric or
//! non-finite cell, or a time that does not increase is an error naming the
//! file, the line (or index) and the column.
//!
//! [`ReadOptions`] adapt other exports: joint columns under other names (a
//! `/joint_states` export's `position_0`, a namespace prefix) and times in
//! milliseconds, microseconds or nanoseconds (ROS bag exports), detected
//! from the recording's span unless given. A duration no robot
//! demonstration has (outside [`MIN_DEMO_DURATION_S`] ..
//! [`MAX_DEMO_DURATION_S`] seconds) is refused, naming the unit used.

use crate::{Error, Result};
use nalgebra::DMatrix;
use std::path::{Path, PathBuf};

/// The column holding the sample times.
pub const TIME_COLUMN: &str = "time";
/// Shortest demonstration accepted (s).
pub const MIN_DEMO_DURATION_S: f64 = 0.1;
/// Longest demonstration accepted (s): the optimiser's longest duration.
pub const MAX_DEMO_DURATION_S: f64 = crate::optim::task::MAX_DURATION_S;

/// Unit of the `time` column.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TimeUnit {
    /// The first of s, ms, µs, ns that makes the recording's span a
    /// plausible demonstration duration.
    #[default]
    Auto,
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
    /// Nanoseconds.
    Ns,
}

impl TimeUnit {
    /// The explicit units, in the order auto-detection tries them.
    const EXPLICIT: [TimeUnit; 4] = [TimeUnit::S, TimeUnit::Ms, TimeUnit::Us, TimeUnit::Ns];

    /// Seconds per unit (1 for `Auto`, which is resolved first).
    fn seconds(self) -> f64 {
        match self {
            TimeUnit::Auto | TimeUnit::S => 1.0,
            TimeUnit::Ms => 1e-3,
            TimeUnit::Us => 1e-6,
            TimeUnit::Ns => 1e-9,
        }
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            TimeUnit::Auto => "auto",
            TimeUnit::S => "s",
            TimeUnit::Ms => "ms",
            TimeUnit::Us => "us",
            TimeUnit::Ns => "ns",
        }
    }

    /// `auto` resolved for a recording spanning `span` of its own units.
    fn resolve(self, span: f64) -> TimeUnit {
        if self != TimeUnit::Auto {
            return self;
        }
        Self::EXPLICIT
            .into_iter()
            .find(|u| (MIN_DEMO_DURATION_S..=MAX_DEMO_DURATION_S).contains(&(span * u.seconds())))
            .unwrap_or(TimeUnit::S)
    }
}

impl std::str::FromStr for TimeUnit {
    type Err = String;
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        match text {
            "auto" => Ok(TimeUnit::Auto),
            "s" => Ok(TimeUnit::S),
            "ms" => Ok(TimeUnit::Ms),
            "us" => Ok(TimeUnit::Us),
            "ns" => Ok(TimeUnit::Ns),
            other => Err(format!("expected auto, s, ms, us or ns, got `{other}`")),
        }
    }
}

/// How to read a recording that is not in the native layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReadOptions {
    /// Unit of the `time` column.
    pub time_unit: TimeUnit,
    /// Joint name -> the column that holds it (joints not listed keep
    /// their own name).
    pub joint_columns: Vec<(String, String)>,
}

impl ReadOptions {
    /// Parse `JOINT=COLUMN,...` against the robot's `joint_names`; errors
    /// name `flag`.
    pub fn parse_joint_map(
        flag: &str,
        text: &str,
        joint_names: &[String],
    ) -> Result<Vec<(String, String)>> {
        let pairs = text
            .split(',')
            .map(str::trim)
            .filter(|p| !p.is_empty())
            .map(|pair| {
                pair.split_once('=')
                    .map(|(j, c)| (j.trim().to_string(), c.trim().to_string()))
                    .ok_or_else(|| {
                        Error::invalid(flag, format!("expected JOINT=COLUMN pairs, got `{pair}`"))
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        Self::check_joint_columns(flag, pairs, joint_names)
    }

    /// `(joint, column)` pairs checked against the robot's `joint_names`:
    /// each joint the robot's, once, with a non-empty column; errors name
    /// `field`.
    pub fn check_joint_columns(
        field: &str,
        pairs: Vec<(String, String)>,
        joint_names: &[String],
    ) -> Result<Vec<(String, String)>> {
        for (k, (joint, column)) in pairs.iter().enumerate() {
            if !joint_names.contains(joint) {
                return Err(Error::invalid(
                    field,
                    format!(
                        "`{joint}` is not a joint of the robot ({})",
                        joint_names.join(", ")
                    ),
                ));
            }
            if column.is_empty() || pairs[..k].iter().any(|(j, _)| j == joint) {
                return Err(Error::invalid(
                    field,
                    format!("`{joint}` needs exactly one non-empty column name"),
                ));
            }
        }
        Ok(pairs)
    }

    /// The column read for each of `joint_names`.
    fn columns(&self, joint_names: &[String]) -> Vec<String> {
        joint_names
            .iter()
            .map(|n| {
                self.joint_columns
                    .iter()
                    .find(|(j, _)| j == n)
                    .map_or_else(|| n.clone(), |(_, c)| c.clone())
            })
            .collect()
    }
}

/// One recorded motion: sample times and joint positions in the robot's
/// joint order.
#[derive(Clone, Debug)]
pub struct Demonstration {
    /// The file it was read from (named in every later error).
    pub source: PathBuf,
    /// Sample times (s), strictly increasing.
    pub time_s: Vec<f64>,
    /// `L x n_joints` joint positions (rad or m), one row per sample.
    pub positions: DMatrix<f64>,
}

impl Demonstration {
    /// A demonstration from arrays: `time_s` strictly increasing and finite,
    /// `positions` with one row per time and finite; errors name `source`.
    pub fn new(source: &Path, time_s: Vec<f64>, positions: DMatrix<f64>) -> Result<Self> {
        if positions.nrows() != time_s.len() {
            return Err(Error::file(
                source,
                format!(
                    "{} times but {} rows of positions",
                    time_s.len(),
                    positions.nrows()
                ),
            ));
        }
        if time_s.len() < 2 {
            return Err(Error::file(
                source,
                format!(
                    "too short: {} sample(s), a demonstration needs at least 2",
                    time_s.len()
                ),
            ));
        }
        check_times(source, &time_s)?;
        if let Some(i) = positions.iter().position(|v| !v.is_finite()) {
            let (row, col) = (i % positions.nrows(), i / positions.nrows());
            return Err(Error::file(
                source,
                format!("sample {row}, joint {col}: not a finite number"),
            ));
        }
        Ok(Demonstration {
            source: source.to_path_buf(),
            time_s,
            positions,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// Whether there are no samples (never true for a validated one).
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Number of joints.
    pub fn n_joints(&self) -> usize {
        self.positions.ncols()
    }

    /// Time from the first to the last sample (s).
    pub fn duration_s(&self) -> f64 {
        self.time_s[self.time_s.len() - 1] - self.time_s[0]
    }

    /// Each sample's phase `(t - t_0) / (t_end - t_0)` in `[0, 1]`.
    pub fn phases(&self) -> Vec<f64> {
        let (t0, d) = (self.time_s[0], self.duration_s());
        self.time_s.iter().map(|t| (t - t0) / d).collect()
    }
}

/// Finite and strictly increasing; the error names the first bad sample.
fn check_times(source: &Path, time_s: &[f64]) -> Result<()> {
    if let Some(i) = time_s.iter().position(|t| !t.is_finite()) {
        return Err(Error::file(
            source,
            format!("{TIME_COLUMN}[{i}]: not a finite number"),
        ));
    }
    if let Some(i) = time_s.windows(2).position(|w| w[1] <= w[0]) {
        return Err(Error::file(
            source,
            format!(
                "{TIME_COLUMN} must increase: sample {} ({} s) is not after sample {i} ({} s)",
                i + 1,
                time_s[i + 1],
                time_s[i]
            ),
        ));
    }
    Ok(())
}

/// Read a demonstration (`.csv` or `.json`, by extension), its joint
/// columns in the order of `joint_names`, times in seconds.
pub fn read_demonstration(path: &Path, joint_names: &[String]) -> Result<Demonstration> {
    read_demonstration_with(path, joint_names, &ReadOptions::default())
}

/// [`read_demonstration`] with the joints under other column names and
/// the times in another unit (see [`ReadOptions`]).
pub fn read_demonstration_with(
    path: &Path,
    joint_names: &[String],
    options: &ReadOptions,
) -> Result<Demonstration> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
    let columns = options.columns(joint_names);
    let (time, positions) = match extension(path).as_deref() {
        Some("csv") => read_csv(path, &bytes, &columns)?,
        Some("json") => read_json(path, &bytes, &columns)?,
        _ => {
            return Err(Error::file(
                path,
                "unknown demonstration format: expected a .csv or .json file",
            ))
        }
    };
    check_times(path, &time)?;
    let time_s = in_seconds(path, time, options.time_unit)?;
    Demonstration::new(path, time_s, positions)
}

/// `time` in seconds, its unit detected unless given; a duration outside
/// the plausible range is refused, naming the unit used.
fn in_seconds(path: &Path, time: Vec<f64>, unit: TimeUnit) -> Result<Vec<f64>> {
    if time.len() < 2 {
        return Ok(time); // Demonstration::new names the sample count.
    }
    let t0 = time.first().copied().unwrap_or(0.0);
    let span = time.last().copied().unwrap_or(t0) - t0;
    let unit = unit.resolve(span);
    let scale = unit.seconds();
    let duration = span * scale;
    if !(MIN_DEMO_DURATION_S..=MAX_DEMO_DURATION_S).contains(&duration) {
        return Err(Error::file(
            path,
            format!(
                "column '{TIME_COLUMN}': the recording lasts {duration:.6e} s read in {} (span {span:.6e}); a demonstration lasts {MIN_DEMO_DURATION_S}..{MAX_DEMO_DURATION_S} s: give the unit (--time-unit s|ms|us|ns, or an import manifest's time_unit)",
                unit.name()
            ),
        ));
    }
    // Relative to the first sample: epoch timestamps lose no precision.
    Ok(time.iter().map(|t| (t - t0) * scale).collect())
}

/// A recording's times, in the file's unit, and its positions.
type Recorded = (Vec<f64>, DMatrix<f64>);

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

/// The demonstration files among `inputs`: files as given, directories
/// expanded to their `.csv` and `.json` files in name order.
pub fn demonstration_paths(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut paths = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let entries =
                std::fs::read_dir(input).map_err(|e| Error::file(input, e.to_string()))?;
            let mut found: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && matches!(extension(p).as_deref(), Some("csv" | "json")))
                .collect();
            if found.is_empty() {
                return Err(Error::file(input, "no .csv or .json demonstrations in it"));
            }
            found.sort();
            paths.extend(found);
        } else if input.is_file() {
            paths.push(input.clone());
        } else {
            return Err(Error::file(input, "no such file or directory"));
        }
    }
    Ok(paths)
}

/// Times (as written) and positions of a CSV recording.
fn read_csv(path: &Path, bytes: &[u8], joint_names: &[String]) -> Result<Recorded> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(bytes);
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| Error::file(path, format!("unreadable CSV header: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    let wanted: Vec<&str> = std::iter::once(TIME_COLUMN)
        .chain(joint_names.iter().map(String::as_str))
        .collect();
    let columns = wanted
        .iter()
        .map(|name| column_index(path, &header, name))
        .collect::<Result<Vec<usize>>>()?;
    let mut time_s = Vec::new();
    let mut values = Vec::new();
    for (row, record) in reader.records().enumerate() {
        // The header is line 1.
        let line = row + 2;
        let record =
            record.map_err(|e| Error::file(path, format!("line {line}: unreadable CSV: {e}")))?;
        for (k, (&col, name)) in columns.iter().zip(&wanted).enumerate() {
            let cell = record.get(col).unwrap_or("");
            let v = parse_cell(cell).ok_or_else(|| {
                Error::file(
                    path,
                    format!("line {line}, column '{name}': '{cell}' is not a finite number"),
                )
            })?;
            if k == 0 {
                time_s.push(v);
            } else {
                values.push(v);
            }
        }
    }
    let positions = DMatrix::from_row_slice(time_s.len(), joint_names.len(), &values);
    Ok((time_s, positions))
}

fn column_index(path: &Path, header: &[String], name: &str) -> Result<usize> {
    header.iter().position(|h| h == name).ok_or_else(|| {
        Error::file(
            path,
            format!(
                "column '{name}' is missing (header: {}; joints under other names: --joint-map JOINT=COLUMN)",
                header.join(", ")
            ),
        )
    })
}

fn parse_cell(cell: &str) -> Option<f64> {
    cell.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Times (as written) and positions of a JSON recording.
fn read_json(path: &Path, bytes: &[u8], joint_names: &[String]) -> Result<Recorded> {
    let value: serde_json::Value = serde_json::from_slice(bytes)
        .map_err(|e| Error::file(path, format!("malformed JSON: {e}")))?;
    let object = value.as_object().ok_or_else(|| {
        Error::file(
            path,
            format!("expected an object with '{TIME_COLUMN}' and one array per joint"),
        )
    })?;
    let column = |name: &str| -> Result<Vec<f64>> {
        let array = object
            .get(name)
            .ok_or_else(|| Error::file(path, format!("field '{name}' is missing")))?
            .as_array()
            .ok_or_else(|| Error::file(path, format!("field '{name}' must be an array")))?;
        array
            .iter()
            .enumerate()
            .map(|(i, v)| {
                v.as_f64().filter(|v| v.is_finite()).ok_or_else(|| {
                    Error::file(path, format!("{name}[{i}]: {v} is not a finite number"))
                })
            })
            .collect()
    };
    let time_s = column(TIME_COLUMN)?;
    let mut positions = DMatrix::zeros(time_s.len(), joint_names.len());
    for (j, name) in joint_names.iter().enumerate() {
        let values = column(name)?;
        if values.len() != time_s.len() {
            return Err(Error::file(
                path,
                format!(
                    "field '{name}' has {} values, '{TIME_COLUMN}' has {}",
                    values.len(),
                    time_s.len()
                ),
            ));
        }
        positions.column_mut(j).copy_from_slice(&values);
    }
    Ok((time_s, positions))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        vec!["j1".into(), "j2".into()]
    }

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn csv_and_json_read_the_same_samples_in_joint_order() {
        let dir = tempfile::tempdir().unwrap();
        let csv = write(
            dir.path(),
            "a.csv",
            "extra, j2 ,time,j1\n9, 0.5, 0.0, 0.1\n9, 0.6, 0.5, 0.2\n9,0.7,1.5,0.3\n",
        );
        let json = write(
            dir.path(),
            "a.json",
            r#"{"time": [0.0, 0.5, 1.5], "j1": [0.1, 0.2, 0.3], "j2": [0.5, 0.6, 0.7], "note": "x"}"#,
        );
        for path in [csv, json] {
            let d = read_demonstration(&path, &names()).unwrap();
            assert_eq!(d.time_s, vec![0.0, 0.5, 1.5]);
            assert_eq!(
                d.positions.row(1).iter().copied().collect::<Vec<_>>(),
                [0.2, 0.6]
            );
            assert_eq!(d.duration_s(), 1.5);
            assert_eq!(d.phases(), vec![0.0, 1.0 / 3.0, 1.0]);
        }
    }

    #[test]
    fn bad_files_name_the_file_line_and_column() {
        let dir = tempfile::tempdir().unwrap();
        let cases = [
            (
                "missing.csv",
                "time,j1\n0,0\n1,0\n",
                "column 'j2' is missing",
            ),
            (
                "text.csv",
                "time,j1,j2\n0,0,0\n1,abc,0\n",
                "line 3, column 'j1': 'abc'",
            ),
            (
                "nan.csv",
                "time,j1,j2\n0,0,NaN\n1,0,0\n",
                "line 2, column 'j2': 'NaN'",
            ),
            (
                "empty.csv",
                "time,j1,j2\n0,0,\n1,0,0\n",
                "line 2, column 'j2': ''",
            ),
            (
                "back.csv",
                "time,j1,j2\n0,0,0\n1,0,0\n1,0,0\n",
                "time must increase: sample 2",
            ),
            ("short.csv", "time,j1,j2\n0,0,0\n", "too short"),
            (
                "short.json",
                r#"{"time": [0, 1], "j1": [0, 1], "j2": [0]}"#,
                "field 'j2' has 1 values",
            ),
            (
                "str.json",
                r#"{"time": [0, "1"], "j1": [0, 1], "j2": [0, 1]}"#,
                "time[1]",
            ),
            ("list.json", "[1, 2]", "expected an object"),
            ("a.txt", "time,j1,j2\n", "expected a .csv or .json"),
        ];
        for (name, text, expected) in cases {
            let path = write(dir.path(), name, text);
            let e = read_demonstration(&path, &names()).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(expected), "{name}: {e}");
        }
    }

    #[test]
    fn directories_expand_to_their_demonstrations_in_name_order() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b.csv", "a.json", "notes.txt"] {
            write(dir.path(), name, "");
        }
        let paths = demonstration_paths(&[dir.path().to_path_buf()]).unwrap();
        let names: Vec<_> = paths
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a.json", "b.csv"]);
        let empty = dir.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        assert!(demonstration_paths(&[empty]).is_err());
        assert!(demonstration_paths(&[dir.path().join("nope.csv")]).is_err());
    }
}
