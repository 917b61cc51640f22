//! The moves of the hand's base on the grid (speed thresholds with hysteresis, refined by
//! minimum-jerk fits) and the contact episodes: what the grammar labels.

use dfs_core::math::Vector;

use super::grid::Grid;
use super::SegmentParams;

/// A move of the hand's base: grid indices of its refined start and end, and its displacement.
#[derive(Debug, Clone, Copy)]
pub(super) struct Move {
    pub(super) start: f64,
    pub(super) end: f64,
    pub(super) dp: Vector,
    pub(super) angle: f64,
}

/// The speed of the hand's base at each grid point (m/s): linear plus
/// [`SegmentParams::rotation_radius`] × angular, central differences over ± `window_s`.
fn speed_profile(g: &Grid, params: &SegmentParams, window_s: f64) -> Vec<f64> {
    let n = g.len();
    let w = ((window_s / params.grid_s).round() as usize).max(1);
    let dt = g.dt_ns as f64 * 1e-9;
    (0..n)
        .map(|i| {
            let a = i.saturating_sub(w);
            let b = (i + w).min(n - 1);
            if b <= a {
                return 0.0;
            }
            let span = (b - a) as f64 * dt;
            let lin = (g.base_p[b] - g.base_p[a]).norm();
            let ang = g.angle(a, b);
            (lin + params.rotation_radius * ang) / span
        })
        .collect()
}

