//! Segmentation on odd sessions built sample by sample (no simulator): contacts that flicker, an
//! object dropped and grasped again, no contact at all, a session a few samples long, samples
//! out of order or missing, contacts that outlast the object's samples. Whatever the input, the
//! phases found are well formed: each non-empty, in time order across all skills, never
//! overlapping, and inside the session's time span.

use proptest::prelude::*;
use services::foxglove::{Pose, Quaternion, Vector3};
use services::segmentation::{segment, SegmentParams, Segmentation};
use services::session::{Contacts, FingerContact, Intensity4, ObjectState, Session};

const MS: u64 = 1_000_000;

/// One piece of the hand's motion: a rest, or a minimum-jerk move by `d` (m) turning by `turn`
/// (rad about z), `ms` long.
#[derive(Debug, Clone)]
enum Piece {
    Rest { ms: u64 },
    Move { ms: u64, d: [f64; 3], turn: f64 },
}

/// How a session is sampled, and when fingers touch.
#[derive(Debug, Clone)]
struct Plan {
    /// Time of the first object sample (ns): sessions need not start at 0.
    t0_ns: u64,
    /// Sample period (ns).
    period_ns: u64,
    pieces: Vec<Piece>,
    /// Runs of `(ms, fingers in contact)` from `t0_ns`, in order; after the last, none.
    contact_runs: Vec<(u64, usize)>,
    /// Contacts sampled from this offset (ns, may be before the first object sample).
    contact_offset_ns: i64,
    /// Every `drop_every`-th object sample is missing (0: none).
    drop_every: usize,
    /// Swap neighbouring object samples every this many (0: none).
    swap_every: usize,
    /// The session's metadata describes the object.
    with_object: bool,
}

fn min_jerk(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

fn pose(p: [f64; 3], yaw: f64) -> Pose {
    Pose {
        position: Vector3::new(p[0], p[1], p[2]),
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: (0.5 * yaw).sin(),
            w: (0.5 * yaw).cos(),
        },
    }
}

fn finger(name: &str, on: bool, side: f64) -> FingerContact {
    FingerContact {
        name: name.into(),
        touching: on,
        in_contact: on,
        point_b: if on {
            Vector3::new(0.0, side * 0.025, 0.0)
        } else {
            Vector3::default()
        },
        normal_b: if on {
            Vector3::new(0.0, -side, 0.0)
        } else {
            Vector3::default()
        },
        intensity: if on {
            Intensity4 {
                x: 0.1,
                y: 0.0,
                z: 2.0,
                torsion: 0.0,
            }
        } else {
            Intensity4::default()
        },
        in_cone: true,
        ..FingerContact::default()
    }
}

fn build(plan: &Plan) -> Session {
    // The hand's base pose along the pieces; the object sits in the hand (pose_in_hand = I), so
    // the base's motion is the object's.
    let total_ms: u64 = plan
        .pieces
        .iter()
        .map(|p| match p {
            Piece::Rest { ms } | Piece::Move { ms, .. } => *ms,
        })
        .sum();
    let end_ns = plan.t0_ns + total_ms * MS;
    let base_at = |t: u64| -> ([f64; 3], f64) {
        let mut p = [0.0, 0.0, 0.1];
        let mut yaw = 0.0;
        let mut start = plan.t0_ns;
        for piece in &plan.pieces {
            let (ms, d, turn) = match piece {
                Piece::Rest { ms } => (*ms, [0.0; 3], 0.0),
                Piece::Move { ms, d, turn } => (*ms, *d, *turn),
            };
            let stop = start + ms * MS;
            let s = if t >= stop {
                1.0
            } else if t <= start {
                0.0
            } else {
                min_jerk((t - start) as f64 / (stop - start) as f64)
            };
            for k in 0..3 {
                p[k] += s * d[k];
            }
            yaw += s * turn;
            start = stop;
        }
        (p, yaw)
    };
    let mut object = Vec::new();
    let mut t = plan.t0_ns;
    let mut i = 0usize;
    while t <= end_ns {
        i += 1;
        if plan.drop_every == 0 || !i.is_multiple_of(plan.drop_every) {
            let (p, yaw) = base_at(t);
            object.push((
                t,
                ObjectState {
                    pose: pose(p, yaw),
                    pose_in_hand: Pose::default(),
                    ..ObjectState::default()
                },
            ));
        }
        t += plan.period_ns;
    }
    if plan.swap_every > 0 {
        let mut k = 0;
        while k + 1 < object.len() {
            object.swap(k, k + 1);
            k += plan.swap_every;
        }
    }
    let mut contacts = Vec::new();
    let c0 = plan.t0_ns as i64 + plan.contact_offset_ns;
    let mut t = c0.max(0) as u64;
    while t <= end_ns + 200 * MS {
        let since_ms = (t as i64 - c0).max(0) as u64 / MS;
        let mut acc = 0;
        let mut n = 0;
        for &(ms, fingers) in &plan.contact_runs {
            if since_ms < acc + ms {
                n = fingers;
                break;
            }
            acc += ms;
        }
        let fingers = vec![
            finger("thumb", n >= 1, -1.0),
            finger("index", n >= 2, 1.0),
            finger("middle", n >= 3, 1.0),
        ];
        contacts.push((
            t,
            Contacts {
                n_contacts: n as u32,
                fingers,
            },
        ));
        t += plan.period_ns;
    }
    let mut metadata = std::collections::BTreeMap::new();
    if plan.with_object {
        metadata.insert(
            "object".to_owned(),
            r#"{"shape": "box", "half_extents": [0.025, 0.025, 0.04], "mass": 0.2, "mu": 0.8}"#
                .to_owned(),
        );
    }
    Session {
        metadata,
        phases: Vec::new(),
        joint_states: Vec::new(),
        feedback: Vec::new(),
        contacts,
        object,
        message_counts: Default::default(),
        replay: None,
    }
}

