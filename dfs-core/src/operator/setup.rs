//! Setting a scenario up for the closed loop: the script's phases timed (varied reaches
//! drawn), cut to a duration, the grasp planned, the DFS built on the scene with the hand at
//! its start, and the operator's tremor drawn.

use super::plan::mount_link;
use super::reach::{draw_home, whole_ticks_ns};
use super::{
    approach_pose, plan_operator_grasp, raise, OperatorParams, Reach, ScriptPhase, Simulation,
    REACH_STREAM, TICK_NS,
};
use crate::contact::{ContactModel, Friction};
use crate::dfs::{Dfs, DfsParams, GloveSample};
use crate::error::{DfsError, Result};
use crate::hand::{HandModel, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Real, Vector};
use crate::object::{ObjectState, RigidObject};
use crate::scenario::{Phase, PhaseSpan, ResolvedTask, Scenario, Scene, MAX_SCRIPT_S, MIN_TASK_S};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

impl Simulation {
    /// Sets up a scenario with `hand` (normally glove10): its scene ([`Scenario::resolve_scene`])
    /// in one DFS, the grasp planned on the target. `duration_s`, when given, cuts the
    /// script short or extends its last phase. Errors name the scenario's field, or say that no
    /// grasp of the object is reachable.
    pub fn new(
        scenario: &Scenario,
        hand: HandModel,
        duration_s: Option<Real>,
    ) -> Result<Simulation> {
        let (scene, tasks) = scenario.resolve_scene()?;
        let target = scene.target;
        let (object, pose, friction) = {
            let t = scene.target();
            (t.object, t.pose, t.friction)
        };
        let table_height = scene.table_height;
        // Varied reaches: their own stream of the seed, so the tremor and the noise below are
        // the seed's either way.
        let mut reach_rng = scenario.vary_reach.then(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
            rng.set_stream(REACH_STREAM);
            rng
        });
        let (mut spans, reaches, t) = schedule(&tasks, reach_rng.as_mut());
        if scenario.vary_reach && t as Real * 1e-9 > MAX_SCRIPT_S {
            return Err(DfsError::invalid(
                "vary_reach",
                format!(
                    "the varied reaches make the script last {} s; a session lasts at most \
                     {MAX_SCRIPT_S} s",
                    t as Real * 1e-9
                ),
            ));
        }
        let n_steps = cut_to_duration(&mut spans, t, duration_s)?;
        let obstacles = start_obstacles(&scene);
        let plan = plan_operator_grasp(&hand, &object, &pose, scenario.grasp, &obstacles)?;
        let params = dfs_params(friction, table_height, plan.wrap.is_some());
        let approach = approach_pose(&plan.base, &object.shape);
        let start_base = match reach_rng.as_mut() {
            Some(rng) => draw_home(
                rng,
                &hand,
                &plan.q_open[..hand.dof()],
                &approach,
                &pose.translation.vector,
                &scene.dfs_objects(),
                table_height,
            ),
            None => raise(&approach, 0.15),
        };
        let q0 = plan.q_open;
        let mut mount = [0; MAX_TIPS];
        for (k, m) in mount.iter_mut().enumerate().take(hand.fingertips.len()) {
            *m = mount_link(&hand, k);
        }
        let dfs = start_dfs(hand, &scene, params, &q0, start_base)?;
        let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
        let (tremor_freq, tremor_phase) = draw_tremor(&mut rng);
        let operator_mu = scenario.operator_mu.unwrap_or(friction.mu).max(1e-3);
        let mut sim = Simulation {
            dfs,
            scene,
            target,
            params: OperatorParams::default(),
            style: scenario.grasp,
            spans,
            span: 0,
            step: 0,
            n_steps,
            table_height,
            operator_mu,
            plan,
            object_held: false,
            from_base: start_base,
            to_base: start_base,
            from_q: q0,
            to_q: q0,
            from_grip: 0.0,
            to_grip: 0.0,
            from_offset: 0.03,
            to_offset: 0.03,
            offset: 0.03,
            seen_object: pose,
            hold_in_mount: [None; MAX_TIPS],
            resting: [false; MAX_TIPS],
            mount,
            base: start_base,
            base_acceleration: Vector::zeros(),
            q_intent: q0,
            grip: 0.0,
            carry: 0.0,
            grip_boost: 0.0,
            q_meas: q0,
            tau_meas: [0.0; MAX_DOF],
            tau: [0.0; MAX_DOF],
            rng,
            tremor_freq,
            tremor_phase,
            reaches,
            reach_rng,
            reach_path: None,
            reach_shaping: 1.0,
            wrap_close: 0.0,
            wrap_set: None,
        };
        sim.begin_phase()?;
        Ok(sim)
    }
}

