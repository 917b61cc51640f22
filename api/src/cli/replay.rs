//! `icms hands`: the built-in robot hands (or one hand spec file); `icms replay`: a skill
//! retargeted onto a hand and simulated in the DFS, with its report and optionally an MCAP.

use super::{print_json, CliError};
use dfs_core::hand::BUILTIN_HANDS;
use dfs_core::replay::ReplayParams;
use serde::Serialize;
use services::replay::{load_hand, replay_skill, skill_spec_from_json, ReplaySource};
use std::path::PathBuf;

/// Arguments of `icms hands`.
#[derive(Debug, clap::Args)]
pub struct HandsArgs {
    /// Show one hand: a built-in name or a hand spec file (JSON; its `urdf` beside it).
    hand: Option<String>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// One hand as `icms hands` lists it.
#[derive(Debug, Serialize)]
pub struct HandSummary {
    /// Name.
    pub name: String,
    /// Fingertip names (the thumb first).
    pub fingers: Vec<String>,
    /// Number of DOFs.
    pub dof: usize,
    /// DOF names.
    pub dof_names: Vec<String>,
    /// Smallest and largest torque limit (N·m, or N for prismatic DOFs).
    pub torque_limit: [f64; 2],
    /// Built in.
    pub builtin: bool,
}

fn summary(name_or_path: &str) -> Result<HandSummary, CliError> {
    let hand = load_hand(name_or_path)?;
    let m = &hand.model;
    let mut fingers: Vec<String> = vec![m.fingertips[hand.thumb].name.clone()];
    fingers.extend(
        m.fingertips
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != hand.thumb)
            .map(|(_, t)| t.name.clone()),
    );
    let lo = m.torque_limit.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = m.torque_limit.iter().copied().fold(0.0, f64::max);
    Ok(HandSummary {
        name: m.name.clone(),
        fingers,
        dof: m.dof(),
        dof_names: m.dof_names.clone(),
        torque_limit: [lo, hi],
        builtin: BUILTIN_HANDS.contains(&name_or_path),
    })
}

/// Lists the built-in hands, or shows one.
pub fn run_hands(a: HandsArgs) -> Result<(), CliError> {
    let hands = match &a.hand {
        Some(h) => vec![summary(h)?],
        None => BUILTIN_HANDS
            .iter()
            .map(|h| summary(h))
            .collect::<Result<Vec<_>, _>>()?,
    };
    if a.json {
        return print_json(&hands);
    }
    for h in &hands {
        println!(
            "{:<8} {} fingers ({}), {} DOFs, torque limit {}",
            h.name,
            h.fingers.len(),
            h.fingers.join(", "),
            h.dof,
            if h.torque_limit[0] == h.torque_limit[1] {
                format!("{}", h.torque_limit[0])
            } else {
                format!("{}-{}", h.torque_limit[0], h.torque_limit[1])
            }
        );
    }
    Ok(())
}

/// Arguments of `icms replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The skill: a JSON file holding one element of the `skills` list that `icms segment
    /// --json` prints, or the id of a skill in the data base (see --data).
    #[arg(long)]
    skill: String,
    /// The hand: a built-in name (see `icms hands`) or a hand spec file (JSON).
    #[arg(long)]
    hand: String,
    /// Data directory of the skill data base, for a skill id.
    #[arg(long, default_value = "icms-data")]
    data: PathBuf,
    /// Record the replay into this MCAP file (viewable in Foxglove like a session).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

/// The skill's JSON and a name for it: a file, or a stored skill's parameters.
fn read_skill(a: &ReplayArgs) -> Result<(serde_json::Value, ReplaySource), CliError> {
    let path = PathBuf::from(&a.skill);
    if path.is_file() {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| CliError(format!("{}: {e}", path.display())))?;
        let value = serde_json::from_str(&text)
            .map_err(|e| CliError(format!("{}: not JSON: {e}", path.display())))?;
        let source = ReplaySource {
            skill_id: None,
            skill_name: path.display().to_string(),
        };
        return Ok((value, source));
    }
    let id: i64 = a.skill.parse().map_err(|_| {
        CliError(format!(
            "--skill {:?} is neither a file nor a skill id",
            a.skill
        ))
    })?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the runtime: {e}")))?;
    let skill = rt.block_on(async {
        let store = services::store::Store::open(&a.data).await?;
        let skill = store.get_skill(id).await;
        store.close().await;
        skill
    })?;
    Ok((
        skill.params,
        ReplaySource {
            skill_id: Some(id),
            skill_name: format!("skill {id}"),
        },
    ))
}

