//! Replay time from the operator's phases as they happen (issue 20, IP-flow 3): a replay
//! driven by the live counterpart of segmentation rather than by a fixed clock.
//!
//! # Spans
//!
//! The skill's [`Timeline`] and its phase list give each phase a span of replay time, in skill
//! order ([`PhaseClock::spans`]):
//!
//! * `approach` and `preshape` share the span before `grasp_start` (the approach's base
//!   motion), split in proportion to their durations in the skill (the timeline makes that
//!   span at least 0.5 s; a skill with neither gets one `approach` span);
//! * `grasp` spans `grasp_start..grasp_end` (the timeline's 0.8 s when the skill has none);
//! * `lift`, `hold` and `transport` span `grasp_end..place_start`, each occurrence with its
//!   own duration, in the skill's order;
//! * `place` spans `place_start..release_start`, `release` `release_start..release_end` (0.6 s
//!   when the skill has none), `retreat` `release_end..end`.
//!
//! Phases of zero duration have no span; neighbouring spans of one phase are one span.
//!
//! # Driving
//!
//! The clock follows the operator's phase ([`PhaseClock::set_phase`]: the operator entered
//! `phase` at `now_s`) and turns real time ([`PhaseClock::advance`]) into replay time:
//!
//! * **Within a phase** the replay time runs at real rate through the phase's span, aligned
//!   with the operator: its target is the span's start plus the time since the operator
//!   entered the phase.
//! * **A phase held longer than the skill's** (a hold held longer): the replay *waits* at the
//!   end of the span, decelerating onto it (the rate falls no faster than [`RATE_SLEW`]), until
//!   the operator moves on.
//! * **A later phase entered early** (the operator moved on before the replay reached the end
//!   of the span): the replay catches up through the spans it has not finished (a phase the
//!   operator skipped included) as fast as it may, back to real rate just as it is in step
//!   with the operator again: its rate changes by at most [`RATE_SLEW`] per second and is at
//!   most [`MAX_CATCH_UP_RATE`] (3× real time) while the hand is free (`approach`,
//!   `preshape`, `release`, `retreat`) and [`MAX_HELD_CATCH_UP_RATE`] (1.25×) from the grasp to
//!   the release (`grasp`, `lift`, `hold`, `transport`, `place`: the fingers closing, and the
//!   object carried along the skill's motion, whose accelerations grow with the square of the
//!   rate while the grip was planned for the skill's own); it slows before a span of a lower
//!   limit so as to enter it within that limit. It never jumps: the replay time is continuous
//!   and so is its rate, up to one slew step a tick (the tick that comes to rest at a span's
//!   end may drop by up to twice that), and so is the motion of the robot's arm, which
//!   follows the skill's at the replay time.
//! * **Phases that are ignored**: one the skill has no span of after the current one (e.g.
//!   `transport` when the skill has none, or a phase that goes backwards: `lift` once the
//!   operator is in `hold`, `grasp` once it is in `lift`); the phase the replay already
//!   follows. Of a phase the skill has more than once, the next occurrence after the current
//!   span is taken (`hold`, `transport`, `hold`: the second `hold` once the operator has
//!   entered `transport`). Until the first accepted phase the clock follows the skill's first
//!   span, entered when the clock started; the first phase may be any of the skill's.
//! * The replay time never runs past the end of the span of the operator's phase: in
//!   particular not past `release_end` until the operator has entered `retreat`, nor into the
//!   release (the grip ramping down) until the operator has entered `release`.

use super::{SkillSpec, Timeline};
use crate::math::Real;
use crate::scenario::Phase;

/// Fastest the replay time runs while it catches up with an operator who moved on early,
/// relative to real time.
pub const MAX_CATCH_UP_RATE: Real = 3.0;

/// Fastest the replay time runs while it catches up from the grasp to the release (the
/// object in the hand), relative to real time.
pub const MAX_HELD_CATCH_UP_RATE: Real = 1.25;

/// Fastest change of the replay's rate (1/s²): from rest to real time in 0.2 s, from real time
/// to rest over 0.1 s of replay time (so the arm, following the skill's motion at the replay
/// time, speeds up and slows down smoothly).
pub const RATE_SLEW: Real = 5.0;

/// A phase's span of replay time (s since the replay's start) and how fast the replay may run
/// through it: [`PhaseClock`]'s own, in seconds of the skill's timeline, not a session's
/// [`PhaseSpan`](crate::scenario::PhaseSpan) (ns since the session's start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockSpan {
    /// The phase.
    pub phase: Phase,
    /// Start (s).
    pub start: Real,
    /// End (s).
    pub end: Real,
    /// Fastest rate of the replay time in the span ([`MAX_CATCH_UP_RATE`] or
    /// [`MAX_HELD_CATCH_UP_RATE`]).
    pub max_rate: Real,
}