/// Every phase non-empty, in time order across skills, not overlapping, inside
/// `[0, last object sample]`; each skill's source span is its phases' span.
fn check(seg: &Segmentation, s: &Session) -> Result<(), String> {
    // Phases are timed from the session's start, its first object sample (sessions need not
    // start at 0).
    let start = s.object.iter().map(|(t, _)| *t).min().unwrap_or(0);
    let end = s.object.iter().map(|(t, _)| *t).max().unwrap_or(0) - start;
    let mut prev_end = 0u64;
    let mut prev_name = String::from("(session start)");
    for (k, skill) in seg.skills.iter().enumerate() {
        if skill.phases.is_empty() {
            return Err(format!("skill {k} has no phase"));
        }
        for p in &skill.phases {
            if p.start_ns >= p.end_ns {
                return Err(format!("skill {k}: empty or reversed phase {p:?}"));
            }
            if p.start_ns < prev_end {
                return Err(format!(
                    "skill {k}: {p:?} starts before the end of {prev_name} at {prev_end}"
                ));
            }
            if p.end_ns > end {
                return Err(format!(
                    "skill {k}: {p:?} ends after the session's last sample at {end}"
                ));
            }
            prev_end = p.end_ns;
            prev_name = format!("{} (skill {k})", p.phase);
        }
        let src = &skill.parameters.source;
        if src.start_ns != skill.phases[0].start_ns || src.end_ns != prev_end {
            return Err(format!(
                "skill {k}: source span {}-{} is not its phases' span",
                src.start_ns, src.end_ns
            ));
        }
    }
    Ok(())
}

