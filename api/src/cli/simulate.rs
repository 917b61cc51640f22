//! `icms scenarios` and `icms simulate`: the built-in operator scenarios, and a scenario run
//! through the closed 1 kHz loop and recorded into an MCAP session.

use super::{print_json, CliError};
use dfs_core::scenario::Scenario;
use serde::Serialize;
use services::session::{record_simulation, RecordSummary};
use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One-line descriptions of the built-in scenarios (dfs-core has none).
const DESCRIPTIONS: &[(&str, &str)] = &[
    (
        "sphere-lift",
        "thumb-index pinch of a 0.3 kg sphere (r 0.04 m, μ 0.8): lift, hold 2 s, place, release",
    ),
    (
        "box-pinch-lift",
        "pinch of a 0.2 kg box (5 × 5 × 8 cm, μ 0.8): lift, hold, place, release",
    ),
    (
        "cylinder-power-grasp",
        "thumb and index opposed across a 0.5 kg upright cylinder (r 35 mm, μ 0.7), the middle finger resting on it: lift, hold, carry 0.15 m sideways, place",
    ),
    (
        "sphere-rotate",
        "pinch of the sphere, lifted and turned 0.8 rad about the vertical, placed back",
    ),
    (
        "box-slip",
        "pinch of the box with μ 0.3 while the operator grips for μ 0.8: lifted by the grip peak at lift-off, it slips and drops as the grip relaxes",
    ),
    (
        "two-grasps",
        "pick the box, carry it, place it, then pick it again and hold: two grasps in one session",
    ),
    (
        "table-three",
        "a ball, a box and a cylinder on the table, 20 cm apart: pinch the box between the other two, lift, hold, place, release",
    ),
];

/// The description of a built-in scenario.
pub fn description(name: &str) -> &'static str {
    DESCRIPTIONS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, d)| *d)
        .unwrap_or("")
}

/// Arguments of `icms scenarios`.
#[derive(Debug, clap::Args)]
pub struct ScenariosArgs {
    /// Print JSON: a list of `{name, description, duration_s, object, phases}` (and
    /// `objects` for a scene of several).
    #[arg(long)]
    json: bool,
}

/// One entry of `icms scenarios --json`: `object` is the one the script grasps; a scene of
/// several objects lists them all in `objects`.
#[derive(Debug, Serialize)]
struct ScenarioEntry {
    name: &'static str,
    description: &'static str,
    duration_s: f64,
    object: dfs_core::scenario::ScenarioObject,
    #[serde(skip_serializing_if = "Option::is_none")]
    objects: Option<Vec<dfs_core::scenario::ScenarioObject>>,
    phases: Vec<dfs_core::scenario::Phase>,
}

/// Lists the built-in scenarios.
pub fn run_scenarios(a: ScenariosArgs) -> Result<(), CliError> {
    let entries: Vec<ScenarioEntry> = Scenario::BUILTINS
        .iter()
        .filter_map(|name| {
            let s = Scenario::builtin(name, 0)?;
            Some(ScenarioEntry {
                name,
                description: description(name),
                duration_s: s.duration(),
                phases: s.tasks.iter().map(|t| t.phase).collect(),
                object: s.target_object()?.clone(),
                objects: s.objects,
            })
        })
        .collect();
    if a.json {
        return print_json(&entries);
    }
    for e in &entries {
        println!("{:<22} {:>5.1} s  {}", e.name, e.duration_s, e.description);
    }
    Ok(())
}

/// Arguments of `icms simulate`.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// A built-in scenario (see `icms scenarios`) or a scenario file (JSON; format in the
    /// dfs-core `scenario` module docs).
    #[arg(long)]
    scenario: String,
    /// Seed of the operator's tremor and sensor noise (default: the file's seed, or 0).
    #[arg(long)]
    seed: Option<u64>,
    /// Simulate the built-in scenario's variant for `--seed` instead of the scenario itself:
    /// each object's sizes ×0.85-1.15, mass ×0.7-1.3 and μ ×0.8-1.2, the operator's reaches
    /// varied (start 0.25-0.40 m from the object, path bent, speed ×0.7-1.3, pauses), and in
    /// `table-three` the target drawn among the three objects and the objects shifted up to
    /// 2 cm. Only with a built-in scenario's name.
    #[arg(long)]
    variant: bool,
    /// Simulated seconds: cuts the script short or extends its last phase (default: the
    /// script's length).
    #[arg(long, allow_negative_numbers = true)]
    duration: Option<f64>,
    /// The session file to write (MCAP).
    #[arg(long)]
    out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

/// Loads a scenario by built-in name or from a JSON file and validates it; errors name the
/// file and the field.
pub fn load_scenario(name_or_path: &str, seed: Option<u64>) -> Result<Scenario, CliError> {
    if let Some(s) = Scenario::builtin(name_or_path, seed.unwrap_or(0)) {
        return Ok(s);
    }
    let path = Path::new(name_or_path);
    if !path.exists() {
        return Err(CliError(format!(
            "no built-in scenario or file named {name_or_path:?} (built-in: {})",
            Scenario::BUILTINS.join(", ")
        )));
    }
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError(format!("{}: {e}", path.display())))?;
    let mut s: Scenario = super::parse_json(&text)
        .map_err(|e| CliError(format!("{}: invalid scenario file: {e}", path.display())))?;
    if let Some(seed) = seed {
        s.seed = seed;
    }
    s.resolve()
        .map_err(|e| CliError(format!("{}: {e}", path.display())))?;
    Ok(s)
}

