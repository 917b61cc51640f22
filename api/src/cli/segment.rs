//! `icms segment`: a session file into skills (one per grasp) with their parameters, and
//! `icms bench segmentation`: the segmentation scored against the simulator's ground truth.

use super::{print_json, CliError};
use dfs_core::scenario::Scenario;
use serde::Serialize;
use services::mcap_io::ReadLimits;
use services::segmentation::{median, score, segment, segment_source, PhaseSpan, SegmentParams};
use services::session::{read_session, record_simulation, Session, SessionSource};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `icms segment`.
#[derive(Debug, clap::Args)]
pub struct SegmentArgs {
    /// The session file (MCAP).
    input: PathBuf,
    /// Print JSON: `{"skills": [{"phases": [{"name", "start_ns", "end_ns"}], ...parameters}]}`.
    #[arg(long)]
    json: bool,
}

/// Segments a session file and prints its skills; a replay recording is refused.
pub fn run_segment(a: SegmentArgs) -> Result<(), CliError> {
    // Two streamed passes: memory bounded by the session's grid, not the file.
    let (_, seg) = segment_source(
        &SessionSource::File(&a.input),
        &ReadLimits::streaming(),
        &SegmentParams::default(),
    )
    .map_err(|e| match e {
        e @ services::RecordingError::ReplayRecording { .. } => CliError::from(e),
        e => CliError(format!("{}: {e}", a.input.display())),
    })?;
    if a.json {
        return print_json(&seg);
    }
    println!("{}: {} skill(s)", a.input.display(), seg.skills.len());
    for (i, s) in seg.skills.iter().enumerate() {
        let phases: Vec<String> = s
            .phases
            .iter()
            .map(|p| {
                format!(
                    "{} {:.3}-{:.3} s",
                    p.phase,
                    p.start_ns as f64 * 1e-9,
                    p.end_ns as f64 * 1e-9
                )
            })
            .collect();
        println!(
            "  skill {i}: {} contacts, {} ({} virtual fingers), internal force {:.2} N; {}",
            s.parameters.contact_count,
            s.parameters.grasp_type.label,
            s.parameters.grasp_type.opposing_virtual_fingers,
            s.parameters.internal_force_n,
            phases.join(", ")
        );
    }
    Ok(())
}

/// Score of one group of sessions.
#[derive(Debug, Default, Serialize)]
pub struct GroupScore {
    /// Sessions scored.
    pub sessions: usize,
    /// Median absolute boundary error (ms).
    pub median_boundary_error_ms: f64,
    /// 90th percentile of the boundary error (ms).
    pub p90_boundary_error_ms: f64,
    /// Fraction of ground-truth phases found.
    pub phases_found_fraction: f64,
    /// Skills found per session (mean).
    pub skills_per_session: f64,
}

/// Result of `icms bench segmentation`.
#[derive(Debug, Serialize)]
pub struct SegmentationBench {
    /// Over every scenario and seed.
    pub overall: GroupScore,
    /// Per built-in scenario.
    pub per_scenario: BTreeMap<String, GroupScore>,
    /// Seeds per scenario.
    pub seeds: u64,
    /// Median wall-clock time to segment one 60 s sphere-lift session (ms), with parameters.
    pub segment_60s_ms: f64,
    /// Wall-clock seconds of the whole benchmark (simulation included).
    pub seconds: f64,
}

#[derive(Default)]
struct Acc {
    errors: Vec<f64>,
    found: usize,
    truth: usize,
    sessions: usize,
    skills: usize,
}

impl Acc {
    fn add(&mut self, o: &Acc) {
        self.errors.extend_from_slice(&o.errors);
        self.found += o.found;
        self.truth += o.truth;
        self.sessions += o.sessions;
        self.skills += o.skills;
    }
    fn score(&self) -> GroupScore {
        let mut e = self.errors.clone();
        let med = median(&mut e);
        let p90 = e
            .get(((e.len() as f64 * 0.9) as usize).min(e.len().saturating_sub(1)))
            .copied()
            .unwrap_or(0.0);
        GroupScore {
            sessions: self.sessions,
            median_boundary_error_ms: med,
            p90_boundary_error_ms: p90,
            phases_found_fraction: if self.truth == 0 {
                1.0
            } else {
                self.found as f64 / self.truth as f64
            },
            skills_per_session: self.skills as f64 / self.sessions.max(1) as f64,
        }
    }
}

