//! Reading a [`PriorSpec`]: exactly one of its two forms, every length
//! capped while it is read ([`crate::strict_json::AtMost`]).
//!
//! The prior is `"smooth"` or an object with either `mean` and `cov` or
//! `annotation`;
//! both forms at once, an unknown key or a missing half is refused with a
//! message in the request's own terms. It is read straight into typed
//! vectors (an untagged enum would first buffer the whole value, ~50 bytes
//! a number).

use super::PriorSpec;
use crate::optim::task::MAX_JOINTS;
use crate::promp::annotation::JointAnnotation;
use crate::strict_json::AtMost;
use serde::de::{Error as _, MapAccess, Visitor};
use serde::{Deserialize, Deserializer};
use std::fmt;
use std::marker::PhantomData;

/// Most weights a prior may have (64 joints x 64 basis functions).
pub const MAX_WEIGHTS: usize = 4096;

/// The keys of a prior object.
const KEYS: &[&str] = &["mean", "cov", "annotation"];

impl<'de> Deserialize<'de> for PriorSpec {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(PriorVisitor)
    }
}

struct PriorVisitor;

impl<'de> Visitor<'de> for PriorVisitor {
    type Value = PriorSpec;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a prior: \"smooth\", or an object with `mean` and `cov`, or with `annotation`")
    }

    fn visit_str<E: serde::de::Error>(self, value: &str) -> Result<PriorSpec, E> {
        if value == super::SMOOTH_PRIOR {
            Ok(PriorSpec::Smooth)
        } else {
            Err(E::invalid_value(serde::de::Unexpected::Str(value), &self))
        }
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<PriorSpec, A::Error> {
        let mut mean: Option<Vec<f64>> = None;
        let mut cov: Option<Vec<Vec<f64>>> = None;
        let mut annotation: Option<Vec<JointAnnotation>> = None;
        while let Some(key) = map.next_key::<String>()? {
            match key.as_str() {
                "mean" if mean.is_none() => {
                    mean =
                        Some(map.next_value_seed(AtMost::<PhantomData<f64>>::items(MAX_WEIGHTS))?)
                }
                "cov" if cov.is_none() => {
                    cov = Some(map.next_value_seed(AtMost {
                        max: MAX_WEIGHTS,
                        item: AtMost::<PhantomData<f64>>::items(MAX_WEIGHTS),
                    })?)
                }
                "annotation" if annotation.is_none() => {
                    annotation = Some(map.next_value_seed(
                        AtMost::<PhantomData<JointAnnotation>>::items(MAX_JOINTS),
                    )?)
                }
                "mean" | "cov" | "annotation" => {
                    return Err(A::Error::custom(format!("duplicate field `{key}`")))
                }
                other => return Err(A::Error::unknown_field(other, KEYS)),
            }
        }
        match (mean, cov, annotation) {
            (Some(mean), Some(cov), None) => Ok(PriorSpec::Full { mean, cov }),
            (None, None, Some(annotation)) => Ok(PriorSpec::Annotation { annotation }),
            (_, _, Some(_)) => Err(A::Error::custom(
                "give the prior either as `mean` and `cov` or as `annotation`, not both",
            )),
            (None, _, None) => Err(A::Error::missing_field("mean")),
            (_, None, None) => Err(A::Error::missing_field("cov")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<PriorSpec, String> {
        serde_json::from_str(text).map_err(|e| e.to_string())
    }

    #[test]
    fn exactly_one_form_is_accepted() {
        assert!(matches!(
            parse(r#"{"mean": [0, 1], "cov": [[1, 0], [0, 1]]}"#),
            Ok(PriorSpec::Full { .. })
        ));
        let a = r#"{"annotation": [{"mean_weights": [[0], [1]], "L": [1, 0, 1]}]}"#;
        assert!(matches!(parse(a), Ok(PriorSpec::Annotation { .. })));
        let both = r#"{"mean": [0], "cov": [[1]], "annotation": []}"#;
        assert!(parse(both).unwrap_err().contains("not both"));
        assert!(parse(r#"{"mean": [0], "cov": [[1]], "extra": 1}"#)
            .unwrap_err()
            .contains("unknown field `extra`, expected one of `mean`, `cov`, `annotation`"));
        assert!(parse(r#"{"cov": [[1]]}"#)
            .unwrap_err()
            .contains("missing field `mean`"));
        assert!(parse(r#"{"mean": [1]}"#)
            .unwrap_err()
            .contains("missing field `cov`"));
        assert!(parse(r#"{"mean": [1], "mean": [2], "cov": [[1]]}"#)
            .unwrap_err()
            .contains("duplicate field `mean`"));
        assert!(parse("[1]").unwrap_err().contains("an object with `mean`"));
    }

    #[test]
    fn lengths_are_capped_while_reading() {
        let long = format!(r#"{{"mean": [{}0], "cov": []}}"#, "0,".repeat(MAX_WEIGHTS));
        assert!(parse(&long).unwrap_err().contains("at most 4096 items"));
        let row = format!(
            r#"{{"mean": [], "cov": [[{}0]]}}"#,
            "0,".repeat(MAX_WEIGHTS)
        );
        assert!(parse(&row).unwrap_err().contains("at most 4096 items"));
    }
}
