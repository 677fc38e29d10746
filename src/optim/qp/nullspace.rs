//! Elimination of equality rows `E z = e` from a QP by a null-space basis.
//!
//! Every feasible `z` is `z_p + N y`, where `z_p` is the minimum-norm
//! solution of `E z = e` and the columns of `N` are an orthonormal basis of
//! the null space of `E`. Because `N` is orthonormal and `z_p` lies in the
//! row space of `E`, an isotropic cost `|z - c|²` stays isotropic in `y`
//! (`|y - Nᵀ(c - z_p)|²` plus a constant), and so does a trust ball. The QP
//! Clarabel sees is then smaller by one variable and one dense row per
//! equality, and the interior-point cost per iteration grows with
//! (rows x variables²): with the 7 start-configuration rows of a 56-weight
//! problem that is about a quarter of each factorisation.

use nalgebra::{DMatrix, DVector};

/// `|R_ii|` below this fraction of the largest counts as a dependent row.
const RANK_TOLERANCE: f64 = 1e-9;
/// Largest residual `|a·z_p - e|` (relative to `1 + |e|`) of a dependent
/// equality that still counts as consistent with the others.
const CONSISTENCY_TOLERANCE: f64 = 1e-8;

/// The affine set `{z : E z = e}` as `z_p + N y`.
#[derive(Clone, Debug)]
pub struct NullSpace {
    /// Minimum-norm point of the set.
    pub particular: DVector<f64>,
    /// Orthonormal basis of the null space of `E` (`dim z x dim y`).
    pub basis: DMatrix<f64>,
}

impl NullSpace {
    /// The set of `equalities` (`a·z = b`) over `dim` coordinates; `None`
    /// when they contradict each other.
    pub fn new(equalities: &[(DVector<f64>, f64)], dim: usize) -> Option<NullSpace> {
        let mut kept: Vec<usize> = (0..equalities.len()).collect();
        loop {
            if kept.is_empty() {
                // Only zero rows: consistent when every right-hand side is 0.
                let consistent = equalities
                    .iter()
                    .all(|(_, b)| b.abs() <= CONSISTENCY_TOLERANCE);
                return consistent.then(|| NullSpace {
                    particular: DVector::zeros(dim),
                    basis: DMatrix::identity(dim, dim),
                });
            }
            let rows_t = DMatrix::from_fn(dim, kept.len(), |r, c| equalities[kept[c]].0[r]);
            let qr = rows_t.qr();
            let r = qr.r();
            let pivots = kept.len().min(dim);
            let largest = (0..pivots).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
            // More rows than coordinates: the rows past `dim` depend on the rest.
            let dependent = (0..pivots)
                .find(|&i| r[(i, i)].abs() <= RANK_TOLERANCE * largest)
                .or((kept.len() > dim).then_some(dim));
            if let Some(i) = dependent {
                kept.remove(i);
                continue;
            }
            let rhs = DVector::from_iterator(kept.len(), kept.iter().map(|&i| equalities[i].1));
            let coeffs = r.transpose().solve_lower_triangular(&rhs)?;
            let particular = qr.q() * coeffs;
            let consistent = equalities.iter().all(|(a, b)| {
                (a.dot(&particular) - b).abs() <= CONSISTENCY_TOLERANCE * (1.0 + b.abs())
            });
            if !consistent {
                return None;
            }
            let mut q_t = DMatrix::identity(dim, dim);
            qr.q_tr_mul(&mut q_t);
            let basis = q_t.rows(kept.len(), dim - kept.len()).transpose();
            return Some(NullSpace { particular, basis });
        }
    }

    /// Dimension of `y`.
    pub fn dim(&self) -> usize {
        self.basis.ncols()
    }

    /// `z_p + N y`.
    pub fn lift(&self, y: &DVector<f64>) -> DVector<f64> {
        &self.particular + &self.basis * y
    }

    /// `Nᵀ (z - z_p)`: the coordinates of `z`'s projection onto the set.
    pub fn coordinates(&self, z: &DVector<f64>) -> DVector<f64> {
        self.basis.tr_mul(&(z - &self.particular))
    }

