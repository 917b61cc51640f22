//! `icms hands`: the built-in robot hands (or one hand spec file), with `--data` the hands
//! uploaded to a data base too; `icms replay`: a skill retargeted onto a hand and simulated in
//! the DFS, with its report and optionally an MCAP. A replay of a stored skill (`--skill ID`) is
//! stored in the data base beside it, with its MCAP, like `POST /api/v1/skills/{id}/replays`.

use super::{no_data_base, open_store, print_json, CliError, Open};
use crate::config::DataArgs;
use dfs_core::hand::BUILTIN_HANDS;
use dfs_core::replay::ReplayParams;
use serde::Serialize;
use services::replay::{load_hand, replay_skill, skill_spec_from_json, LoadedHand, ReplaySource};
use services::store::{HandSummary, Store, StoreError, DB_FILE};
use std::path::{Path, PathBuf};

/// Arguments of `icms hands`.
#[derive(Debug, clap::Args)]
pub struct HandsArgs {
    /// Show one hand: a built-in name, a hand spec file (JSON; its `urdf` beside it), or with
    /// --data the name of an uploaded hand.
    hand: Option<String>,
    /// Data directory of a skill data base: list its uploaded hands too.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the runtime: {e}")))
}

/// Runs `f` on the existing store `at` names (it only reads: an SQLite data directory without
/// a data base is an error and nothing is created), then closes it.
fn with_store<T>(
    at: &DataArgs,
    f: impl AsyncFnOnce(&Store) -> Result<T, StoreError>,
) -> Result<T, CliError> {
    runtime()?.block_on(async {
        let store = open_store(at, Open::Read).await?;
        let out = f(&store).await;
        store.close().await;
        Ok(out?)
    })
}

/// Whether `at` names a data base (so looking a hand up there cannot create one): an SQLite
/// data directory that holds one, or a PostgreSQL data base (created by whoever runs it).
fn has_store(at: &DataArgs) -> bool {
    at.database_url.is_some() || at.data.join(DB_FILE).is_file()
}

/// Lists the built-in hands (and with --data the uploaded ones), or shows one.
pub fn run_hands(a: HandsArgs) -> Result<(), CliError> {
    let mut from_file = false;
    let at = a.data.clone().map(DataArgs::in_dir);
    let hands: Vec<HandSummary> = match (&a.hand, &at) {
        (Some(h), at) => {
            let (hand, origin) = resolve_hand(h, at.as_ref(), "hand")?;
            from_file = origin == Origin::File;
            vec![HandSummary::of(&hand, origin == Origin::Builtin, None)]
        }
        (None, Some(at)) => with_store(at, async |s| s.list_hands().await)?,
        (None, None) => BUILTIN_HANDS
            .iter()
            .map(|h| Ok(HandSummary::of(&load_hand(h)?, true, None)))
            .collect::<Result<Vec<_>, CliError>>()?,
    };
    if a.json {
        return print_json(&hands);
    }
    for h in &hands {
        println!(
            "{:<8} {} fingers ({}), {} DOFs, torque limit {}{}",
            h.name,
            h.fingers.len(),
            h.fingers.join(", "),
            h.dof,
            if h.torque_limit[0] == h.torque_limit[1] {
                format!("{}", h.torque_limit[0])
            } else {
                format!("{}-{}", h.torque_limit[0], h.torque_limit[1])
            },
            match (h.builtin, from_file) {
                (true, _) => "",
                (false, true) => " (spec file)",
                (false, false) => " (uploaded)",
            }
        );
    }
    Ok(())
}

/// Where a hand came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Origin {
    Builtin,
    File,
    Uploaded,
}