fn describe(seg: &Segmentation) -> String {
    seg.skills
        .iter()
        .enumerate()
        .flat_map(|(k, s)| {
            s.phases.iter().map(move |p| {
                format!(
                    "[{k}] {} {:.3}-{:.3}",
                    p.phase,
                    p.start_ns as f64 * 1e-9,
                    p.end_ns as f64 * 1e-9
                )
            })
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Segments the session `plan` builds and panics, naming `case`, unless its phases are well
/// formed.
fn assert_well_formed(case: &str, plan: &Plan) {
    let s = build(plan);
    let seg = segment(&s, &SegmentParams::default());
    if let Err(e) = check(&seg, &s) {
        panic!("{case}: {e}\nphases: {}\nplan: {plan:#?}", describe(&seg));
    }
}

fn reach(ms: u64, d: [f64; 3]) -> Piece {
    Piece::Move { ms, d, turn: 0.0 }
}

fn rest(ms: u64) -> Piece {
    Piece::Rest { ms }
}

/// A pick: reach, close, lift, hold, place, open, retreat (1 ms samples from `t0`).
fn pick(contact_runs: Vec<(u64, usize)>) -> Plan {
    Plan {
        t0_ns: 0,
        period_ns: MS,
        pieces: vec![
            rest(300),
            reach(800, [0.2, 0.0, -0.05]),
            rest(600),
            reach(900, [0.0, 0.0, 0.1]),
            rest(800),
            reach(900, [0.0, 0.0, -0.1]),
            rest(600),
            reach(700, [0.0, -0.15, 0.08]),
            rest(300),
        ],
        contact_runs,
        contact_offset_ns: 0,
        drop_every: 0,
        swap_every: 0,
        with_object: true,
    }
}

#[test]
fn odd_sessions_give_sorted_non_overlapping_phases_inside_the_session() {
    let flicker: Vec<(u64, usize)> = std::iter::once((1300, 0))
        .chain((0..300).map(|i| (5 + i % 7, if i % 2 == 0 { 2 } else { 1 })))
        .collect();
    let regrasp = vec![
        (1200, 0),
        (1500, 2),
        (150, 0),
        (200, 2),
        (500, 0),
        (1400, 3),
    ];
    let cases: Vec<(&str, Plan)> = vec![
        ("one clean grasp", pick(vec![(1600, 0), (2800, 2)])),
        ("contacts flickering every few ms", pick(flicker)),
        ("object dropped and grasped again", pick(regrasp)),
        ("no contact at all", pick(vec![])),
        (
            "in contact from the first sample to the last",
            pick(vec![(10_000, 2)]),
        ),
        (
            "contact long before the first object sample",
            Plan {
                contact_offset_ns: -2_000 * MS as i64,
                t0_ns: 2_500 * MS,
                ..pick(vec![(2_500, 2), (300, 0), (2_800, 2)])
            },
        ),
        (
            "one object sample",
            Plan {
                pieces: vec![rest(0)],
                ..pick(vec![(10, 2)])
            },
        ),
        (
            "two object samples",
            Plan {
                pieces: vec![rest(1)],
                ..pick(vec![(10, 2)])
            },
        ),
        (
            "a 50 ms session in contact",
            Plan {
                pieces: vec![reach(50, [0.0, 0.0, 0.05])],
                ..pick(vec![(50, 2)])
            },
        ),
        (
            "10 ms samples, some missing and some out of order",
            Plan {
                period_ns: 10 * MS,
                drop_every: 7,
                swap_every: 5,
                ..pick(vec![(1600, 0), (2800, 2)])
            },
        ),
        (
            "moves overlapping the first touch",
            Plan {
                pieces: vec![
                    reach(1500, [0.0, 0.0, 0.2]),
                    reach(1500, [0.2, 0.0, 0.0]),
                    reach(1500, [0.0, 0.0, -0.2]),
                ],
                ..pick(vec![(700, 0), (1500, 2), (100, 0), (300, 2), (400, 0)])
            },
        ),
    ];
    for (name, plan) in cases {
        assert_well_formed(name, &plan);
    }
}

fn piece() -> impl Strategy<Value = Piece> {
    prop_oneof![
        (0u64..1500).prop_map(|ms| Piece::Rest { ms }),
        (
            1u64..1500,
            prop::array::uniform3(-0.25f64..0.25),
            prop_oneof![Just(0.0), -1.5f64..1.5]
        )
            .prop_map(|(ms, d, turn)| Piece::Move { ms, d, turn }),
    ]
}

fn plan() -> impl Strategy<Value = Plan> {
    (
        prop_oneof![Just(0u64), 0u64..3_000_000_000],
        prop_oneof![Just(MS), Just(10 * MS), 200_000u64..20_000_000],
        prop::collection::vec(piece(), 0..9),
        prop::collection::vec((0u64..1200, 0usize..4), 0..14),
        -1_000_000_000i64..1_000_000_000,
        prop_oneof![Just(0usize), 2usize..20],
        prop_oneof![Just(0usize), 2usize..20],
        any::<bool>(),
    )
        .prop_map(
            |(t0_ns, period_ns, pieces, contact_runs, off, drop_every, swap_every, obj)| Plan {
                t0_ns,
                period_ns,
                pieces,
                contact_runs,
                contact_offset_ns: off,
                drop_every,
                swap_every,
                with_object: obj,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn any_session_gives_sorted_non_overlapping_phases_inside_the_session(p in plan()) {
        assert_well_formed("generated session", &p);
    }
}