/// The script's phases one after the other from time 0, each at least a tick, in whole
/// ticks; with `reach_rng` (varied reaches) each `approach` drawn from it, and the `preshape`
/// after it at the same speed. Returns the spans, each span's varied reach (if any) and the
/// script's end (ns).
fn schedule(
    tasks: &[ResolvedTask],
    mut reach_rng: Option<&mut ChaCha8Rng>,
) -> (Vec<ScriptPhase>, Vec<Option<Reach>>, u64) {
    let mut spans = Vec::with_capacity(tasks.len());
    let mut t = 0u64;
    let mut reaches = vec![None; tasks.len()];
    let mut speed = 1.0;
    for (i, task) in tasks.iter().enumerate() {
        let d = match (reach_rng.as_deref_mut(), task.phase) {
            (Some(rng), Phase::Approach) => {
                let reach = Reach::draw(rng, task.duration);
                speed = reach.speed;
                reaches[i] = Some(reach);
                ((reach.move_s + reach.pause_s) * 1e9).round() as u64
            }
            (Some(_), Phase::Preshape) => whole_ticks_ns(task.duration / speed),
            _ => (task.duration * 1e9).round() as u64 / TICK_NS * TICK_NS,
        };
        spans.push(ScriptPhase {
            span: PhaseSpan {
                phase: task.phase,
                start_ns: t,
                end_ns: t + d.max(TICK_NS),
            },
            task: *task,
        });
        t += d.max(TICK_NS);
    }
    (spans, reaches, t)
}

/// The number of ticks of a script that ends at `t` (ns), or of `duration_s` when given: the
/// spans after it dropped and the last one cut or extended to it.
fn cut_to_duration(spans: &mut Vec<ScriptPhase>, t: u64, duration_s: Option<Real>) -> Result<u64> {
    let mut n_steps = t / TICK_NS;
    if let Some(d) = duration_s {
        // A session shorter than the shortest phase holds no motion to segment (and one of
        // a tick or two would not read back as a session).
        if !(d.is_finite() && (MIN_TASK_S..=MAX_SCRIPT_S).contains(&d)) {
            return Err(DfsError::invalid(
                "duration",
                format!("must be {MIN_TASK_S} to {MAX_SCRIPT_S} s, got {d}"),
            ));
        }
        n_steps = ((d * 1e9).round() as u64 / TICK_NS).max(1);
        let end = n_steps * TICK_NS;
        spans.retain(|s| s.span.start_ns < end);
        if let Some(last) = spans.last_mut() {
            last.span.end_ns = end;
        }
    }
    Ok(n_steps)
}

/// The scene's objects other than the target where they start, as obstacles to the grasp's
/// planning.
fn start_obstacles(scene: &Scene) -> Vec<(RigidObject, Isometry)> {
    scene
        .objects
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != scene.target)
        .map(|(_, o)| (o.object, o.pose))
        .collect()
}

/// The DFS's parameters for a session: soft fingertips, the scene's friction and table, and
/// whole-hand contact for a wrap.
fn dfs_params(friction: Friction, table_height: Real, whole_hand: bool) -> DfsParams {
    DfsParams {
        // Fingertip pads are soft: they resist spin about the normal (Table 1, soft finger).
        contact_model: ContactModel::SoftFinger,
        friction,
        table_height: Some(table_height),
        // A grasp that wraps the hand around the object holds it with the palm and the
        // phalanges too: whole-hand contact is the plan's, not a default of the physics
        // (fingertip sessions stay as they were, bit for bit, and their ticks as cheap).
        whole_hand,
        ..DfsParams::default()
    }
}

/// The DFS on the scene with `hand` open at `q0` at its start pose `base` (one tick, no
/// operator torques), every object then set at rest where the scene puts it.
fn start_dfs(
    hand: HandModel,
    scene: &Scene,
    params: DfsParams,
    q0: &[Real; MAX_DOF],
    base: Isometry,
) -> Result<Dfs> {
    let mut dfs = Dfs::with_objects(hand, &scene.dfs_objects(), params)?;
    let n = dfs.hand().dof();
    let zeros = [0.0; MAX_DOF];
    dfs.step(&GloveSample {
        q: &q0[..n],
        tau: &zeros[..n],
        base,
    })?;
    for (i, o) in scene.objects.iter().enumerate() {
        dfs.set_object_state_at(i, ObjectState::at_rest(o.pose))?;
    }
    Ok(dfs)
}

/// The tremor's frequency (8-12 Hz) and phase for every joint and the arm's three axes, from
/// the seed's stream.
#[allow(clippy::type_complexity)]
fn draw_tremor(rng: &mut ChaCha8Rng) -> ([Real; MAX_DOF + 3], [Real; MAX_DOF + 3]) {
    let mut tremor_freq = [0.0; MAX_DOF + 3];
    let mut tremor_phase = [0.0; MAX_DOF + 3];
    for i in 0..MAX_DOF + 3 {
        tremor_freq[i] = 8.0 + 4.0 * rand::Rng::random::<Real>(rng);
        tremor_phase[i] = std::f64::consts::TAU * rand::Rng::random::<Real>(rng);
    }
    (tremor_freq, tremor_phase)
}