/// A hand: built-in name, spec file, or (with a data base in `data`) an uploaded hand's name,
/// and where it came from. `what` names the argument in errors (`--hand`, `hand`).
pub(super) fn resolve_hand(
    name_or_path: &str,
    at: Option<&DataArgs>,
    what: &str,
) -> Result<(LoadedHand, Origin), CliError> {
    if BUILTIN_HANDS.contains(&name_or_path) {
        return Ok((load_hand(name_or_path)?, Origin::Builtin));
    }
    if Path::new(name_or_path).is_file() {
        return Ok((load_hand(name_or_path)?, Origin::File));
    }
    match at {
        Some(d) if has_store(d) => {
            let name = name_or_path.to_owned();
            let hand = with_store(d, async move |s| s.get_hand(&name).await?.load()).map_err(
                |CliError(e)| {
                    CliError(format!(
                        "{what} {name_or_path:?} is neither a built-in hand ({}), a spec file, \
                         nor a hand in {}: {e}",
                        BUILTIN_HANDS.join(", "),
                        d.data.display()
                    ))
                },
            )?;
            Ok((hand, Origin::Uploaded))
        }
        Some(d) => Err(CliError(format!(
            "{what} {name_or_path:?} is neither a built-in hand ({}) nor a spec file, and \
             there is no uploaded hand to look it up in: {}",
            BUILTIN_HANDS.join(", "),
            no_data_base(&d.data)
        ))),
        None => Ok((load_hand(name_or_path)?, Origin::File)),
    }
}

/// Arguments of `icms replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The skill: a JSON file holding one element of the `skills` list that `icms segment
    /// --json` prints, or the id of a skill in the data base (see --data); a replay of a stored
    /// skill is stored there too, with its MCAP.
    #[arg(long)]
    skill: String,
    /// The hand: a built-in name (see `icms hands`), a hand spec file (JSON), or the name of a
    /// hand uploaded to the data base.
    #[arg(long)]
    hand: String,
    /// The skill data base, for a skill id or an uploaded hand.
    #[command(flatten)]
    at: DataArgs,
    /// Record the replay into this MCAP file (viewable in Foxglove like a session).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON (with `replay_id` when the replay was stored).
    #[arg(long)]
    json: bool,
}