    /// Squared distance from `z` to the set.
    pub fn distance_squared(&self, z: &DVector<f64>) -> f64 {
        (z - self.lift(&self.coordinates(z))).norm_squared()
    }

    /// A row `a·z` as a row in `y`: coefficients `Nᵀa` and the constant `a·z_p`.
    pub fn row(&self, a: &DVector<f64>) -> (DVector<f64>, f64) {
        (self.basis.tr_mul(a), a.dot(&self.particular))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn random_rows(k: usize, n: usize, seed: u64) -> Vec<(DVector<f64>, f64)> {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        (0..k)
            .map(|_| (DVector::from_fn(n, |_, _| next()), next()))
            .collect()
    }

    proptest! {
        #[test]
        fn the_basis_is_orthonormal_and_spans_the_affine_set(k in 1usize..8, n in 8usize..20, seed in 0u64..1000) {
            let eqs = random_rows(k, n, seed);
            let ns = NullSpace::new(&eqs, n).unwrap();
            prop_assert_eq!(ns.dim(), n - k);
            let gram = ns.basis.tr_mul(&ns.basis);
            prop_assert!((gram - DMatrix::identity(n - k, n - k)).amax() < 1e-12);
            let y = DVector::from_fn(n - k, |i, _| (i as f64 * 0.7).sin());
            let z = ns.lift(&y);
            for (a, b) in &eqs {
                prop_assert!((a.dot(&z) - b).abs() < 1e-10);
                // The basis is orthogonal to every row: N^T a = 0.
                prop_assert!(ns.row(a).0.amax() < 1e-12);
            }
            prop_assert!((ns.coordinates(&z) - &y).amax() < 1e-12);
            // z_p is the minimum-norm point: orthogonal to the null space.
            prop_assert!(ns.basis.tr_mul(&ns.particular).amax() < 1e-12);
        }
    }

    #[test]
    fn isotropic_cost_stays_isotropic() {
        // |z - c|² = |y - N^T(c - z_p)|² + dist(c, set)² for every y.
        let n = 10;
        let eqs = random_rows(3, n, 7);
        let ns = NullSpace::new(&eqs, n).unwrap();
        let c = DVector::from_fn(n, |i, _| (i as f64).cos());
        let c_y = ns.coordinates(&c);
        for t in 0..5 {
            let y = DVector::from_fn(ns.dim(), |i, _| (i as f64 + t as f64).sin());
            let lhs = (ns.lift(&y) - &c).norm_squared();
            let rhs = (&y - &c_y).norm_squared() + ns.distance_squared(&c);
            assert!((lhs - rhs).abs() < 1e-12, "{lhs} vs {rhs}");
        }
    }

    #[test]
    fn dependent_rows_are_dropped_and_contradictions_detected() {
        let n = 6;
        let mut eqs = random_rows(2, n, 3);
        // A consistent combination of the first two.
        let a = &eqs[0].0 * 2.0 - &eqs[1].0;
        let b = 2.0 * eqs[0].1 - eqs[1].1;
        eqs.push((a.clone(), b));
        let ns = NullSpace::new(&eqs, n).unwrap();
        assert_eq!(ns.dim(), n - 2);
        for (a, b) in &eqs {
            assert!((a.dot(&ns.particular) - b).abs() < 1e-10);
        }
        // The same row with another right-hand side contradicts them.
        eqs.push((a, b + 1.0));
        assert!(NullSpace::new(&eqs, n).is_none());
    }

    #[test]
    fn more_rows_than_coordinates_leave_a_point_or_nothing() {
        let n = 3;
        let point = DVector::from_vec(vec![0.5, -1.0, 2.0]);
        let mut eqs: Vec<(DVector<f64>, f64)> = random_rows(5, n, 11)
            .into_iter()
            .map(|(a, _)| {
                let b = a.dot(&point);
                (a, b)
            })
            .collect();
        let ns = NullSpace::new(&eqs, n).unwrap();
        assert_eq!(ns.dim(), 0);
        assert!((&ns.particular - &point).amax() < 1e-10);
        eqs[4].1 += 0.1;
        assert!(NullSpace::new(&eqs, n).is_none());
    }
}