/// Runs of `speed` above `enter` (extended back and forward to where it is below `exit`)
/// inside `[from, to)`.
fn hysteresis(speed: &[f64], enter: f64, exit: f64, from: usize, to: usize) -> Vec<(usize, usize)> {
    let mut raw = Vec::new();
    let mut start: Option<usize> = None;
    for i in from..to {
        let v = speed[i];
        match start {
            None if v > enter => {
                let mut s = i;
                while s > from && speed[s - 1] > exit {
                    s -= 1;
                }
                start = Some(s);
            }
            Some(s) if v < exit => {
                raw.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        raw.push((s, to.saturating_sub(1)));
    }
    raw
}

/// A minimum-jerk fit of the hand's motion over the grid window `[a, b]`: the times (grid
/// indices) at which it covered 10 %, 50 % and 90 % of the window's displacement give the
/// move's start and end. Also the displacement and rotation vector over the window.
struct Fit {
    start: f64,
    end: f64,
    dp: Vector,
    rv: Vector,
}

/// The [`Fit`] of the window `[a, b]`; `tau10` is the time (fraction of the whole) at which a
/// minimum-jerk profile covers 10 %.
fn fit_min_jerk(g: &Grid, params: &SegmentParams, a: usize, b: usize, tau10: f64) -> Fit {
    let dp = g.base_p[b] - g.base_p[a];
    let ra = g.rot(a).inverse();
    let rv = (ra * g.rot(b)).scaled_axis();
    let d2 = (dp.norm_squared() + (params.rotation_radius * rv.norm()).powi(2)).max(1e-30);
    // Progress along the window's displacement (translation and rotation together). A
    // rotation under 1 % of the displacement is left out: it changes the progress by less than
    // 1e-4, and its rotations cost most of the time on a long window.
    let turns = (params.rotation_radius * rv.norm()).powi(2) > 1e-4 * d2;
    let progress = |i: usize| -> f64 {
        let p = g.base_p[i] - g.base_p[a];
        let r = if turns {
            params.rotation_radius.powi(2) * (ra * g.rot(i)).scaled_axis().dot(&rv)
        } else {
            0.0
        };
        (p.dot(&dp) + r) / d2
    };
    // First crossings of 10 %, 50 % and 90 %, in one pass.
    let levels = [0.1, 0.5, 0.9];
    let mut at = [b as f64; 3];
    let mut k = 0;
    let mut prev = progress(a);
    for i in a + 1..=b {
        let cur = progress(i);
        while k < 3 && cur >= levels[k] {
            let f = if cur > prev {
                (levels[k] - prev) / (cur - prev)
            } else {
                1.0
            };
            at[k] = (i - 1) as f64 + f.clamp(0.0, 1.0);
            k += 1;
        }
        if k == 3 {
            break;
        }
        prev = cur;
    }
    let [t10, t50, t90] = at;
    let dur = (t90 - t10) / (1.0 - 2.0 * tau10);
    Fit {
        start: t50 - 0.5 * dur,
        end: t50 + 0.5 * dur,
        dp,
        rv,
    }
}

/// The moves of the hand's base on the grid `g`, in time order and not overlapping: each
/// window that holds one ([`move_windows`]) refined by minimum-jerk fits ([`fit_moves`]).
pub(super) fn find_moves(g: &Grid, params: &SegmentParams) -> Vec<Move> {
    let raw = move_windows(g, params);
    let mut moves = fit_moves(g, params, &raw);
    // Neighbouring moves must not overlap after refinement.
    for i in 1..moves.len() {
        if moves[i].start < moves[i - 1].end {
            let m = 0.5 * (moves[i].start + moves[i - 1].end);
            moves[i].start = m;
            moves[i - 1].end = m;
        }
    }
    moves
}

/// The grid windows `(start, end)` that may hold a move, sorted: the runs of the speed above
/// the fast thresholds (extended over their slow start and end), the runs of the slower speed
/// in the rests between them, and the rests whose ends are [`SegmentParams::slow_move_m`] apart.
fn move_windows(g: &Grid, params: &SegmentParams) -> Vec<(usize, usize)> {
    let n = g.len();
    let speed = speed_profile(g, params, params.speed_window_s);
    let mut raw = hysteresis(
        &speed,
        params.move_enter_speed,
        params.move_exit_speed,
        0,
        n,
    );
    // A wider window (less noise) for slow motion, with a quarter of the thresholds.
    let slow = speed_profile(g, params, 3.0 * params.speed_window_s);
    let slow_exit = 0.25 * params.move_exit_speed;
    // A long, gentle move (a retreat stretched over many seconds by `--duration`) spends its
    // first and last seconds below the fast exit speed: extend each fast run outward while the
    // hand is still moving at the slow exit speed, up to its neighbours. Otherwise the slow pass
    // below finds its slow start and end as moves of their own (a 2 mm "retreat" ahead of the
    // real one, which then started 0.7 s late).
    for i in 0..raw.len() {
        let lo = if i > 0 { raw[i - 1].1 } else { 0 };
        let hi = raw.get(i + 1).map_or(n.saturating_sub(1), |r| r.0);
        let (mut a, mut b) = raw[i];
        while a > lo && slow[a - 1] > slow_exit {
            a -= 1;
        }
        while b < hi && slow[b + 1] > slow_exit {
            b += 1;
        }
        raw[i] = (a, b);
    }
    // Second pass for slow, small moves in the rests between the fast ones.
    let margin = (3.0 * params.speed_window_s / params.grid_s) as usize;
    let mut gaps = Vec::new();
    let mut prev = 0usize;
    for &(a, b) in &raw {
        gaps.push((prev, a.saturating_sub(margin)));
        prev = (b + margin).min(n);
    }
    gaps.push((prev, n));
    for (a, b) in gaps {
        if b > a {
            raw.extend(hysteresis(
                &slow,
                0.25 * params.move_enter_speed,
                slow_exit,
                a,
                b,
            ));
        }
    }
    raw.sort_unstable();
    // Last, moves too slow for either threshold (a 0.1 m retreat stretched over two minutes
    // peaks at 1.6 mm/s): a rest between the runs at whose ends the hand is
    // [`SegmentParams::slow_move_m`] apart held a move; the fit below finds it in the rest.
    let mut prev = 0usize;
    let mut slow_moves = Vec::new();
    for &(a, b) in raw.iter().chain(std::iter::once(&(n - 1, n - 1))) {
        if a > prev && (g.base_p[a] - g.base_p[prev]).norm() >= params.slow_move_m {
            slow_moves.push((prev, a));
        }
        prev = prev.max(b);
    }
    if !slow_moves.is_empty() {
        raw.extend(slow_moves);
        raw.sort_unstable();
    }
    raw
}

/// The move in each of the sorted windows `raw` ([`move_windows`]), its start and end refined
/// by minimum-jerk fits ([`fit_min_jerk`]); windows too short or too small hold none.
fn fit_moves(g: &Grid, params: &SegmentParams, raw: &[(usize, usize)]) -> Vec<Move> {
    let n = g.len();
    let dt = g.dt_ns as f64 * 1e-9;
    let tau10 = dfs_core::min_jerk::time_at_progress(0.1);
    let mut moves = Vec::new();
    for (i, &(a, b)) in raw.iter().enumerate() {
        if (b - a) as f64 * dt < params.min_move_s {
            continue;
        }
        let mut fit = fit_min_jerk(g, params, a, b, tau10);
        let d2 = fit.dp.norm_squared() + (params.rotation_radius * fit.rv.norm()).powi(2);
        if d2.sqrt() < params.min_move_m {
            continue;
        }
        // The thresholds cut off the move's slow start and end, which for a long move can be a
        // large part of it: widen the window to the fit's start and end (plus a quarter of its
        // duration) within the rests around it, and fit again, until it holds the whole move.
        // Rests add nothing to the displacement, so the fit then sees the complete profile.
        let lo = if i > 0 { raw[i - 1].1.min(a) } else { 0 };
        let hi = raw.get(i + 1).map_or(n - 1, |r| r.0.max(b));
        let (mut wa, mut wb) = (a, b);
        for _ in 0..6 {
            let pad = 0.25 * (fit.end - fit.start).max(0.0);
            let na = (fit.start - pad).floor().max(lo as f64) as usize;
            let nb = ((fit.end + pad).ceil().min(hi as f64) as usize).max(na);
            if na >= wa && nb <= wb {
                break;
            }
            (wa, wb) = (wa.min(na), wb.max(nb));
            fit = fit_min_jerk(g, params, wa, wb, tau10);
        }
        let (mut s, mut e) = (fit.start, fit.end);
        // The fit should not move a boundary far outside what the threshold saw.
        let slack = 0.3 * (b - a) as f64;
        s = s.clamp(a as f64 - slack, a as f64 + slack).max(0.0);
        e = e
            .clamp(b as f64 - slack, b as f64 + slack)
            .min((n - 1) as f64);
        moves.push(Move {
            start: s,
            end: e,
            dp: fit.dp,
            angle: fit.rv.norm(),
        });
    }
    moves
}

/// The contact episodes on the grid `g`: runs of grid points touching (two fingers or more),
/// gaps shorter than [`SegmentParams::contact_gap_s`] bridged, those shorter than
/// [`SegmentParams::min_contact_s`] dropped.
pub(super) fn find_episodes(g: &Grid, params: &SegmentParams) -> Vec<(usize, usize)> {
    let mut eps: Vec<(usize, usize)> = Vec::new();
    let mut start = None;
    for i in 0..=g.len() {
        let on = i < g.len() && g.touching[i];
        match (start, on) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                eps.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    let gap = (params.contact_gap_s / params.grid_s) as usize;
    let mut merged: Vec<(usize, usize)> = Vec::new();
    for e in eps {
        match merged.last_mut() {
            Some(last) if e.0 - last.1 <= gap => last.1 = e.1,
            _ => merged.push(e),
        }
    }
    let min = (params.min_contact_s / params.grid_s) as usize;
    merged.retain(|(a, b)| b - a >= min);
    merged
}
