//! The crate's one error type.
//!
//! Every stage returns [`Result`]. Errors that come from outside input name
//! the offending field (a JSON path such as `prior.cov[3][4]` or
//! `obstacles[2] (id "berry-2").radius`) or file, so that the HTTP layer can
//! answer `{"error": {"code", "message", "field"}}` and the CLI can print a
//! message a user can act on.

use std::path::{Path, PathBuf};

/// Result alias used across the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in dPMP.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Input that parses but breaks a rule (NaN, wrong size, out of range...).
    #[error("invalid {field}: {message}")]
    Invalid {
        /// JSON-path-like name of the offending field.
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// A file that cannot be read, written or parsed.
    #[error("{path}: {message}")]
    File {
        /// The file concerned.
        path: PathBuf,
        /// What went wrong, naming the field inside the file when known.
        message: String,
    },
    /// An output that cannot be written (full disk, no permission): not the
    /// input's fault.
    #[error("{path}: {message}")]
    Write {
        /// The file or folder concerned.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The answer was printed but is not the one asked for (the CLI's
    /// `--require-optimal` / `--require-converged`): exit code 3.
    #[error("{0}")]
    Unsolved(String),
    /// A problem that is well formed but cannot be solved, with the reason.
    #[error("infeasible: {0}")]
    Infeasible(String),
    /// The work was cancelled or ran past its deadline.
    #[error("cancelled: {0}")]
    Cancelled(String),
    /// A numerical failure inside a solver or a factorisation.
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// A loaded model produced output that is not a valid prior (corrupt or
    /// badly trained weights): the server's fault, not the request's.
    #[error("model error: {0}")]
    Model(String),
}

impl Error {
    /// A validation error for `field`.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid {
            field: field.into(),
            message: message.into(),
        }
    }

    /// A file error for `path`.
    pub fn file(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error::File {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    /// An output error for `path` (see [`Error::Write`]).
    pub fn write(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error::Write {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    /// Machine-readable error code (`invalid_input`, `file`, ...).
    pub fn code(&self) -> &'static str {
        match self {
            Error::Invalid { .. } => "invalid_input",
            Error::File { .. } => "file",
            Error::Write { .. } => "write",
            Error::Unsolved(_) => "not_optimal",
            Error::Infeasible(_) => "infeasible",
            Error::Cancelled(_) => "cancelled",
            Error::Numerical(_) => "numerical",
            Error::Model(_) => "model_error",
        }
    }

    /// The offending field, when the error names one.
    pub fn field(&self) -> Option<&str> {
        match self {
            Error::Invalid { field, .. } => Some(field),
            _ => None,
        }
    }

    /// Prefix the field of an [`Error::Invalid`] with `prefix.` so nested
    /// validators can report full paths (`prior` + `cov[2]` -> `prior.cov[2]`).
    pub fn within(self, prefix: &str) -> Self {
        match self {
            Error::Invalid { field, message } => Error::Invalid {
                field: join_field(prefix, &field),
                message,
            },
            other => other,
        }
    }
}

fn join_field(prefix: &str, field: &str) -> String {
    if prefix.is_empty() {
        field.to_string()
    } else if field.is_empty() {
        prefix.to_string()
    } else if field.starts_with('[') {
        format!("{prefix}{field}")
    } else {
        format!("{prefix}.{field}")
    }
}

/// Fail with a field-naming error unless every value is finite.
pub fn ensure_finite(field: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::invalid(
            format!("{field}[{i}]"),
            format!("must be a finite number, got {}", values[i]),
        )),
    }
}

/// Fail with a field-naming error unless `value` is finite and in
/// `[lo, hi]` (the one range check of every validator).
pub fn ensure_in_range(field: &str, value: f64, lo: f64, hi: f64) -> Result<()> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("must be a finite number in [{lo}, {hi}], got {value}"),
        ))
    }
}

/// Fail with a field-naming error unless `value` is finite and > 0.
pub fn ensure_positive(field: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("must be a finite number > 0, got {value}"),
        ))
    }
}

/// Fail with a field-naming error unless `values` has exactly `len` entries.
pub fn ensure_len(field: &str, values: &[f64], len: usize) -> Result<()> {
    if values.len() == len {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("expected {len} numbers, got {}", values.len()),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_fields_join_with_dots_and_brackets() {
        let e = Error::invalid("cov[2]", "bad").within("prior");
        assert_eq!(e.field(), Some("prior.cov[2]"));
        let e = Error::invalid("[3]", "bad").within("start");
        assert_eq!(e.field(), Some("start[3]"));
    }

    #[test]
    fn finite_check_names_the_index() {
        let e = ensure_finite("start", &[0.0, f64::NAN]).unwrap_err();
        assert_eq!(e.field(), Some("start[1]"));
        assert!(ensure_finite("start", &[1.0, 2.0]).is_ok());
    }
}
