//! The paper's covariance code: `n(n+1)/2` numbers that pack an LDLᵀ
//! factorisation in the order of TensorFlow Probability's
//! `fill_triangular` (lower).
//!
//! For a code `x` of length `m = n(n+1)/2`, the `n x n` matrix is the lower
//! triangle of `concat(x[n..], reverse(x))` reshaped row-major to `(n, n)`:
//! `[1, 2, 3, 4, 5, 6] -> [[4, 0, 0], [6, 5, 0], [3, 2, 1]]`. Its diagonal is
//! `d` and its strictly lower part the unit lower-triangular `L`;
//! `Sigma = L diag(D) Lᵀ` with `D = d` ([`DiagEncoding::Raw`], annotations)
//! or `D = exp(d)` ([`DiagEncoding::Log`], network output).

use crate::{error::ensure_finite, Error, Result};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// How the diagonal of the code stores `D`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DiagEncoding {
    /// `D = d` (the published annotations).
    Raw,
    /// `D = exp(d)` (the network's prediction).
    Log,
}

/// Smallest `D` used when encoding a singular covariance in [`DiagEncoding::Log`].
pub const LOG_FLOOR: f64 = 1e-30;

/// Matrix size `n` for a code of length `n(n+1)/2`.
pub fn size_for_code_len(len: usize) -> Result<usize> {
    let n = (((8 * len + 1) as f64).sqrt() as usize).saturating_sub(1) / 2;
    if n == 0 || n * (n + 1) / 2 != len {
        return Err(Error::invalid(
            "L",
            format!("length {len} is not n(n+1)/2 for any n >= 1"),
        ));
    }
    Ok(n)
}

/// For each code entry `k`, the `(row, col)` of the lower triangle it fills.
pub fn fill_triangular_index(n: usize) -> Vec<(usize, usize)> {
    let m = n * (n + 1) / 2;
    let mut out = vec![(0, 0); m];
    for r in 0..n {
        for c in 0..=r {
            out[code_index(n, r, c)] = (r, c);
        }
    }
    out
}

/// Code index that lands at `(row, col)` (`col <= row`).
fn code_index(n: usize, row: usize, col: usize) -> usize {
    let m = n * (n + 1) / 2;
    let flat = row * n + col;
    if flat < m - n {
        n + flat
    } else {
        m - 1 - (flat - (m - n))
    }
}

/// TensorFlow Probability's `fill_triangular` (lower).
pub fn fill_triangular(x: &[f64]) -> Result<DMatrix<f64>> {
    let n = size_for_code_len(x.len())?;
    let mut out = DMatrix::zeros(n, n);
    for (k, (r, c)) in fill_triangular_index(n).into_iter().enumerate() {
        out[(r, c)] = x[k];
    }
    Ok(out)
}

/// Inverse of [`fill_triangular`]: the code of a lower-triangular matrix.
pub fn fill_triangular_inverse(m: &DMatrix<f64>) -> Vec<f64> {
    fill_triangular_index(m.nrows())
        .into_iter()
        .map(|(r, c)| m[(r, c)])
        .collect()
}

/// `Sigma = L diag(D) Lᵀ` from a code.
pub fn decode_covariance(code: &[f64], encoding: DiagEncoding) -> Result<DMatrix<f64>> {
    ensure_finite("L", code)?;
    let packed = fill_triangular(code)?;
    let n = packed.nrows();
    let mut l = packed.clone();
    let mut d = nalgebra::DVector::zeros(n);
    for i in 0..n {
        d[i] = match encoding {
            DiagEncoding::Raw => packed[(i, i)],
            DiagEncoding::Log => packed[(i, i)].exp(),
        };
        l[(i, i)] = 1.0;
    }
    if let Some(i) = d.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            format!("L[{}]", code_index(n, i, i)),
            "diagonal overflows",
        ));
    }
    Ok(&l * DMatrix::from_diagonal(&d) * l.transpose())
}

/// The code of a symmetric positive semi-definite matrix (LDLᵀ without
/// pivoting). Pivots that vanish leave their column of `L` at zero; with
/// [`DiagEncoding::Log`] they are floored at [`LOG_FLOOR`].
pub fn encode_covariance(cov: &DMatrix<f64>, encoding: DiagEncoding) -> Result<Vec<f64>> {
    let n = cov.nrows();
    if n == 0 || cov.ncols() != n {
        return Err(Error::invalid(
            "cov",
            format!(
                "expected a non-empty square matrix, got {} x {}",
                cov.nrows(),
                cov.ncols()
            ),
        ));
    }
    ensure_finite("cov", cov.as_slice())?;
    let (l, d) = ldl(cov);
    // Pivots of a rank-deficient matrix come out as round-off of either sign;
    // only a negative pivot beyond that round-off means "indefinite".
    let roundoff = cov.diagonal().amax() * 1e-12;
    let mut packed = l;
    for i in 0..n {
        packed[(i, i)] = match encoding {
            DiagEncoding::Raw => d[i],
            DiagEncoding::Log => {
                if d[i] < -roundoff {
                    return Err(Error::invalid(
                        "cov",
                        format!("not positive semi-definite (pivot {i} is {})", d[i]),
                    ));
                }
                d[i].max(LOG_FLOOR).ln()
            }
        };
    }
    Ok(fill_triangular_inverse(&packed))
}