/// What `icms simulate --json` prints.
#[derive(Debug, Serialize)]
pub struct SimulateReport {
    /// Scenario name.
    pub scenario: String,
    /// Seed used.
    pub seed: u64,
    /// The scenario is the built-in one's variant for the seed (`--variant`); written only
    /// when true.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub variant: bool,
    /// The session file.
    pub out: PathBuf,
    /// Ticks recorded (1 kHz).
    pub ticks: u64,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Messages written, all topics.
    pub messages: u64,
    /// Messages per topic.
    pub messages_per_topic: BTreeMap<String, u64>,
    /// zstd chunks in the file.
    pub chunks: u64,
    /// File size (bytes).
    pub file_bytes: u64,
    /// Wall-clock seconds taken.
    pub elapsed_s: f64,
    /// Simulated seconds per wall-clock second.
    pub realtime_factor: f64,
}

impl SimulateReport {
    fn new(scenario: &Scenario, out: &Path, summary: &RecordSummary, elapsed_s: f64) -> Self {
        let duration_s = summary.ticks as f64 * 1e-3;
        Self {
            scenario: scenario.name.clone(),
            seed: scenario.seed,
            variant: false,
            out: out.to_path_buf(),
            ticks: summary.ticks,
            duration_s,
            messages: summary.write.messages,
            messages_per_topic: summary.write.messages_per_topic.clone(),
            chunks: summary.write.chunks,
            file_bytes: summary.file_bytes,
            elapsed_s,
            realtime_factor: duration_s / elapsed_s.max(1e-9),
        }
    }
}

/// A progress bar on stderr, only when stderr is a terminal and the output is for people (not
/// `--json`); at most one update per percent: `simulating [#####·····] 52% 31200/60000 ticks,
/// 1.9 s left`.
pub struct Progress {
    enabled: bool,
    label: &'static str,
    last_percent: Option<u64>,
    start: Instant,
}

/// Width of the bar, characters.
const BAR: u64 = 30;

impl Progress {
    /// A progress bar for `label`, shown if `wanted` and stderr is a terminal.
    pub fn new(label: &'static str, wanted: bool) -> Self {
        Self {
            enabled: wanted && std::io::stderr().is_terminal(),
            label,
            last_percent: None,
            start: Instant::now(),
        }
    }

    /// Reports `done` of `total`.
    pub fn update(&mut self, done: u64, total: u64) {
        if !self.enabled || total == 0 {
            return;
        }
        let percent = done.min(total) * 100 / total;
        if self.last_percent == Some(percent) {
            return;
        }
        self.last_percent = Some(percent);
        let filled = (done.min(total) * BAR / total) as usize;
        let bar = format!(
            "{}{}",
            "#".repeat(filled),
            "·".repeat(BAR as usize - filled)
        );
        let elapsed = self.start.elapsed().as_secs_f64();
        let left = if done > 0 {
            format!(
                ", {:.1} s left",
                elapsed * (total - done.min(total)) as f64 / done as f64
            )
        } else {
            String::new()
        };
        let mut err = std::io::stderr().lock();
        let _ = write!(
            err,
            "\r\x1b[2K{} [{bar}] {percent}% {done}/{total} ticks{left}",
            self.label
        );
        let _ = err.flush();
    }

    /// Clears the progress bar.
    pub fn done(&self) {
        if self.enabled && self.last_percent.is_some() {
            eprint!("\r\x1b[2K");
        }
    }
}

/// Runs and records a scenario.
pub fn run_simulate(a: SimulateArgs) -> Result<(), CliError> {
    let scenario = if a.variant {
        Scenario::variant(&a.scenario, a.seed.unwrap_or(0)).ok_or_else(|| {
            CliError(format!(
                "--variant takes a built-in scenario's name, not {:?} (built-in: {})",
                a.scenario,
                Scenario::BUILTINS.join(", ")
            ))
        })?
    } else {
        load_scenario(&a.scenario, a.seed)?
    };
    if Scenario::builtin(&a.scenario, 0).is_none() {
        let inputs = [("the --scenario file", Path::new(&a.scenario))];
        super::refuse_out_over_inputs(&a.out, &inputs)?;
    }
    let mut progress = Progress::new("simulating", !a.json);
    let start = Instant::now();
    let result = record_simulation(&scenario, a.duration, &a.out, |d, t| progress.update(d, t));
    progress.done();
    let summary = result.map_err(|e| match &e {
        services::RecordingError::Simulation { time_ns, .. } if a.out.exists() => {
            CliError(format!(
                "{}: {e} ({} holds the {} ticks recorded before the failure)",
                scenario.name,
                a.out.display(),
                time_ns / 1_000_000
            ))
        }
        _ => CliError(e.to_string()),
    })?;
    let report = SimulateReport {
        variant: a.variant,
        ..SimulateReport::new(&scenario, &a.out, &summary, start.elapsed().as_secs_f64())
    };
    if a.json {
        return print_json(&report);
    }
    println!(
        "{}{} (seed {}): {} ticks ({:.3} s simulated) recorded to {}: {} messages in {} chunks, {} bytes; took {:.2} s ({:.0}× real time)",
        report.scenario,
        if report.variant { " variant" } else { "" },
        report.seed,
        report.ticks,
        report.duration_s,
        report.out.display(),
        report.messages,
        report.chunks,
        report.file_bytes,
        report.elapsed_s,
        report.realtime_factor
    );
    Ok(())
}
