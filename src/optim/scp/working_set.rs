//! Which candidate rows a QP starts with and which it gains.
//!
//! A QP of the SCP loop has thousands of candidate rows (every joint limit,
//! velocity limit and linearised clearance at every optimisation phase), but
//! at its optimum only a few dozen are active, and Clarabel's cost grows with
//! every dense row it is given. So each QP is solved on a small working set
//! and grown by constraint generation: after a solve, every candidate row the
//! solution violates is a candidate for the next round; the loop ends when
//! none is violated, and then the solution is the optimum of the full QP (a
//! relaxation whose optimum is feasible for the full problem is optimal for
//! it). This module picks the rows of each round; `scp` runs the rounds.
//!
//! Constraints are smooth in time, so of a run of neighbouring phases of one
//! constraint (one joint bound, one robot-shape/obstacle pair) the local
//! maxima of the violation and every [`RUN_STRIDE`]-th phase suffice to
//! steer the QP's first working set; generation adds every row a solution
//! breaks, unthinned (each round is a re-solve, and thinning there cost more
//! rounds than the rows it saved: hard set −10 % in total, p90 −24 %;
//! docs/experiments.md).

use std::collections::BTreeMap;

/// Of a run of phases of one constraint, every this-many-th phase is taken.
pub const RUN_STRIDE: usize = 8;

/// One candidate row seen by [`thin_in_time`].
#[derive(Clone, Copy, Debug)]
pub struct Candidate<K> {
    /// The constraint the row samples (rows of one key form a curve in time).
    pub key: K,
    /// Phase of the row.
    pub phase: f64,
    /// How strongly the row asks to be included (larger: more violated).
    pub score: f64,
    /// Whether the row is in the band that may be included at all.
    pub in_band: bool,
}

/// Indices (ascending) of the candidates to include: per key, the in-band
/// rows that are local maxima of `score` along the phase, plus every
/// [`RUN_STRIDE`]-th row of each run of consecutive in-band rows. Every key
/// with an in-band row keeps at least one, so a generation round that passes
/// only violated rows always adds one.
pub fn thin_in_time<K: Ord + Copy>(candidates: &[Candidate<K>]) -> Vec<usize> {
    let mut by_key: BTreeMap<K, Vec<usize>> = BTreeMap::new();
    for (i, c) in candidates.iter().enumerate() {
        by_key.entry(c.key).or_default().push(i);
    }
    let mut keep = Vec::new();
    for mut group in by_key.into_values() {
        group.sort_by(|&a, &b| candidates[a].phase.total_cmp(&candidates[b].phase));
        let mut run = 0usize;
        for (e, &i) in group.iter().enumerate() {
            let c = &candidates[i];
            if !c.in_band {
                run = 0;
                continue;
            }
            run += 1;
            let score_at =
                |k: Option<&usize>| k.map_or(f64::NEG_INFINITY, |&k| candidates[k].score);
            let before = score_at(e.checked_sub(1).and_then(|k| group.get(k)));
            let after = score_at(group.get(e + 1));
            let maximum = c.score >= before && c.score >= after;
            if maximum || (run - 1).is_multiple_of(RUN_STRIDE) {
                keep.push(i);
            }
        }
    }
    keep.sort_unstable();
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(key: u8, scores: &[f64], band: f64) -> Vec<Candidate<u8>> {
        scores
            .iter()
            .enumerate()
            .map(|(i, &s)| Candidate {
                key,
                phase: i as f64 / 10.0,
                score: s,
                in_band: s > band,
            })
            .collect()
    }

    #[test]
    fn keeps_the_run_start_every_stride_th_row_and_the_peak() {
        // Out of band, then a rising run of 2 x RUN_STRIDE + 2 rows with a
        // peak two before its end, then out of band again: the last row is
        // a local maximum too.
        let len = 2 * RUN_STRIDE + 2;
        let peak = len - 2;
        let mut scores = vec![-1.0];
        scores.extend((1..=len).map(|i| if i == peak { 10.0 } else { i as f64 * 0.1 }));
        scores.push(-1.0);
        let kept = thin_in_time(&curve(0, &scores, 0.0));
        let mut expect = vec![1, 1 + RUN_STRIDE, 1 + 2 * RUN_STRIDE, peak, len];
        expect.sort_unstable();
        expect.dedup();
        assert_eq!(kept, expect);
    }

    #[test]
    fn out_of_band_rows_are_never_kept_and_keys_are_separate() {
        let mut c = curve(0, &[-3.0, -1.0, -2.0], 0.0);
        c.extend(curve(1, &[0.5, 0.1, 0.2], 0.0));
        // Key 0 has no in-band row; key 1 keeps its run start, and its
        // maxima (0.5 at the start, 0.2 at the end).
        assert_eq!(thin_in_time(&c), vec![3, 5]);
    }

    #[test]
    fn a_group_with_an_in_band_row_keeps_at_least_one_whatever_the_order() {
        let mut c = curve(7, &[0.3, 0.2, 0.4, 0.1, 0.6], 0.0);
        c.reverse();
        let kept = thin_in_time(&c);
        assert!(!kept.is_empty());
        // The global maximum (0.6) is always a local maximum.
        assert!(kept.iter().any(|&i| c[i].score == 0.6));
    }
}