/// Unit lower-triangular `L` and diagonal `d` with `A = L diag(d) Lᵀ`.
fn ldl(a: &DMatrix<f64>) -> (DMatrix<f64>, Vec<f64>) {
    let n = a.nrows();
    let mut l = DMatrix::identity(n, n);
    let mut d = vec![0.0; n];
    let tiny = 1e-300_f64.max(a.amax() * 1e-15);
    for j in 0..n {
        let s: f64 = (0..j).map(|k| l[(j, k)] * l[(j, k)] * d[k]).sum();
        d[j] = a[(j, j)] - s;
        for i in j + 1..n {
            let s: f64 = (0..j).map(|k| l[(i, k)] * l[(j, k)] * d[k]).sum();
            l[(i, j)] = if d[j].abs() > tiny {
                (a[(i, j)] - s) / d[j]
            } else {
                0.0
            };
        }
    }
    (l, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn fill_triangular_matches_the_reference_example() {
        let m = fill_triangular(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let expected =
            DMatrix::from_row_slice(3, 3, &[4.0, 0.0, 0.0, 6.0, 5.0, 0.0, 3.0, 2.0, 1.0]);
        assert_eq!(m, expected);
        assert_eq!(
            fill_triangular_inverse(&m),
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
        );
    }

    #[test]
    fn index_map_is_a_bijection_onto_the_lower_triangle() {
        for n in 1..10 {
            let idx = fill_triangular_index(n);
            let mut seen = std::collections::HashSet::new();
            for &(r, c) in &idx {
                assert!(c <= r && r < n);
                assert!(seen.insert((r, c)));
            }
            assert_eq!(seen.len(), n * (n + 1) / 2);
        }
    }

    #[test]
    fn code_round_trips_exactly_both_ways() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for encoding in [DiagEncoding::Raw, DiagEncoding::Log] {
            for _ in 0..20 {
                let mut code: Vec<f64> = (0..36).map(|_| rng.gen_range(-2.0..2.0)).collect();
                if encoding == DiagEncoding::Raw {
                    for (k, (r, c)) in fill_triangular_index(8).into_iter().enumerate() {
                        if r == c {
                            code[k] = rng.gen_range(0.1..3.0);
                        }
                    }
                }
                let cov = decode_covariance(&code, encoding).unwrap();
                let back = encode_covariance(&cov, encoding).unwrap();
                for (a, b) in code.iter().zip(&back) {
                    assert!(
                        (a - b).abs() < 1e-9 * (1.0 + a.abs()),
                        "{encoding:?}: {a} vs {b}"
                    );
                }
                let again = decode_covariance(&back, encoding).unwrap();
                assert!((&again - &cov).amax() < 1e-10 * (1.0 + cov.amax()));
            }
        }
    }

    #[test]
    fn bad_codes_are_rejected() {
        assert_eq!(
            decode_covariance(&[1.0; 7], DiagEncoding::Raw)
                .unwrap_err()
                .field(),
            Some("L")
        );
        assert_eq!(
            decode_covariance(&[1.0, f64::NAN, 1.0], DiagEncoding::Raw)
                .unwrap_err()
                .field(),
            Some("L[1]")
        );
        assert!(decode_covariance(&[1000.0, 0.0, 0.0], DiagEncoding::Log).is_err());
    }

    #[test]
    fn rank_deficient_covariances_encode_and_indefinite_ones_do_not() {
        // Rank 2 in 4 dimensions: the round-off pivots must not count as negative.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let a = DMatrix::from_fn(4, 2, |_, _| rng.gen_range(-40.0..40.0));
        let cov = &a * a.transpose();
        let code = encode_covariance(&cov, DiagEncoding::Log).unwrap();
        let back = decode_covariance(&code, DiagEncoding::Log).unwrap();
        assert!((&back - &cov).amax() < 1e-8 * cov.amax());
        let indefinite = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        let err = encode_covariance(&indefinite, DiagEncoding::Log).unwrap_err();
        assert_eq!(err.field(), Some("cov"));
    }
}