/// The skill's JSON and a name for it: a file, or a stored skill's parameters.
fn read_skill(a: &ReplayArgs) -> Result<(serde_json::Value, ReplaySource), CliError> {
    let path = PathBuf::from(&a.skill);
    if path.is_file() {
        let bytes =
            std::fs::read(&path).map_err(|e| CliError(format!("{}: {e}", path.display())))?;
        let not_a_skill = |why: String| {
            let hint = if bytes.starts_with(b"\x89MCAP") {
                " (it is an MCAP file: a session's skills come from `icms segment --json`, or \
                 `icms ingest` stores them and `--skill ID` replays one)"
            } else {
                ""
            };
            CliError(format!(
                "{}: not a skill JSON file: {why}{hint}",
                path.display()
            ))
        };
        let text =
            std::str::from_utf8(&bytes).map_err(|_| not_a_skill("it is not UTF-8 text".into()))?;
        let value = serde_json::from_str(text).map_err(|e| not_a_skill(e.to_string()))?;
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
    if !has_store(&a.at) {
        return Err(CliError(format!(
            "--skill {id}: there is no skill data base in {} (see --data)",
            a.at.data.display()
        )));
    }
    let skill = with_store(&a.at, async |s| s.get_skill(id).await)?;
    Ok((
        skill.params,
        ReplaySource {
            skill_id: Some(id),
            skill_name: format!("skill {id}"),
        },
    ))
}

/// Makes sure the data base knows the hand a stored replay names: a hand from a spec file is
/// stored (under its spec's name) unless an identical one is; a different hand of that name is
/// refused before the replay runs.
async fn ensure_hand_stored(store: &Store, hand: &LoadedHand) -> Result<(), CliError> {
    let name = &hand.model.name;
    let (Some(spec), Some(urdf)) = (&hand.spec, &hand.urdf) else {
        return Err(CliError(format!("hand {name:?} has no spec to store")));
    };
    match store.get_hand(name).await {
        Ok(stored) => {
            let same = stored.urdf.as_deref() == Some(urdf.as_str())
                && stored.spec.as_ref().is_some_and(|s| {
                    let mut s = s.clone();
                    s.urdf.clone_from(&spec.urdf);
                    &s == spec
                });
            if same {
                Ok(())
            } else if stored.summary.builtin {
                Err(CliError(format!(
                    "the hand spec is named {name:?}, a built-in hand it differs from, which \
                     cannot be replaced; rename the hand in its spec to store this replay"
                )))
            } else {
                Err(CliError(format!(
                    "a different hand named {name:?} is already stored in the data base; \
                     rename the hand in its spec to store this replay"
                )))
            }
        }
        Err(StoreError::HandNotFound(_)) => {
            store.put_hand(spec.clone(), urdf.clone()).await?;
            Ok(())
        }
        Err(e) => Err(e.into()),
    }
}

/// Refuses a `--out` that is one of the files the replay read: the skill file, and for a hand
/// from a spec file the spec and its URDF (the recording would overwrite them). A built-in or
/// uploaded hand read no file, whatever files share its name.
fn refuse_out_over_inputs(
    out: &Path,
    a: &ReplayArgs,
    hand: &LoadedHand,
    origin: Origin,
) -> Result<(), CliError> {
    let mut inputs = vec![("the --skill file", PathBuf::from(&a.skill))];
    if origin == Origin::File {
        let spec = Path::new(&a.hand);
        inputs.push(("the --hand file", spec.to_path_buf()));
        if let Some(urdf) = hand.spec.as_ref().map(|s| &s.urdf) {
            let dir = spec.parent().unwrap_or(Path::new("."));
            inputs.push(("the URDF of the --hand spec", dir.join(urdf)));
        }
    }
    super::refuse_out_over_inputs(out, &inputs)
}

/// Replays a skill on a hand and prints the report. A failed replay is a report (exit 0).
/// A stored skill's replay is stored too.
pub fn run_replay(a: ReplayArgs) -> Result<(), CliError> {
    let (value, source) = read_skill(&a)?;
    let skill = skill_spec_from_json(&value, &source.skill_name)?;
    let (hand, origin) = resolve_hand(&a.hand, Some(&a.at), "--hand")?;
    if let Some(out) = &a.out {
        refuse_out_over_inputs(out, &a, &hand, origin)?;
    }
    let builtin = origin == Origin::Builtin;
    let Some(skill_id) = source.skill_id else {
        let report = replay_skill(
            &hand,
            &skill,
            &ReplayParams::default(),
            &source,
            a.out.as_deref(),
        )?;
        return print_report(&a, &source, &report, None);
    };
    let rt = runtime()?;
    let store = rt.block_on(open_store(&a.at, Open::Create))?;
    let result = (|| {
        if !builtin {
            rt.block_on(ensure_hand_stored(&store, &hand))?;
        }
        // Record into --out, or a temporary file in the data directory, and store the bytes.
        let tmp;
        let out = match &a.out {
            Some(p) => p.clone(),
            None => {
                let dir = a.at.data.join("tmp");
                std::fs::create_dir_all(&dir)
                    .map_err(|e| CliError(format!("{}: {e}", dir.display())))?;
                tmp = tempfile::Builder::new()
                    .prefix("replay-")
                    .suffix(".mcap")
                    .tempfile_in(&dir)
                    .map_err(|e| CliError(format!("{}: {e}", dir.display())))?;
                tmp.path().to_path_buf()
            }
        };
        let report = replay_skill(&hand, &skill, &ReplayParams::default(), &source, Some(&out))?;
        let bytes = std::fs::read(&out).map_err(|e| CliError(format!("{}: {e}", out.display())))?;
        let replay =
            rt.block_on(store.insert_replay(skill_id, &hand.model.name, &report, bytes))?;
        Ok::<_, CliError>((report, replay.id))
    })();
    rt.block_on(store.close());
    let (report, replay_id) = result?;
    print_report(&a, &source, &report, Some(replay_id))
}

fn print_report(
    a: &ReplayArgs,
    source: &ReplaySource,
    report: &dfs_core::replay::ReplayReport,
    replay_id: Option<i64>,
) -> Result<(), CliError> {
    if a.json {
        let mut v = serde_json::to_value(report)?;
        if let (Some(id), Some(obj)) = (replay_id, v.as_object_mut()) {
            obj.insert("replay_id".into(), id.into());
        }
        return print_json(&v);
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
    if let Some(id) = replay_id {
        let place = match &a.at.database_url {
            Some(_) => "the PostgreSQL data base".to_owned(),
            None => a.at.data.display().to_string(),
        };
        println!("  stored as replay {id} in {place}");
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