/// Turns the operator's phases as they happen into replay time; see the module's doc.
/// Advancing allocates nothing.
#[derive(Debug, Clone)]
pub struct PhaseClock {
    spans: Vec<ClockSpan>,
    end: Real,
    /// The span of the operator's phase.
    current: usize,
    /// A phase was accepted (before that, the first span is followed by default).
    told: bool,
    /// Real time at which the operator entered the current span's phase (s).
    entered: Real,
    /// Real time (s).
    now: Real,
    /// Replay time (s).
    t: Real,
    /// Replay time per real time.
    rate: Real,
}

impl PhaseClock {
    /// A clock for `skill`, its real time starting at 0, its replay time at 0 and at rest.
    pub fn new(skill: &SkillSpec) -> PhaseClock {
        PhaseClock::starting_at(skill, 0.0)
    }

    /// [`PhaseClock::new`] with its real time starting at `now_s` (say, the live session's
    /// time when the replay starts, so that [`PhaseClock::set_phase`] takes session times).
    pub fn starting_at(skill: &SkillSpec, now_s: Real) -> PhaseClock {
        let tl = skill.timeline();
        PhaseClock {
            spans: spans(skill, &tl),
            end: tl.end,
            current: 0,
            told: false,
            entered: now_s,
            now: now_s,
            t: 0.0,
            rate: 0.0,
        }
    }

    /// The operator entered `phase` at `now_s` (real time, on the clock's own base; it may be
    /// before the clock's current time when the phase was known late). `true` when the replay
    /// follows it from now on; `false` when it is ignored (not in the skill after the current
    /// span, going backwards, or the phase the replay already follows; see the module's doc).
    pub fn set_phase(&mut self, phase: Phase, now_s: Real) -> bool {
        if !now_s.is_finite() {
            return false;
        }
        let from = if self.told { self.current + 1 } else { 0 };
        let Some(i) = self.spans[from.min(self.spans.len())..]
            .iter()
            .position(|s| s.phase == phase)
        else {
            return false;
        };
        self.current = from + i;
        self.entered = now_s;
        self.told = true;
        true
    }

    /// Advances real time by `dt` (s) and returns the replay time to step to (s on the skill's
    /// timeline): never decreasing, never past the end of the operator's phase's span.
    pub fn advance(&mut self, dt: Real) -> Real {
        if !(dt.is_finite() && dt > 0.0) {
            return self.t;
        }
        self.now += dt;
        let span = self.spans[self.current];
        // Where the replay would be, aligned with the operator.
        let elapsed = (self.now - self.entered).clamp(0.0, span.end - span.start);
        let target = span.start + elapsed;
        // The rate changes by at most `a` a tick. Slowing by `a` a tick from `c + e` to `c`
        // covers `(e/a) c dt + e (e + a) dt / 2a` of replay time: the largest excess over `c`
        // that still comes down to `c` within `d` is `excess(d, c)`.
        let a = RATE_SLEW * dt;
        let excess = |d: Real, c: Real| {
            let b = a + 2.0 * c;
            0.5 * ((b * b + 8.0 * a * d.max(0.0) / dt).sqrt() - b)
        };
        // Towards the operator: as fast as allows coming back to real rate just as the lag
        // closes (the excess over real rate closes the lag).
        let lag = target - self.t;
        let wanted = if lag >= 0.0 {
            1.0 + excess(lag, 0.0)
        } else {
            1.0 - excess(-lag, 0.0)
        };
        // Within the limit of the span the replay is in and, slowing in time, of those ahead
        // of it up to the operator's, and to rest at the end of the operator's span.
        let here = self.replay_index();
        let mut cap = self.spans[here].max_rate;
        for s in &self.spans[here + 1..=self.current] {
            cap = cap.min(s.max_rate + excess(s.start - self.t, s.max_rate));
        }
        cap = cap.min(excess(span.end - self.t, 0.0));
        let rate = wanted.clamp(self.rate - a, self.rate + a).min(cap).max(0.0);
        let t = (self.t + rate * dt).min(span.end);
        self.rate = (t - self.t) / dt;
        self.t = t;
        self.t
    }

    /// The replay time (s).
    pub fn time(&self) -> Real {
        self.t
    }

    /// The replay time's current rate relative to real time (0 while waiting).
    pub fn rate(&self) -> Real {
        self.rate
    }

