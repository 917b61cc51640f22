//! Sessions of scenario variants (issue 20: recognition measured on a varied operator): every
//! built-in scenario's [`Scenario::variant`] for seeds 1-20 (objects' sizes, mass and μ
//! perturbed, reaches varied by seed, in `table-three` the target drawn among the three
//! objects) is simulated to its end, recorded, read back and segmented, and the segmentation
//! finds the grasp of the target.
//!
//! Measured (`cargo test --release -p services --test integration -- varied_reach:: --nocapture` prints
//! them): a skill on the target in 20 of 20 seeds for `sphere-lift`, `box-pinch-lift`,
//! `cylinder-power-grasp`, `sphere-rotate` and `table-three` (8 balls, 7 boxes, 5 cylinders),
//! both grasps of `two-grasps` in 20 of 20, and `box-slip`'s grasp in 20 of 20: it loses the
//! box by design (the operator grips for μ 0.8, the box has 0.24-0.36), but only after the
//! grip's peak at lift-off has carried it 7-10 cm up, which is a grasp.
//!
//! (The phases are another matter, left to issue 20's measurements: a reach that pauses is
//! two moves, and the segmentation ends `approach` at the pause and takes the rest of the
//! reach for `preshape`, so 7 of 8 phases match there.)

use dfs_core::scenario::{Phase, Scenario};
use services::segmentation::{score, segment, SegmentParams, Segmentation};
use services::session::{read_session, record_simulation, Session};

/// Seeds of the variants: 1-20.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=20;

/// What one variant's session gave.
struct Outcome {
    /// The target's name (`None` for a single unnamed object).
    target: Option<String>,
    /// Skills that grasped the target (its name and shape).
    on_target: usize,
    /// All skills found.
    skills: usize,
    /// How high (m) the target rose above its start while at least two fingertips touched.
    carried: f64,
    /// Fraction of the ground-truth phases the segmentation found.
    phases_found: f64,
}

/// The variant `name`, `seed` simulated to its end, recorded, read back and segmented.
fn outcome(name: &str, seed: u64) -> Outcome {
    let scenario = Scenario::variant(name, seed).unwrap();
    assert!(scenario.vary_reach);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.mcap");
    let summary = record_simulation(&scenario, None, &path, |_, _| {})
        .unwrap_or_else(|e| panic!("{name} seed {seed}: {e}"));
    let session = read_session(&path).unwrap();
    check_ground_truth(name, seed, &scenario, &session, summary.ticks);
    let seg = segment(&session, &SegmentParams::default());
    let target = scenario.target.clone();
    let shape = scenario.target_object().unwrap().shape;
    let on_target = seg
        .skills
        .iter()
        .filter(|s| {
            s.parameters
                .object
                .as_ref()
                .is_some_and(|o| o.name == target && o.shape == shape)
        })
        .count();
    let start = session.object[0].1.pose.position.z;
    let carried = session
        .object
        .iter()
        .zip(&session.contacts)
        .filter(|(_, (_, c))| c.fingers.iter().filter(|f| f.touching).count() >= 2)
        .map(|((_, o), _)| o.pose.position.z - start)
        .fold(0.0, f64::max);
    Outcome {
        target,
        on_target,
        skills: seg.skills.len(),
        carried,
        phases_found: phases_found(&seg, &session),
    }
}

fn phases_found(seg: &Segmentation, session: &Session) -> f64 {
    let found: Vec<_> = seg.skills.iter().flat_map(|s| s.phases.clone()).collect();
    score(&found, &session.phases).phases_found_fraction
}

/// The ground truth tiles the session, in the script's phases, the approach and preshape
/// varied within their ranges and the other phases as scripted.
fn check_ground_truth(name: &str, seed: u64, scenario: &Scenario, session: &Session, ticks: u64) {
    let truth = &session.phases;
    assert_eq!(truth.len(), scenario.tasks.len(), "{name} {seed}");
    assert_eq!(truth[0].start_ns, 0);
    assert!(truth.windows(2).all(|w| w[0].end_ns == w[1].start_ns));
    assert_eq!(truth.last().unwrap().end_ns, ticks * 1_000_000);
    for (p, task) in truth.iter().zip(&scenario.tasks) {
        assert_eq!(p.name, task.phase.name());
        let s = (p.end_ns - p.start_ns) as f64 * 1e-9;
        match task.phase {
            // Duration / speed (0.7-1.3), plus a pause of up to 0.3 s in an approach.
            Phase::Approach => assert!(
                (task.duration / 1.3 - 1e-3..=task.duration / 0.7 + 0.3 + 1e-3).contains(&s),
                "{name} {seed}: approach {s} s"
            ),
            Phase::Preshape => assert!(
                (task.duration / 1.3 - 1e-3..=task.duration / 0.7 + 1e-3).contains(&s),
                "{name} {seed}: preshape {s} s"
            ),
            _ => assert!((s - task.duration).abs() < 1e-3, "{name} {seed}"),
        }
    }
}