/// Replays a skill on a hand and prints the report. A failed replay is a report (exit 0).
pub fn run_replay(a: ReplayArgs) -> Result<(), CliError> {
    let (value, source) = read_skill(&a)?;
    let skill = skill_spec_from_json(&value, &source.skill_name)?;
    let hand = load_hand(&a.hand)?;
    let report = replay_skill(
        &hand,
        &skill,
        &ReplayParams::default(),
        &source,
        a.out.as_deref(),
    )?;
    if a.json {
        return print_json(&report);
    }
    println!(
        "{} on {}: {}{} — {}",
        source.skill_name,
        report.hand,
        if report.success { "success" } else { "failed" },
        report
            .failure_reason
            .map(|r| format!(" ({})", r.name()))
            .unwrap_or_default(),
        report.detail
    );
    println!(
        "  tracking {:.1} mm / {:.1}° max, slip {:.1} mm, peak torque {:.0} % ({}), ε {:.3}",
        report.position_error_max_m * 1e3,
        report.orientation_error_max_rad.to_degrees(),
        report.max_slip_m * 1e3,
        report.peak_torque_ratio * 100.0,
        report.peak_torque_joint,
        report.quality.epsilon
    );
    if let Some(out) = &a.out {
        println!("  recorded to {}", out.display());
    }
    Ok(())
}

/// Result of `icms bench replay`.
#[derive(Debug, Serialize)]
pub struct ReplayBench {
    /// Hand.
    pub hand: String,
    /// Whether the replay succeeded.
    pub success: bool,
    /// Retargeting: contacts, base pose, IK and the force schedule (ms, median of 5).
    pub retarget_ms: f64,
    /// The whole replay (retargeting plus every tick; ms, median of 5).
    pub replay_ms: f64,
    /// Ticks of the replay.
    pub ticks: u64,
    /// Retargeting plus 5 000 ticks, scaled from the replay (ms).
    pub per_5s_ms: f64,
    /// One retargeting step along the held motion: IK warm-started from the previous step and
    /// the force distribution with cones and torque limits (µs, median).
    pub retarget_step_us: f64,
    /// Of those steps, how many found a force distribution (the others: the load cannot be
    /// carried there).
    pub retarget_steps_held: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Times the replay of the sphere-lift skill on `hand`.
pub fn bench_replay(hand: &str, json: bool) -> Result<(), CliError> {
    use std::time::Instant;
    let path = std::env::temp_dir().join(format!("icms-bench-replay-{}.mcap", std::process::id()));
    let scenario = dfs_core::scenario::Scenario::builtin("sphere-lift", 0)
        .ok_or_else(|| CliError("no sphere-lift scenario".into()))?;
    let recorded = services::session::record_simulation(&scenario, None, &path, |_, _| {});
    let session = recorded.and_then(|_| services::session::read_session(&path));
    let _ = std::fs::remove_file(&path);
    let session = session?;
    let seg = services::segmentation::segment(
        &session,
        &services::segmentation::SegmentParams::default(),
    );
    let first = seg
        .skills
        .first()
        .ok_or_else(|| CliError("sphere-lift gave no skill".into()))?;
    let skill = skill_spec_from_json(&serde_json::to_value(first)?, "sphere-lift")?;
    let loaded = load_hand(hand)?;
    let params = ReplayParams::default();
    let mut plan_t = Vec::new();
    let mut run_t = Vec::new();
    let mut last = None;
    for _ in 0..5 {
        let t0 = Instant::now();
        let plan = dfs_core::replay::plan(&loaded.model, loaded.thumb, &skill, &params)?;
        plan_t.push(t0.elapsed().as_secs_f64() * 1e3);
        drop(plan);
        let t0 = Instant::now();
        let r = dfs_core::replay::run(&loaded.model, loaded.thumb, &skill, &params)?;
        run_t.push(t0.elapsed().as_secs_f64() * 1e3);
        last = Some(r);
    }
    let report = last.ok_or_else(|| CliError("no replay".into()))?;
    let plan = dfs_core::replay::plan(&loaded.model, loaded.thumb, &skill, &params)?;
    let tl = skill.timeline();
    let mut step = dfs_core::replay::RetargetStep::new(&plan, &skill, &params);
    let mut steps = Vec::new();
    let mut held = 0;
    for i in 0..200 {
        let t = tl.grasp_end + (tl.release_start - tl.grasp_end) * i as f64 / 200.0;
        let t0 = Instant::now();
        let (_, forces) = std::hint::black_box(step.step(t));
        steps.push(t0.elapsed().as_secs_f64() * 1e6);
        held += usize::from(forces.is_some());
    }
    let (retarget_ms, replay_ms) = (median(plan_t), median(run_t));
    let ticks = report.ticks.max(1);
    let result = ReplayBench {
        hand: hand.to_owned(),
        success: report.success,
        retarget_ms,
        replay_ms,
        ticks,
        per_5s_ms: retarget_ms + (replay_ms - retarget_ms) * 5000.0 / ticks as f64,
        retarget_step_us: median(steps),
        retarget_steps_held: held,
    };
    if json {
        return print_json(&result);
    }
    println!(
        "replay sphere-lift on {}: retarget {:.1} ms, replay {:.1} ms for {} ticks \
         (retarget + 5 000 ticks: {:.1} ms), one retargeting step {:.0} µs ({} of 200 held)",
        result.hand,
        result.retarget_ms,
        result.replay_ms,
        result.ticks,
        result.per_5s_ms,
        result.retarget_step_us,
        result.retarget_steps_held
    );
    Ok(())
}