/// A built-in scenario simulated and read back (through a temporary file, deleted).
pub fn simulate_session(name: &str, seed: u64, duration: Option<f64>) -> Result<Session, CliError> {
    let scenario = Scenario::builtin(name, seed)
        .ok_or_else(|| CliError(format!("no built-in scenario {name:?}")))?;
    let path = std::env::temp_dir().join(format!(
        "icms-bench-seg-{}-{name}-{seed}-{:?}.mcap",
        std::process::id(),
        std::thread::current().id()
    ));
    let r = record_simulation(&scenario, duration, &path, |_, _| {});
    let s = r
        .map_err(CliError::from)
        .and_then(|_| read_session(&path).map_err(CliError::from));
    let _ = std::fs::remove_file(&path);
    s
}

fn all_found(skills: &[services::segmentation::Skill]) -> Vec<PhaseSpan> {
    skills
        .iter()
        .flat_map(|s| s.phases.iter().cloned())
        .collect()
}

/// Runs `icms bench segmentation`.
pub fn bench_segmentation(seeds: u64, duration: f64, json: bool) -> Result<(), CliError> {
    let t0 = Instant::now();
    let params = SegmentParams::default();
    let jobs: Vec<(&str, u64)> = Scenario::BUILTINS
        .iter()
        .flat_map(|n| (0..seeds).map(move |s| (*n, s)))
        .collect();
    let workers = std::thread::available_parallelism()
        .map_or(2, |n| n.get())
        .min(4);
    let results: Vec<Result<(String, Acc), CliError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let jobs = &jobs;
                scope.spawn(move || {
                    jobs.iter()
                        .skip(w)
                        .step_by(workers)
                        .map(|(name, seed)| {
                            let s = simulate_session(name, *seed, None)?;
                            let seg = segment(&s, &params);
                            let sc = score(&all_found(&seg.skills), &s.phases);
                            Ok((
                                name.to_string(),
                                Acc {
                                    found: (sc.phases_found_fraction * s.phases.len() as f64)
                                        .round()
                                        as usize,
                                    truth: s.phases.len(),
                                    errors: sc.boundary_errors_ms,
                                    sessions: 1,
                                    skills: seg.skills.len(),
                                },
                            ))
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("worker panicked"))
            .collect()
    });
    let mut per: BTreeMap<String, Acc> = BTreeMap::new();
    let mut overall = Acc::default();
    for r in results {
        let (name, acc) = r?;
        overall.add(&acc);
        per.entry(name).or_default().add(&acc);
    }
    let long = simulate_session("sphere-lift", 0, Some(duration))?;
    let mut times = Vec::new();
    for _ in 0..7 {
        let t = Instant::now();
        std::hint::black_box(segment(std::hint::black_box(&long), &params));
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let r = SegmentationBench {
        overall: overall.score(),
        per_scenario: per.iter().map(|(k, v)| (k.clone(), v.score())).collect(),
        seeds,
        segment_60s_ms: median(&mut times),
        seconds: t0.elapsed().as_secs_f64(),
    };
    if json {
        return print_json(&r);
    }
    let line = |name: &str, g: &GroupScore| {
        println!(
            "{name:>22}: median boundary error {:.1} ms (p90 {:.1} ms), {:.1} % of phases found, {:.2} skills/session over {} sessions",
            g.median_boundary_error_ms,
            g.p90_boundary_error_ms,
            100.0 * g.phases_found_fraction,
            g.skills_per_session,
            g.sessions
        );
    };
    for (k, v) in &r.per_scenario {
        line(k, v);
    }
    line("overall", &r.overall);
    println!(
        "segmenting a {duration} s sphere-lift session: {:.2} ms (median of 7)",
        r.segment_60s_ms
    );
    Ok(())
}
