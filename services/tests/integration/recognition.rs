//! Recognition (issue 20) on simulated sessions.

use dfs_core::scenario::Scenario;
use std::ops::RangeInclusive;

use services::assist::evaluate::{evaluate, EvalSetup, Evaluation};
use services::assist::recognise::RecogniserParams;

const KINDS: [&str; 3] = ["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"];

/// Variants `seeds` of each of the built-in scenarios `kinds`.
fn variants(kinds: &[&str], seeds: RangeInclusive<u64>) -> Vec<Scenario> {
    kinds
        .iter()
        .flat_map(|k| seeds.clone().map(move |s| Scenario::variant(k, s).unwrap()))
        .collect()
}

/// The sessions of `test` recognised with `params` against the skills stored from `train`, in a
/// data base of their own.
fn evaluated(train: Vec<Scenario>, test: Vec<Scenario>, params: RecogniserParams) -> Evaluation {
    let dir = tempfile::tempdir().unwrap();
    evaluate(EvalSetup {
        train,
        test,
        dir: dir.path(),
        params,
        cost_skills: None,
        progress: &mut |_, _| {},
    })
    .unwrap()
}

/// Skills of three grasp kinds stored from seeds 1-3; seeds 101-102 recognised as they stream:
/// the target and a skill of the kind named 200 ms before the first contact, and a kind left
/// out of the data base flagged unknown and stored as new. (`icms bench recognition` measures
/// the same on varied operators and more seeds.)
#[test]
fn grasps_are_anticipated_and_an_absent_kind_is_unknown_and_learned() {
    let e = evaluated(
        variants(&KINDS, 1..=3),
        variants(&KINDS, 101..=102),
        RecogniserParams::default(),
    );
    let report = serde_json::to_string_pretty(&e).unwrap();
    assert_eq!(e.sessions.len(), 6);
    assert!(e.anticipated_fraction >= 0.9, "{report}");
    assert!(e.median_lead_ms >= 200.0, "{report}");
    assert_eq!(e.open_set.len(), 6);
    assert!(e.unknown_fraction >= 0.9, "{report}");
    assert!(e.stored_as_new_fraction >= 0.9, "{report}");
}

/// Within 1 s of the touch the grasp stage names the stored skill nearest the completed grasp
/// (by the whole feature vector, as `similar`), although the held force and what the grasp does
/// next are not seen yet: the held force is the grip then times the ratio the stored grasps of
/// the kind keep, and what comes next is that of the stored grasps done in a scene like this
/// one. The data base holds twins: a ball grasped alone (held 2 s) and the same ball among
/// three objects (held 1 s, `table-three` of the same seed), which only the scene tells apart.
/// (All 24 named; predicting the held force from μ and leaving out what comes next, as before,
/// named 18.)
#[test]
fn the_nearest_stored_skill_is_named_within_a_second_of_the_touch() {
    let kinds = ["sphere-lift", "table-three", "box-pinch-lift"];
    let e = evaluated(
        variants(&kinds, 1..=3),
        variants(&kinds, 1000..=1007),
        RecogniserParams::default(),
    );
    let report = serde_json::to_string_pretty(&e.sessions).unwrap();
    assert_eq!(e.sessions.len(), 24);
    for s in &e.sessions {
        eprintln!(
            "{} {}: nearest {:?}, named by 1 s: {}",
            s.scenario, s.seed, s.nearest_skill_id, s.nearest_named
        );
    }
    assert!(
        e.nearest_fraction >= 0.9,
        "{}: {report}",
        e.nearest_fraction
    );
}

/// Ingest builds the approach templates from the messages segmentation's first pass kept; a
/// session too long for the kept budget reads its file again. Both give the templates a plain
/// second read of the file gives (a scene of three objects, so the target is looked up too).
#[test]
fn templates_from_kept_messages_equal_those_of_a_second_read() {
    use services::assist::features::TEMPLATE_DIM;
    use services::assist::offline::{approach_templates, APPROACH_TOPICS};
    use services::mcap_io::ReadLimits;
    use services::segmentation::{segment_source_keeping, SegmentParams};
    use services::session::{record_simulation, KeptMessages, SessionSource, KEPT_MESSAGES_BUDGET};

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("three.mcap");
    let scenario = Scenario::variant("table-three", 7).unwrap();
    record_simulation(&scenario, None, &path, |_, _| {}).unwrap();
    let source = SessionSource::File(&path);
    let limits = ReadLimits::streaming();
    let params = SegmentParams::default();
    for budget in [KEPT_MESSAGES_BUDGET, 4096] {
        let mut kept = KeptMessages::new(budget).also(APPROACH_TOPICS);
        let (head, seg) = segment_source_keeping(&source, &limits, &params, &mut kept).unwrap();
        assert!(!seg.skills.is_empty());
        assert_eq!(kept.covers(APPROACH_TOPICS), budget == KEPT_MESSAGES_BUDGET);
        let m = &head.metadata;
        let from_kept = approach_templates(&source, Some(&kept), m, &seg.skills, None).unwrap();
        let from_file = approach_templates(&source, None, m, &seg.skills, None).unwrap();
        assert!(from_file.iter().all(Option::is_some), "{from_file:?}");
        // Bit for bit (NaN marks a checkpoint never reached, so compare the bits).
        let bits = |t: &[Option<[f32; TEMPLATE_DIM]>]| -> Vec<Vec<u32>> {
            t.iter()
                .map(|t| t.unwrap().iter().map(|x| x.to_bits()).collect())
                .collect()
        };
        assert_eq!(bits(&from_kept), bits(&from_file), "budget {budget}");
    }
}