/// Runs the variants of `name` and prints a line per seed and the count.
fn outcomes(name: &str) -> Vec<Outcome> {
    let out: Vec<Outcome> = SEEDS.map(|seed| outcome(name, seed)).collect();
    for (seed, o) in SEEDS.zip(&out) {
        println!(
            "{name} seed {seed}: target {:?}, {} skill(s), {} on it, carried {:.1} mm, {:.0} % \
             of the phases found",
            o.target.as_deref().unwrap_or("object"),
            o.skills,
            o.on_target,
            o.carried * 1e3,
            o.phases_found * 100.0
        );
    }
    out
}

/// At least 19 of 20 variants of a one-grasp scenario give a skill on the target.
fn one_grasp_found(name: &str) {
    let out = outcomes(name);
    let found = out.iter().filter(|o| o.on_target >= 1).count();
    println!("{name}: a skill on the target in {found} of 20");
    assert!(
        found >= 19,
        "{name}: a skill on the target in {found} of 20"
    );
}

#[test]
fn sphere_lift_variants_give_a_skill_on_the_sphere() {
    one_grasp_found("sphere-lift");
}

#[test]
fn box_pinch_lift_variants_give_a_skill_on_the_box() {
    one_grasp_found("box-pinch-lift");
}

#[test]
fn cylinder_power_grasp_variants_give_a_skill_on_the_cylinder() {
    one_grasp_found("cylinder-power-grasp");
}

#[test]
fn sphere_rotate_variants_give_a_skill_on_the_sphere() {
    one_grasp_found("sphere-rotate");
}

/// The target is drawn among the three objects; the skill names it.
#[test]
fn table_three_variants_give_a_skill_on_their_target() {
    let out = outcomes("table-three");
    let found = out.iter().filter(|o| o.on_target >= 1).count();
    let mut targets: Vec<&str> = out.iter().filter_map(|o| o.target.as_deref()).collect();
    targets.sort_unstable();
    targets.dedup();
    println!("table-three: a skill on the target in {found} of 20");
    assert_eq!(
        targets,
        ["ball", "box", "cylinder"],
        "every object a target"
    );
    assert!(
        found >= 19,
        "table-three: a skill on the target in {found} of 20"
    );
    // No skill on another object.
    assert!(out.iter().all(|o| o.skills == o.on_target));
}

/// Two grasps of the box: both found.
#[test]
fn two_grasps_variants_give_both_skills() {
    let out = outcomes("two-grasps");
    let both = out.iter().filter(|o| o.on_target == 2).count();
    println!("two-grasps: both skills in {both} of 20");
    assert!(both >= 19, "two-grasps: both skills in {both} of 20");
}

/// `box-slip` loses the box by design, after the grip's peak at lift-off has carried it up
/// (whether it does depends on the variant's mass and μ): a variant whose box was carried 1 cm
/// or more gives its skill, one whose box never rose 5 mm (the segmentation's least carry)
/// none. Measured: carried 7-10 cm, and a skill, in 20 of 20.
#[test]
fn box_slip_variants_give_a_skill_when_the_box_was_carried() {
    let out = outcomes("box-slip");
    let found = out.iter().filter(|o| o.on_target >= 1).count();
    let carried = out.iter().filter(|o| o.carried >= 0.01).count();
    println!("box-slip: a skill in {found} of 20, the box carried 1 cm or more in {carried}");
    for (seed, o) in SEEDS.zip(&out) {
        if o.carried >= 0.01 {
            assert_eq!(o.on_target, 1, "seed {seed}: carried {} m", o.carried);
        }
        if o.carried < 0.005 {
            assert_eq!(o.skills, 0, "seed {seed}: carried {} m", o.carried);
        }
    }
    assert!(found >= 19, "box-slip: a skill in {found} of 20");
}
