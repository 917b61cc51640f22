//! Scoring of found phases against a session's ground truth, and the median of the scores.

use dfs_core::scenario::Phase;
use serde::Serialize;

use super::PhaseSpan;
use crate::session::GroundTruthPhase;

/// Score of a segmentation against ground truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// Absolute boundary errors (ms) of the found truth phases: start and end of each, except
    /// boundaries at the session's start (0) and at the truth's last end.
    pub boundary_errors_ms: Vec<f64>,
    /// Median of `boundary_errors_ms` (0 when empty).
    pub median_boundary_error_ms: f64,
    /// Fraction of truth phases found: a phase of the same name overlaps it by more than 50 %
    /// of its duration (1 when there is no truth).
    pub phases_found_fraction: f64,
}

/// Scores found phases against ground truth (see [`Score`]).
pub fn score(found: &[PhaseSpan], truth: &[GroundTruthPhase]) -> Score {
    let last_end = truth.iter().map(|p| p.end_ns).max().unwrap_or(0);
    let mut errors = Vec::new();
    let mut n_found = 0;
    for t in truth {
        let len = t.end_ns.saturating_sub(t.start_ns).max(1);
        let name = t.name.parse::<Phase>().ok();
        let best = found
            .iter()
            .filter(|f| Some(f.phase) == name)
            .map(|f| {
                let ov = f
                    .end_ns
                    .min(t.end_ns)
                    .saturating_sub(f.start_ns.max(t.start_ns));
                (ov, f)
            })
            .max_by_key(|(ov, _)| *ov);
        if let Some((ov, f)) = best {
            if ov * 2 > len {
                n_found += 1;
                if t.start_ns > 0 {
                    errors.push((f.start_ns as f64 - t.start_ns as f64).abs() * 1e-6);
                }
                if t.end_ns < last_end {
                    errors.push((f.end_ns as f64 - t.end_ns as f64).abs() * 1e-6);
                }
            }
        }
    }
    let median = median(&mut errors.clone());
    Score {
        boundary_errors_ms: errors,
        median_boundary_error_ms: median,
        phases_found_fraction: if truth.is_empty() {
            1.0
        } else {
            n_found as f64 / truth.len() as f64
        },
    }
}

/// Median of values (0 when empty); reorders `v`.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phase_found_exactly_scores_zero_error_and_full_recall() {
        let truth = vec![
            GroundTruthPhase {
                name: "approach".into(),
                start_ns: 0,
                end_ns: 100,
            },
            GroundTruthPhase {
                name: "grasp".into(),
                start_ns: 100,
                end_ns: 300,
            },
        ];
        let found: Vec<PhaseSpan> = truth
            .iter()
            .map(|p| PhaseSpan {
                phase: p.name.parse().unwrap(),
                start_ns: p.start_ns,
                end_ns: p.end_ns,
            })
            .collect();
        let s = score(&found, &truth);
        assert_eq!(s.phases_found_fraction, 1.0);
        assert_eq!(s.median_boundary_error_ms, 0.0);
        assert_eq!(s.boundary_errors_ms.len(), 2);
    }
}