/// The grasp stage computes its grasp quality a part at a time (`grasp_budget` per
/// observation period, in slices of `grasp_slice`, the first in the observation and the others
/// in `work` calls after it): the grasp-stage verdicts name the same objects, skills and
/// distances as when the quality is computed in one observation; only when they are said
/// differs.
#[test]
fn a_grasp_stage_decided_a_part_at_a_time_names_what_one_decided_at_once_names() {
    use services::assist::recognise::{Stage, Verdict};
    let grasp_verdicts = |grasp_budget: usize, grasp_slice: usize| {
        let e = evaluated(
            variants(&KINDS, 1..=2),
            variants(&KINDS, 201..=201),
            RecogniserParams {
                grasp_budget,
                grasp_slice,
                ..RecogniserParams::default()
            },
        );
        e.sessions
            .iter()
            .map(|s| {
                s.verdicts
                    .iter()
                    .filter(|v| v.stage() == Stage::Grasp)
                    .map(|v| match v {
                        Verdict::Recognised {
                            object,
                            skill,
                            runners_up,
                            ..
                        } => (
                            object.clone(),
                            Some((skill.skill_id, skill.distance)),
                            runners_up.iter().map(|c| c.skill_id).collect::<Vec<_>>(),
                        ),
                        Verdict::Unknown {
                            object, nearest, ..
                        } => (
                            object.clone(),
                            nearest.as_ref().map(|c| (c.skill_id, c.distance)),
                            Vec::new(),
                        ),
                    })
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let defaults = RecogniserParams::default();
    assert!(defaults.grasp_slice < defaults.grasp_budget);
    let sliced = grasp_verdicts(defaults.grasp_budget, defaults.grasp_slice);
    let at_once = grasp_verdicts(usize::MAX, usize::MAX);
    assert_eq!(sliced.len(), KINDS.len());
    assert!(
        sliced.iter().filter(|v| !v.is_empty()).count() >= 2,
        "too few grasp-stage verdicts to compare: {sliced:?}"
    );
    assert_eq!(sliced, at_once);
}

/// A power grasp's palm and phalanges are contacts of its stored skill (its contact count, grasp
/// quality and mean normal count them), so the grasp stage counts them in its query too: a
/// session recognised against a data base holding its own skill among others of its kind finds
/// its own skill within 2 (0.25-0.75 here; the grasp's first 0.8 s are not its whole hold, so
/// its own is not always the closest). Counting fingertips only, the query was about 6 away.
#[test]
fn a_power_grasps_query_counts_its_palm_and_phalanges_as_its_stored_skill_does() {
    use services::assist::recognise::{Stage, Verdict};
    let power = ["cylinder-power-grasp"];
    let e = evaluated(
        variants(&power, 1..=4),
        variants(&power, 1..=4),
        RecogniserParams::default(),
    );
    let report = serde_json::to_string_pretty(&e).unwrap();
    for s in &e.sessions {
        let own = s
            .nearest_skill_id
            .expect("the held-out session is its own stored skill");
        let grasp = s
            .verdicts
            .iter()
            .find(|v| v.stage() == Stage::Grasp)
            .unwrap_or_else(|| panic!("no grasp-stage verdict for seed {}: {report}", s.seed));
        let Verdict::Recognised {
            skill, runners_up, ..
        } = grasp
        else {
            panic!("seed {}: the grasp stage said unknown: {report}", s.seed);
        };
        eprintln!(
            "seed {}: named {} at {:.3}, own {own}, runners-up {:?}",
            s.seed,
            skill.skill_id,
            skill.distance,
            runners_up
                .iter()
                .map(|c| (c.skill_id, c.distance))
                .collect::<Vec<_>>()
        );
        let to_own = std::iter::once(skill)
            .chain(runners_up)
            .find(|c| c.skill_id == own)
            .map(|c| c.distance);
        assert!(
            to_own.is_some_and(|d| d < 2.0),
            "seed {}: own skill at {to_own:?}: {report}",
            s.seed
        );
    }
}