    /// Real time (s).
    pub fn now(&self) -> Real {
        self.now
    }

    /// The operator's phase the replay follows (the skill's first phase until one is set).
    pub fn phase(&self) -> Phase {
        self.spans[self.current].phase
    }

    /// The phase of the span the replay time is in (behind the operator's while catching up;
    /// the operator's while waiting at the end of its span).
    pub fn replay_phase(&self) -> Phase {
        self.spans[self.replay_index()].phase
    }

    /// The span the replay time is in (the operator's at its end).
    fn replay_index(&self) -> usize {
        let mut i = self.current;
        while i > 0 && self.t < self.spans[i].start {
            i -= 1;
        }
        i
    }

    /// The spans, in skill order, contiguous from 0 to the timeline's end.
    pub fn spans(&self) -> &[ClockSpan] {
        &self.spans
    }

    /// The replay time reached the timeline's end (the operator is in `retreat` and the
    /// retreat's span is over).
    pub fn is_finished(&self) -> bool {
        self.t >= self.end
    }
}

/// The phases' spans of replay time; see the module's doc.
fn spans(skill: &SkillSpec, tl: &Timeline) -> Vec<ClockSpan> {
    use Phase::*;
    let blocks: [(&[Phase], Real, Real, Option<Phase>); 6] = [
        (&[Approach, Preshape], 0.0, tl.grasp_start, Some(Approach)),
        (&[Grasp], tl.grasp_start, tl.grasp_end, Some(Grasp)),
        (&[Lift, Hold, Transport], tl.grasp_end, tl.place_start, None),
        (&[Place], tl.place_start, tl.release_start, None),
        (&[Release], tl.release_start, tl.release_end, Some(Release)),
        (&[Retreat], tl.release_end, tl.end, Some(Retreat)),
    ];
    let mut out: Vec<ClockSpan> = Vec::new();
    let mut push = |phase: Phase, start: Real, end: Real| {
        if end <= start {
            return;
        }
        let max_rate = match phase {
            Approach | Preshape | Release | Retreat => MAX_CATCH_UP_RATE,
            Grasp | Lift | Hold | Transport | Place => MAX_HELD_CATCH_UP_RATE,
        };
        match out.last_mut() {
            Some(last) if last.phase == phase => last.end = end,
            _ => out.push(ClockSpan {
                phase,
                start,
                end,
                max_rate,
            }),
        }
    };
    for (phases, a, b, default) in blocks {
        let entries = || {
            skill
                .phases
                .iter()
                .filter(|(p, d)| phases.contains(p) && *d > 0.0)
        };
        let total: Real = entries().map(|(_, d)| d).sum();
        if total > 0.0 {
            let n = entries().count();
            let scale = (b - a) / total;
            let mut sum = 0.0;
            for (i, (p, d)) in entries().enumerate() {
                let start = a + sum * scale;
                sum += d;
                let end = if i + 1 == n { b } else { a + sum * scale };
                push(*p, start, end);
            }
        } else if let Some(p) = default {
            push(p, a, b);
        }
    }
    if out.is_empty() {
        // Not for a timeline (its grasp, release and retreat last), but keep one span.
        out.push(ClockSpan {
            phase: Retreat,
            start: 0.0,
            end: tl.end,
            max_rate: MAX_CATCH_UP_RATE,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::{ContactModel, Friction};
    use crate::object::Shape;

    const DT: Real = 1e-3;

    fn skill(phases: &[(Phase, Real)]) -> SkillSpec {
        SkillSpec {
            shape: Shape::Sphere { radius: 0.04 },
            mass: 0.3,
            friction: Friction {
                mu: 0.8,
                mu_torsion: 0.005,
            },
            contact_model: ContactModel::SoftFinger,
            contacts: Vec::new(),
            motion: Vec::new(),
            phases: phases.to_vec(),
            held_until_s: None,
        }
    }

    /// sphere-lift's phases.
    fn sphere_lift() -> SkillSpec {
        use Phase::*;
        skill(&[
            (Approach, 0.8),
            (Preshape, 0.5),
            (Grasp, 0.8),
            (Lift, 1.0),
            (Hold, 2.0),
            (Place, 1.0),
            (Release, 0.6),
            (Retreat, 0.6),
        ])
    }

    /// Advances `clock` by `s` seconds of real time; the largest rate and rate change per
    /// tick seen, and that the replay time never decreased.
    fn run(clock: &mut PhaseClock, s: Real) -> (Real, Real) {
        let (mut top, mut jerk) = (0.0 as Real, 0.0 as Real);
        let n = (s / DT).round() as usize;
        for _ in 0..n {
            let (t0, r0) = (clock.time(), clock.rate());
            let cap = clock.spans()[clock.replay_index()].max_rate;
            let t = clock.advance(DT);
            assert!(t >= t0);
            // Within the limit of the span it was in, and of the one it is in.
            let cap_now = clock.spans()[clock.replay_index()].max_rate;
            assert!(clock.rate() <= cap + 1e-9, "{} > {cap}", clock.rate());
            assert!(clock.rate() <= cap_now + RATE_SLEW * DT + 1e-9);
            let end = clock.spans()[clock.current].end;
            assert!((t - t0 - clock.rate() * DT).abs() < 1e-9 || t == end);
            top = top.max(clock.rate());

            jerk = jerk.max((clock.rate() - r0).abs());
        }
        (top, jerk)
    }

    fn span_of(clock: &PhaseClock, phase: Phase) -> ClockSpan {
        *clock.spans().iter().find(|s| s.phase == phase).unwrap()
    }

    #[test]
    fn the_spans_follow_the_timeline_in_skill_order() {
        use Phase::*;
        let s = sphere_lift();
        let tl = s.timeline();
        let c = PhaseClock::new(&s);
        let phases: Vec<_> = c.spans().iter().map(|s| s.phase).collect();
        assert_eq!(
            phases,
            [Approach, Preshape, Grasp, Lift, Hold, Place, Release, Retreat]
        );
        for w in c.spans().windows(2) {
            assert_eq!(w[0].end, w[1].start);
        }
        assert_eq!(c.spans()[0].start, 0.0);
        assert!((span_of(&c, Preshape).start - 0.8).abs() < 1e-12);
        assert_eq!(span_of(&c, Grasp).start, tl.grasp_start);
        assert!((span_of(&c, Hold).start - (tl.grasp_end + 1.0)).abs() < 1e-12);
        assert_eq!(span_of(&c, Hold).end, tl.place_start);
        assert_eq!(span_of(&c, Release).end, tl.release_end);
        assert_eq!(c.spans().last().unwrap().end, tl.end);

        // A short approach is stretched to the timeline's 0.5 s; a missing grasp gets 0.8 s;
        // repeated phases keep their order; two holds in a row are one span.
        let s = skill(&[
            (Approach, 0.2),
            (Preshape, 0.05),
            (Lift, 0.5),
            (Hold, 0.5),
            (Hold, 0.25),
            (Transport, 1.0),
            (Hold, 0.5),
            (Release, 0.5),
        ]);
        let c = PhaseClock::new(&s);
        let phases: Vec<_> = c.spans().iter().map(|s| s.phase).collect();
        assert_eq!(
            phases,
            [Approach, Preshape, Grasp, Lift, Hold, Transport, Hold, Release, Retreat]
        );
        assert!((c.spans()[1].start - 0.4).abs() < 1e-12);
        assert!((c.spans()[2].end - c.spans()[2].start - 0.8).abs() < 1e-12);
        assert!((c.spans()[4].end - c.spans()[4].start - 0.75).abs() < 1e-12);
    }

    #[test]
    fn at_the_skills_own_times_the_replay_keeps_pace_with_the_operator() {
        let s = sphere_lift();
        let mut c = PhaseClock::new(&s);
        let mut now = 0.0;
        let mut worst: Real = 0.0;
        for &(phase, d) in &s.phases {
            assert!(c.set_phase(phase, now));
            let n = (d / DT).round() as usize;
            for _ in 0..n {
                now += DT;
                c.advance(DT);
                worst = worst.max((now - c.time()).abs());
            }
        }
        // Behind by the ramps and the deceleration at each span's end, caught up after.
        assert!(worst < 0.12, "{worst}");
        run(&mut c, 0.2);
        assert!(c.is_finished());
        assert_eq!(c.time(), s.timeline().end);
    }

    #[test]
    fn a_hold_held_longer_waits_at_the_end_of_its_span() {
        use Phase::*;
        let s = sphere_lift();
        let mut c = PhaseClock::new(&s);
        assert!(c.set_phase(Approach, 0.0));
        run(&mut c, 1.3);
        assert!(c.set_phase(Grasp, 1.3));
        run(&mut c, 0.8);
        assert!(c.set_phase(Lift, 2.1));
        run(&mut c, 1.0);
        assert!(c.set_phase(Hold, 3.1));
        // Held 6 s instead of 2: the replay comes to rest at the hold's end.
        let (_, jerk) = run(&mut c, 6.0);
        let hold = span_of(&c, Hold);
        assert_eq!(c.time(), hold.end);
        assert_eq!(c.rate(), 0.0);
        assert_eq!(c.replay_phase(), Hold);
        assert!(jerk <= 2.0 * RATE_SLEW * DT, "{jerk}");
        // Then the operator places: the replay goes on at real rate.
        assert!(c.set_phase(Place, 9.1));
        run(&mut c, 0.5);
        assert!((c.time() - (hold.end + 0.5)).abs() < 0.06, "{}", c.time());
        assert_eq!(c.replay_phase(), Place);
    }

    #[test]
    fn a_later_phase_entered_early_is_caught_up_at_a_bounded_rate() {
        use Phase::*;
        let s = sphere_lift();
        // The hand free: the operator grasps after 0.3 s of approach (1.3 s in the skill).
        let mut c = PhaseClock::new(&s);
        c.set_phase(Approach, 0.0);
        run(&mut c, 0.3);
        assert!(c.set_phase(Grasp, 0.3));
        let (top, jerk) = run(&mut c, 0.7);
        assert!(top <= MAX_CATCH_UP_RATE + 1e-9 && top > 2.5, "{top}");
        assert!(jerk <= RATE_SLEW * DT + 1e-9, "{jerk}");
        // Into the grasp, with the fingers closing, no faster than the held limit.
        let grasp = span_of(&c, Grasp);
        assert!(c.time() > grasp.start, "{}", c.time());
        let (top, _) = run(&mut c, 0.3);
        let held = MAX_HELD_CATCH_UP_RATE;
        assert!(top <= held + 1e-9 && top > held - 0.01, "{top}");

        // The object held: the operator lifts in 0.8 s rather than 1 s.
        let mut c = PhaseClock::new(&s);
        c.set_phase(Approach, 0.0);
        run(&mut c, 1.3);
        c.set_phase(Grasp, 1.3);
        run(&mut c, 0.8);
        c.set_phase(Lift, 2.1);
        run(&mut c, 0.8);
        assert!(c.set_phase(Hold, 2.9));
        let t0 = c.time();
        let (top, jerk) = run(&mut c, 0.5);
        let held = MAX_HELD_CATCH_UP_RATE;
        assert!(top <= held + 1e-9 && top > held - 0.01, "{top}");
        assert!(jerk <= RATE_SLEW * DT + 1e-9, "{jerk}");
        assert!(c.time() - t0 > 0.6, "{}", c.time() - t0);
        // In step with the operator again before the hold's span ends.
        let (_, jerk) = run(&mut c, 1.2);
        assert!(jerk <= RATE_SLEW * DT + 1e-9, "{jerk}");
        let hold = span_of(&c, Hold);
        assert!(
            (c.time() - (hold.start + 1.7)).abs() < 0.005,
            "{}",
            c.time()
        );
        assert!((c.rate() - 1.0).abs() < 1e-3, "{}", c.rate());
    }

    #[test]
    fn phases_that_go_backwards_or_that_the_skill_lacks_are_ignored() {
        use Phase::*;
        let s = sphere_lift();
        let mut c = PhaseClock::new(&s);
        assert!(c.set_phase(Approach, 0.0));
        assert!(c.set_phase(Grasp, 0.0));
        assert!(c.set_phase(Lift, 0.1));
        // Backwards, the same again, and not in the skill.
        assert!(!c.set_phase(Grasp, 0.2));
        assert!(!c.set_phase(Approach, 0.2));
        assert!(!c.set_phase(Lift, 0.2));
        assert!(!c.set_phase(Transport, 0.2));
        assert_eq!(c.phase(), Lift);
        assert!(c.set_phase(Hold, 0.3));
        assert!(!c.set_phase(Lift, 0.4));
        assert_eq!(c.phase(), Hold);
    }

    #[test]
    fn the_replay_never_runs_past_release_end_before_the_operator_retreats() {
        use Phase::*;
        let s = sphere_lift();
        let tl = s.timeline();
        let mut c = PhaseClock::new(&s);
        c.set_phase(Release, 0.0);
        run(&mut c, 30.0);
        assert_eq!(c.time(), tl.release_end);
        assert!(!c.is_finished());
        assert!(c.set_phase(Retreat, 30.0));
        run(&mut c, 1.0);
        assert!(c.is_finished());
        // With no phase at all, the replay plays the first span and waits.
        let mut c = PhaseClock::starting_at(&s, 100.0);
        run(&mut c, 3.0);
        assert_eq!(c.time(), span_of(&c, Approach).end);
        assert!((c.now() - 103.0).abs() < 1e-9);
    }
}
