//! The grammar: each contact episode's moves and the rests between them labelled as phases
//! (`approach` to `retreat`), made well formed whatever the data.

use dfs_core::scenario::Phase;

use super::grid::Grid;
use super::moves::{find_episodes, find_moves, Move};
use super::{PhaseSpan, SegmentParams};

/// The candidate skills of a session whose grid is `g`: each one's phases (log times), well
/// formed ([`well_formed`]), before the checks that need the samples again (carried, a grasp).
pub(super) fn plan(g: &Grid, params: &SegmentParams) -> Vec<Vec<PhaseSpan>> {
    let moves = find_moves(g, params);
    let episodes = find_episodes(g, params);
    let n = g.len();
    let last = (n - 1) as f64;
    let tol = 0.05 / params.grid_s;
    let mut skills_spans: Vec<Vec<(Phase, f64, f64)>> = Vec::new();
    let mut prev_end = 0.0f64;
    let mut mi = 0usize; // first move not yet used
    for (k, &(c0, c1)) in episodes.iter().enumerate() {
        let (c0, c1) = (c0 as f64, c1 as f64);
        let mut spans: Vec<(Phase, f64, f64)> = Vec::new();
        // Moves before the first touch.
        let pre: Vec<Move> = moves[mi..]
            .iter()
            .take_while(|m| m.end <= c0 + tol)
            .copied()
            .collect();
        mi += pre.len();
        let grasp_start = pre.last().map_or(c0, |m| m.end.min(c0));
        if pre.len() >= 2 {
            let p = pre[pre.len() - 1];
            spans.push((Phase::Approach, prev_end, p.start));
            spans.push((Phase::Preshape, p.start, p.end.min(grasp_start)));
        } else {
            spans.push((Phase::Approach, prev_end, grasp_start));
        }
        // Moves after the grasp: in contact, or after a lost contact until the retreat (the
        // first upward move after the contact ended or after a place).
        let next_c0 = episodes.get(k + 1).map(|e| e.0 as f64);
        let mut cursor = grasp_start;
        let mut name_rest = Phase::Grasp;
        let mut last_label = None;
        let mut retreat = None;
        while let Some(m) = moves.get(mi).copied() {
            if next_c0.is_some_and(|c| m.end > c + tol) {
                break;
            }
            let h = m.dp.norm();
            let label = if h < params.rotation_radius * m.angle * 0.5 {
                Phase::Transport
            } else if m.dp.z > params.vertical_fraction * h {
                Phase::Lift
            } else if m.dp.z < -params.vertical_fraction * h {
                Phase::Place
            } else {
                Phase::Transport
            };
            mi += 1;
            if label == Phase::Lift && (m.start > c1 + tol || last_label == Some(Phase::Place)) {
                retreat = Some(m);
                break;
            }
            if m.start - cursor > 0.15 / params.grid_s || name_rest == Phase::Grasp {
                spans.push((name_rest, cursor, m.start));
            } else if let Some(prev) = spans.last_mut() {
                prev.2 = m.start;
            }
            spans.push((label, m.start, m.end));
            cursor = m.end;
            last_label = Some(label);
            name_rest = Phase::Hold;
        }
        if last_label == Some(Phase::Place) {
            name_rest = Phase::Release;
        }
        match retreat {
            Some(r) => {
                spans.push((name_rest, cursor, r.start));
                let end = if next_c0.is_some() { r.end } else { last };
                spans.push((Phase::Retreat, r.start, end));
                prev_end = end;
            }
            None => {
                let end = next_c0.map_or(last, |c| c1.max(cursor).min(c));
                spans.push((name_rest, cursor, end.max(cursor)));
                prev_end = end;
            }
        }
        skills_spans.push(spans);
    }
    well_formed(skills_spans, g, last)
}

/// The skills' spans (grid indices) as phases in ns, well formed whatever the data: every
/// phase non-empty, in time order across all skills, never overlapping, inside the session
/// (`0` to the grid's `last` index); a skill left without a phase is dropped.
///
/// The grammar ([`plan`]) can produce disordered spans on odd recordings: a move that starts
/// before the first touch and ends after it (the approach runs to the touch, the move from its
/// own start), contacts that flicker or come back after the object was dropped, a retreat that
/// runs past the next grasp's start. Each span is clipped to start where the previous phase
/// ended; one left empty goes.
fn well_formed(
    skills_spans: Vec<Vec<(Phase, f64, f64)>>,
    g: &Grid,
    last: f64,
) -> Vec<Vec<PhaseSpan>> {
    let grid_ns = |x: f64| g.t0 + (x.max(0.0) * g.dt_ns as f64).round() as u64;
    // End of the previous phase, as a grid index and in ns.
    let mut floor = 0.0f64;
    let mut floor_ns = g.t0;
    let mut skills = Vec::with_capacity(skills_spans.len());
    for spans in skills_spans {
        let mut phases = Vec::with_capacity(spans.len());
        for (name, a, b) in spans {
            let (a, b) = (a.max(floor), b.min(last));
            if b.partial_cmp(&a) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            // The first phase of a session starts at the session's start, the grid's first
            // sample (log times need not start at 0: real recorders log epoch times).
            let start_ns = grid_ns(a).max(floor_ns);
            let end_ns = grid_ns(b);
            if end_ns <= start_ns {
                continue;
            }
            floor = b;
            floor_ns = end_ns;
            phases.push(PhaseSpan {
                phase: name,
                start_ns,
                end_ns,
            });
        }
        if !phases.is_empty() {
            skills.push(phases);
        }
    }
    skills
}
