//! The driver: `icms-fuzz TARGET` runs inputs `0..runs` in child processes (`--jobs` at a
//! time, each over a range of indices), so that an abort (a stack overflow, an allocation
//! over the memory limit) kills only the child. Each child reports on stdout, one line per
//! event: `S i` before input `i`, `P i text` a panic, `F i text` another finding (an HTTP
//! 5xx), `H i ms` an input over the time limit (the child then exits), `D n` done. When a
//! child dies by a signal, the input it had started is run again alone to confirm it, and
//! saved. Every finding's input goes to `--findings` as `TARGET-SEED-INDEX.bin`.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;

use crate::targets::{self, Setup, Target, TARGETS};

/// Exit code of a worker whose input ran over the time limit.
const HANG_EXIT: i32 = 3;

/// Fuzz ICMS's parsers of user bytes on stable Rust.
#[derive(Debug, Clone, Parser)]
#[command(name = "icms-fuzz", version, about, long_about = None)]
pub struct Args {
    /// Target: session, urdf, scenario, grasp, skill, http, or `all` (one after another).
    pub target: String,
    /// Campaign seed: input `i` is a pure function of (target, seed, i).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Inputs to run (indices 0..runs; the first few are the seeds themselves).
    #[arg(long, default_value_t = 1_000_000)]
    pub runs: u64,
    /// Child processes at once.
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Stop starting new ranges after this many seconds (the totals say how many ran).
    #[arg(long)]
    pub max_seconds: Option<f64>,
    /// Inputs per child process (default: by target).
    #[arg(long)]
    pub batch: Option<u64>,
    /// Run one input in this process and print what happened (reproduces a finding).
    #[arg(long)]
    pub only: Option<u64>,
    /// Run a saved input file in this process (a finding's `.bin`).
    #[arg(long)]
    pub input: Option<PathBuf>,
    /// Directory of the robot hands' URDFs (seeds); default the repository's `dfs-core/hands`.
    #[arg(long)]
    pub hands: Option<PathBuf>,
    /// Where findings are saved.
    #[arg(long, default_value = "fuzz/findings")]
    pub findings: PathBuf,
    /// Time limit of one input, seconds (an input over it is a hang).
    #[arg(long, default_value_t = 10.0)]
    pub timeout: f64,
    /// Memory limit of a child process (RLIMIT_DATA), MiB.
    #[arg(long, default_value_t = 2048)]
    pub memory_mib: u64,
    /// Stack of the thread that runs the inputs, KiB (2048: a tokio worker's, where the
    /// server parses request bodies).
    #[arg(long, default_value_t = 2048)]
    pub stack_kib: usize,
    /// Print the totals as JSON too.
    #[arg(long)]
    pub json: bool,
    /// Worker mode (internal): run inputs START..END and report on stdout.
    #[arg(long, num_args = 2, value_names = ["START", "END"], hide = true)]
    pub worker: Option<Vec<u64>>,
    /// Write input INDEX to FILE and exit (internal).
    #[arg(long, num_args = 2, value_names = ["INDEX", "FILE"], hide = true)]
    pub dump: Option<Vec<String>>,
    /// Scratch directory of a worker (internal).
    #[arg(long, hide = true)]
    pub scratch: Option<PathBuf>,
}

/// Totals of one target's campaign.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Totals {
    /// Target.
    pub target: String,
    /// Campaign seed.
    pub seed: u64,
    /// Inputs run.
    pub executions: u64,
    /// Wall time, s.
    pub seconds: f64,
    /// Executions per second.
    pub exec_per_s: f64,
    /// Inputs that panicked.
    pub panics: u64,
    /// Inputs that killed their process (abort, stack overflow, out of memory).
    pub aborts: u64,
    /// Inputs over the time limit.
    pub hangs: u64,
    /// Other findings (HTTP 5xx).
    pub server_errors: u64,
    /// Distinct findings: signature → (count, first index).
    pub findings: BTreeMap<String, (u64, u64)>,
}

fn default_hands() -> PathBuf {
    // The workspace is the fuzz crate's parent; the hands' URDFs live in dfs-core.
    let ws = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or(Path::new("."))
        .to_path_buf();
    ws.join("dfs-core/hands")
}

fn default_batch(target: &str) -> u64 {
    match target {
        "http" => 2_000,
        "session" => 10_000,
        _ => 25_000,
    }
}

/// The entry point of `icms-fuzz`.
pub fn main() -> ExitCode {
    let args = Args::parse();
    let targets: Vec<String> = if args.target == "all" {
        TARGETS.iter().map(|s| (*s).to_owned()).collect()
    } else if TARGETS.contains(&args.target.as_str()) {
        vec![args.target.clone()]
    } else {
        eprintln!(
            "icms-fuzz: unknown target {:?} (targets: {}, all)",
            args.target,
            TARGETS.join(", ")
        );
        return ExitCode::from(2);
    };
    if let Some(range) = &args.worker {
        return worker(&args, range[0], range[1]);
    }
    if let Some(d) = &args.dump {
        return dump(&args, &d[0], &d[1]);
    }
    if args.only.is_some() || args.input.is_some() {
        return reproduce(&args);
    }
    let mut all_clean = true;
    let mut all = Vec::new();
    for t in targets {
        let mut a = args.clone();
        a.target = t;
        match campaign(&a) {
            Ok(tot) => {
                print_totals(&tot);
                if args.json {
                    println!("{}", serde_json::to_string(&tot).unwrap_or_default());
                }
                all_clean &= tot.panics + tot.aborts + tot.hangs + tot.server_errors == 0;
                all.push(tot);
            }
            Err(e) => {
                eprintln!("icms-fuzz {}: {e}", a.target);
                return ExitCode::from(2);
            }
        }
    }
    if all.len() > 1 {
        println!("\ntarget    executions   exec/s   wall s  panics aborts hangs 5xx");
        for t in &all {
            println!(
                "{:<9} {:>10} {:>8.0} {:>8.0} {:>7} {:>6} {:>5} {:>3}",
                t.target,
                t.executions,
                t.exec_per_s,
                t.seconds,
                t.panics,
                t.aborts,
                t.hangs,
                t.server_errors
            );
        }
    }
    if all_clean {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}

fn print_totals(t: &Totals) {
    println!(
        "{}: {} executions in {:.1} s ({:.0} exec/s), seed {}: {} panics, {} aborts, {} hangs, {} server errors",
        t.target, t.executions, t.seconds, t.exec_per_s, t.seed, t.panics, t.aborts, t.hangs, t.server_errors
    );
    for (sig, (n, first)) in &t.findings {
        println!(
            "  {n}x {sig}\n     reproduce: icms-fuzz {} --seed {} --only {first}",
            t.target, t.seed
        );
    }
}

fn setup(args: &Args, scratch: &Path) -> Setup {
    Setup {
        hands_dir: args.hands.clone().unwrap_or_else(default_hands),
        scratch: scratch.to_path_buf(),
    }
}

// ---------------------------------------------------------------------------------------------
// panics

/// The last panic's message, location and the interesting frames of its backtrace.
static LAST_PANIC: Mutex<Option<String>> = Mutex::new(None);
/// Panics so far in this process (any thread: a panic caught inside the code under test,
/// such as a blocking task's, counts).
static PANICS: AtomicU64 = AtomicU64::new(0);

fn install_panic_hook() {
    std::panic::set_hook(Box::new(|info| {
        let msg = if let Some(s) = info.payload().downcast_ref::<&str>() {
            (*s).to_owned()
        } else if let Some(s) = info.payload().downcast_ref::<String>() {
            s.clone()
        } else {
            "(non-string panic payload)".to_owned()
        };
        let loc = info
            .location()
            .map_or_else(|| "?".to_owned(), |l| format!("{}:{}", l.file(), l.line()));
        let bt = std::backtrace::Backtrace::force_capture().to_string();
        let frames: Vec<&str> = bt
            .lines()
            .map(str::trim)
            .filter(|l| {
                (l.contains("services::") || l.contains("dfs_core::") || l.contains("api::"))
                    && !l.starts_with("at ")
            })
            .take(6)
            .collect();
        let text = format!(
            "panicked at {loc}: {msg} [{}]",
            frames.join(" <- ").replace('\n', " ")
        );
        PANICS.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut last) = LAST_PANIC.lock() {
            *last = Some(text);
        }
    }));
}

fn take_panic() -> Option<String> {
    LAST_PANIC.lock().ok().and_then(|mut l| l.take())
}

/// Runs one input; `Ok(None)` clean, `Ok(Some(text))` a finding: `P text` or `F text`.
fn run_one(target: &mut dyn Target, input: &[u8]) -> Option<(char, String)> {
    let before = PANICS.load(Ordering::SeqCst);
    let r = std::panic::catch_unwind(AssertUnwindSafe(|| target.run(input)));
    let panicked = PANICS.load(Ordering::SeqCst) != before;
    let panic_text = if panicked { take_panic() } else { None };
    match r {
        Err(_) => Some(('P', panic_text.unwrap_or_else(|| "panic".into()))),
        Ok(Err(e)) => Some((
            if panicked { 'P' } else { 'F' },
            match panic_text {
                Some(p) => format!("{e} ({p})"),
                None => e,
            },
        )),
        Ok(Ok(())) if panicked => Some(('P', panic_text.unwrap_or_default())),
        Ok(Ok(())) => None,
    }
}

// ---------------------------------------------------------------------------------------------
// worker, dump, reproduce

fn scratch_dir(args: &Args) -> Result<(PathBuf, Option<tempfile::TempDir>), String> {
    match &args.scratch {
        Some(p) => {
            std::fs::create_dir_all(p).map_err(|e| format!("{}: {e}", p.display()))?;
            Ok((p.clone(), None))
        }
        None => {
            let t = tempfile::Builder::new()
                .prefix("icms-fuzz-")
                .tempdir_in(targets::scratch_parent())
                .map_err(|e| format!("scratch directory: {e}"))?;
            Ok((t.path().to_path_buf(), Some(t)))
        }
    }
}

/// Runs `f` on a thread with the configured stack (a tokio worker's by default).
fn on_stack<T: Send + 'static>(args: &Args, f: impl FnOnce() -> T + Send + 'static) -> Option<T> {
    std::thread::Builder::new()
        .name("icms-fuzz-input".into())
        .stack_size(args.stack_kib.max(64) * 1024)
        .spawn(f)
        .ok()?
        .join()
        .ok()
}

fn finding_path(args: &Args, index: u64) -> PathBuf {
    args.findings
        .join(format!("{}-{}-{index}.bin", args.target, args.seed))
}

/// Limits this process's data segment (heap and anonymous mappings) to `--memory-mib`.
fn limit_memory(args: &Args) {
    let limit = args.memory_mib.saturating_mul(1 << 20);
    if let Err(e) = rlimit::setrlimit(rlimit::Resource::DATA, limit, limit) {
        eprintln!("icms-fuzz: setting the memory limit: {e}");
    }
}

fn worker(args: &Args, start: u64, end: u64) -> ExitCode {
    limit_memory(args);
    install_panic_hook();
    let args2 = args.clone();
    let code = on_stack(args, move || {
        let args = args2;
        let (scratch, _keep) = match scratch_dir(&args) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("icms-fuzz worker: {e}");
                return 2;
            }
        };
        let mut target = match targets::build(&args.target, &setup(&args, &scratch)) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("icms-fuzz worker: {e}");
                return 2;
            }
        };
        // Watchdog: an input over the time limit is reported and ends the process.
        let current = Arc::new(AtomicU64::new(u64::MAX));
        let started_ms = Arc::new(AtomicU64::new(0));
        let t0 = Instant::now();
        {
            let (current, started_ms) = (Arc::clone(&current), Arc::clone(&started_ms));
            let limit_ms = (args.timeout * 1000.0) as u64;
            std::thread::spawn(move || loop {
                std::thread::sleep(Duration::from_millis(100));
                let s = started_ms.load(Ordering::SeqCst);
                let now = t0.elapsed().as_millis() as u64 + 1;
                if s != 0 && now.saturating_sub(s) > limit_ms {
                    let i = current.load(Ordering::SeqCst);
                    let mut out = std::io::stdout().lock();
                    let _ = writeln!(out, "H {i} {}", now - s);
                    let _ = out.flush();
                    std::process::exit(HANG_EXIT);
                }
            });
        }
        let mut saved: std::collections::BTreeSet<String> = Default::default();
        let mut done = 0u64;
        let (mut gen_s, mut run_s) = (0.0f64, 0.0f64);
        for i in start..end {
            // Announced before it is made: a crash in the generator is attributed to it too.
            {
                let mut out = std::io::stdout().lock();
                if writeln!(out, "S {i}").and_then(|()| out.flush()).is_err() {
                    // The parent is gone (Rust ignores SIGPIPE): stop.
                    std::process::exit(4);
                }
            }
            let tg = Instant::now();
            let input = target.generate(args.seed, i);
            gen_s += tg.elapsed().as_secs_f64();
            let tr = Instant::now();
            current.store(i, Ordering::SeqCst);
            started_ms.store(t0.elapsed().as_millis() as u64 + 1, Ordering::SeqCst);
            let r = run_one(target.as_mut(), &input);
            started_ms.store(0, Ordering::SeqCst);
            run_s += tr.elapsed().as_secs_f64();
            done += 1;
            if let Some((kind, text)) = r {
                let text = text.replace('\n', " ");
                // One saved input per distinct finding per campaign: the first worker to see
                // it claims its marker file.
                let sig = signature(&text);
                if saved.insert(sig.clone()) && claim(&args, &sig) {
                    let _ = std::fs::write(finding_path(&args, i), &input);
                }
                let mut out = std::io::stdout().lock();
                let _ = writeln!(out, "{kind} {i} {text}");
                let _ = out.flush();
            }
        }
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "D {done} generate {gen_s:.3} s, run {run_s:.3} s");
        let _ = out.flush();
        0
    });
    ExitCode::from(code.unwrap_or(2))
}

fn dump(args: &Args, index: &str, file: &str) -> ExitCode {
    let Ok(index) = index.parse::<u64>() else {
        return ExitCode::from(2);
    };
    let (scratch, _keep) = match scratch_dir(args) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("icms-fuzz: {e}");
            return ExitCode::from(2);
        }
    };
    match targets::build(&args.target, &setup(args, &scratch)) {
        Ok(t) => {
            let input = t.generate(args.seed, index);
            if let Some(p) = Path::new(file).parent() {
                let _ = std::fs::create_dir_all(p);
            }
            match std::fs::write(file, input) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("icms-fuzz: {file}: {e}");
                    ExitCode::from(2)
                }
            }
        }
        Err(e) => {
            eprintln!("icms-fuzz: {e}");
            ExitCode::from(2)
        }
    }
}

fn reproduce(args: &Args) -> ExitCode {
    // Same limit as a worker: an allocation over it aborts here too.
    limit_memory(args);
    install_panic_hook();
    let a = args.clone();
    let r = on_stack(args, move || {
        let (scratch, _keep) = scratch_dir(&a)?;
        let mut t = targets::build(&a.target, &setup(&a, &scratch)).map_err(|e| e.to_string())?;
        let input = match (&a.input, a.only) {
            (Some(p), _) => std::fs::read(p).map_err(|e| format!("{}: {e}", p.display()))?,
            (None, Some(i)) => t.generate(a.seed, i),
            (None, None) => return Err("nothing to run".to_owned()),
        };
        println!("input: {} bytes", input.len());
        let t0 = Instant::now();
        let r = run_one(t.as_mut(), &input);
        println!("ran in {:.3} s", t0.elapsed().as_secs_f64());
        Ok(r)
    });
    match r {
        Some(Ok(None)) => {
            println!("no finding");
            ExitCode::SUCCESS
        }
        Some(Ok(Some((kind, text)))) => {
            println!("{}: {text}", if kind == 'P' { "PANIC" } else { "FINDING" });
            ExitCode::from(1)
        }
        Some(Err(e)) => {
            eprintln!("icms-fuzz: {e}");
            ExitCode::from(2)
        }
        None => ExitCode::from(1),
    }
}

/// What a dead worker's stderr says: the reason line (allocation failure, stack overflow,
/// panic, fatal error) and the project's frames of the backtrace, if any.
fn crash_summary(stderr: &str) -> String {
    let keys = [
        "memory allocation",
        "overflowed",
        "panicked",
        "fatal",
        "abort",
        "SIG",
    ];
    let reason = stderr
        .lines()
        .find(|l| keys.iter().any(|k| l.contains(k)))
        .or_else(|| stderr.lines().rfind(|l| !l.trim().is_empty()))
        .unwrap_or("")
        .trim();
    let frames: Vec<&str> = stderr
        .lines()
        .map(str::trim)
        .filter(|l| {
            [
                "services::",
                "dfs_core::",
                "api::",
                "mcap::",
                "urdf_rs",
                "serde_json::",
            ]
            .iter()
            .any(|k| l.contains(k))
        })
        .filter_map(|l| l.split_once(": ").map(|(_, f)| f))
        .take(5)
        .collect();
    let mut out: String = reason.chars().take(200).collect();
    if !frames.is_empty() {
        out.push_str(" [");
        out.push_str(&frames.join(" <- "));
        out.push(']');
    }
    out
}

/// Claims the marker of a finding's signature (`.TARGET-SEED-HASH.seen` in the findings
/// directory); false when another worker already did.
fn claim(args: &Args, sig: &str) -> bool {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in sig.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let _ = std::fs::create_dir_all(&args.findings);
    let marker = args
        .findings
        .join(format!(".{}-{}-{h:016x}.seen", args.target, args.seed));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(marker)
        .is_ok()
}

/// A finding's signature: its panic location, or its first words.
fn signature(text: &str) -> String {
    if let Some(rest) = text.strip_prefix("panicked at ") {
        return rest.split(':').take(2).collect::<Vec<_>>().join(":");
    }
    if let Some(p) = text.find("panicked at ") {
        return signature(&text[p..]);
    }
    text.chars()
        .take(160)
        .map(|c| if c.is_ascii_digit() { 'N' } else { c })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// campaign (parent)

#[derive(Default)]
struct Shared {
    next: u64,
    totals: Totals,
    stopped: bool,
}

fn campaign(args: &Args) -> Result<Totals, String> {
    let exe = std::env::current_exe().map_err(|e| format!("own executable: {e}"))?;
    let batch = args
        .batch
        .unwrap_or_else(|| default_batch(&args.target))
        .max(1);
    let shared = Arc::new(Mutex::new(Shared {
        next: 0,
        totals: Totals {
            target: args.target.clone(),
            seed: args.seed,
            ..Totals::default()
        },
        stopped: false,
    }));
    let t0 = Instant::now();
    let progress_every = Duration::from_secs(30);
    let last_progress = Arc::new(Mutex::new(Instant::now()));
    let mut handles = Vec::new();
    for _ in 0..args.jobs.max(1) {
        let (args, shared, exe, last_progress) = (
            args.clone(),
            Arc::clone(&shared),
            exe.clone(),
            Arc::clone(&last_progress),
        );
        handles.push(std::thread::spawn(move || loop {
            let range = {
                let Ok(mut s) = shared.lock() else { return };
                let over_time = args
                    .max_seconds
                    .is_some_and(|m| t0.elapsed().as_secs_f64() >= m);
                if over_time {
                    s.stopped = true;
                }
                if s.next >= args.runs || s.stopped {
                    return;
                }
                let a = s.next;
                // With a time budget, smaller ranges so that the stop comes on time.
                let b = (a + batch).min(args.runs);
                s.next = b;
                (a, b)
            };
            run_range(
                &args,
                &exe,
                range.0,
                range.1,
                &shared,
                t0,
                &last_progress,
                progress_every,
            );
        }));
    }
    for h in handles {
        let _ = h.join();
    }
    let mut s = shared.lock().map_err(|_| "lock poisoned".to_owned())?;
    s.totals.seconds = t0.elapsed().as_secs_f64();
    s.totals.exec_per_s = s.totals.executions as f64 / s.totals.seconds.max(1e-9);
    Ok(s.totals.clone())
}

enum ChildEnd {
    Done,
    Hang(u64),
    Crash { last: Option<u64>, why: String },
}

/// Runs a child over `a..b`; returns how it ended, with every reported event recorded.
fn run_child(
    args: &Args,
    exe: &Path,
    a: u64,
    b: u64,
    shared: &Mutex<Shared>,
    count: bool,
) -> Result<ChildEnd, String> {
    let scratch = tempfile::Builder::new()
        .prefix("icms-fuzz-")
        .tempdir_in(targets::scratch_parent())
        .map_err(|e| format!("scratch directory: {e}"))?;
    let stderr_path = scratch.path().join("stderr.txt");
    let stderr = std::fs::File::create(&stderr_path).map_err(|e| e.to_string())?;
    let mut cmd = Command::new(exe);
    cmd.arg(&args.target)
        .args(["--seed", &args.seed.to_string()])
        .args(["--worker", &a.to_string(), &b.to_string()])
        .arg("--findings")
        .arg(&args.findings)
        .args(["--timeout", &args.timeout.to_string()])
        .args(["--memory-mib", &args.memory_mib.to_string()])
        .args(["--stack-kib", &args.stack_kib.to_string()])
        .arg("--scratch")
        .arg(scratch.path().join("w"))
        .stdout(Stdio::piped())
        .stderr(Stdio::from(stderr))
        .stdin(Stdio::null());
    if let Some(h) = &args.hands {
        cmd.arg("--hands").arg(h);
    }
    let mut child = cmd.spawn().map_err(|e| format!("starting a worker: {e}"))?;
    let stdout = child.stdout.take().ok_or("worker stdout")?;
    let mut last_started = None;
    let mut hang = None;
    let mut done = false;
    for line in BufReader::new(stdout).lines() {
        let Ok(line) = line else { break };
        let mut parts = line.splitn(3, ' ');
        let kind = parts.next().unwrap_or("");
        let idx: Option<u64> = parts.next().and_then(|s| s.parse().ok());
        let text = parts.next().unwrap_or("").to_owned();
        match kind {
            "S" => {
                if count {
                    if let Ok(mut s) = shared.lock() {
                        s.totals.executions += 1;
                    }
                }
                last_started = idx;
            }
            "P" | "F" => {
                if let (Some(i), Ok(mut s)) = (idx, shared.lock()) {
                    if kind == "P" {
                        s.totals.panics += 1;
                    } else {
                        s.totals.server_errors += 1;
                    }
                    let e = s.totals.findings.entry(signature(&text)).or_insert((0, i));
                    e.0 += 1;
                    e.1 = e.1.min(i);
                    eprintln!("[{}] finding at input {i}: {text}", args.target);
                }
            }
            "H" => hang = idx,
            "D" => done = true,
            _ => {}
        }
    }
    let status = child
        .wait()
        .map_err(|e| format!("waiting for a worker: {e}"))?;
    if let Some(i) = hang {
        return Ok(ChildEnd::Hang(i));
    }
    if done && status.success() {
        return Ok(ChildEnd::Done);
    }
    let mut err_text = String::new();
    if let Ok(mut f) = std::fs::File::open(&stderr_path) {
        let _ = f.read_to_string(&mut err_text);
    }
    let tail = crash_summary(&err_text);
    if let Some(i) = last_started {
        let _ = std::fs::create_dir_all(&args.findings);
        let _ = std::fs::write(
            args.findings
                .join(format!("{}-{}-{i}.stderr.txt", args.target, args.seed)),
            &err_text,
        );
    }
    use std::os::unix::process::ExitStatusExt;
    let why = match status.signal() {
        Some(sig) => format!("killed by signal {sig}: {tail}"),
        None => format!("exited with {status}: {tail}"),
    };
    if last_started.is_none() && status.code() == Some(2) {
        return Err(format!("worker failed to start: {err_text}"));
    }
    Ok(ChildEnd::Crash {
        last: last_started,
        why,
    })
}

#[allow(clippy::too_many_arguments)]
fn run_range(
    args: &Args,
    exe: &Path,
    a: u64,
    b: u64,
    shared: &Mutex<Shared>,
    t0: Instant,
    last_progress: &Mutex<Instant>,
    every: Duration,
) {
    let mut start = a;
    while start < b {
        let end = match run_child(args, exe, start, b, shared, true) {
            Ok(e) => e,
            Err(e) => {
                eprintln!("icms-fuzz: {e}");
                if let Ok(mut s) = shared.lock() {
                    s.stopped = true;
                }
                return;
            }
        };
        match end {
            ChildEnd::Done => start = b,
            ChildEnd::Hang(i) => {
                save_by_dump(args, exe, i);
                if let Ok(mut s) = shared.lock() {
                    s.totals.hangs += 1;
                    let e = s
                        .totals
                        .findings
                        .entry(format!("hang over {} s", args.timeout))
                        .or_insert((0, i));
                    e.0 += 1;
                    e.1 = e.1.min(i);
                }
                eprintln!("[{}] hang at input {i}", args.target);
                start = i + 1;
            }
            ChildEnd::Crash { last, why } => {
                let Some(i) = last else {
                    eprintln!(
                        "[{}] worker died before its first input: {why}",
                        args.target
                    );
                    if let Ok(mut s) = shared.lock() {
                        s.stopped = true;
                    }
                    return;
                };
                // Confirm alone; if it does not reproduce alone, bisect the range it ran in.
                let culprit = match run_child(args, exe, i, i + 1, shared, false) {
                    Ok(ChildEnd::Crash { .. }) => i,
                    _ => bisect(args, exe, start, i + 1, shared).unwrap_or(i),
                };
                save_by_dump(args, exe, culprit);
                if let Ok(mut s) = shared.lock() {
                    s.totals.aborts += 1;
                    let generic = why
                        .chars()
                        .map(|c| if c.is_ascii_digit() { 'N' } else { c })
                        .collect::<String>();
                    let sig = if culprit == i {
                        generic
                    } else {
                        format!("{generic} (after the inputs before it)")
                    };
                    let e = s.totals.findings.entry(sig).or_insert((0, culprit));
                    e.0 += 1;
                    e.1 = e.1.min(culprit);
                }
                eprintln!("[{}] abort at input {culprit}: {why}", args.target);
                start = i + 1;
            }
        }
        if let (Ok(mut lp), Ok(s)) = (last_progress.lock(), shared.lock()) {
            if lp.elapsed() >= every {
                *lp = Instant::now();
                let el = t0.elapsed().as_secs_f64();
                eprintln!(
                    "[{}] {} executions, {:.0} exec/s, {:.0} s",
                    args.target,
                    s.totals.executions,
                    s.totals.executions as f64 / el.max(1e-9),
                    el
                );
            }
        }
    }
}

/// The smallest `lo..hi` prefix end whose run crashes, by halving (inputs may depend on
/// state that earlier ones left, as HTTP requests do).
fn bisect(args: &Args, exe: &Path, lo: u64, hi: u64, shared: &Mutex<Shared>) -> Option<u64> {
    let crashes = |a: u64, b: u64| {
        matches!(
            run_child(args, exe, a, b, shared, false),
            Ok(ChildEnd::Crash { .. })
        )
    };
    if !crashes(lo, hi) {
        return None;
    }
    let (mut a, mut b) = (lo, hi);
    while b - a > 1 {
        let mid = a + (b - a) / 2;
        if crashes(mid, b) {
            a = mid;
        } else if crashes(a, mid) {
            b = mid;
        } else {
            break;
        }
    }
    Some(b - 1)
}

fn save_by_dump(args: &Args, exe: &Path, index: u64) {
    let file = finding_path(args, index);
    let mut cmd = Command::new(exe);
    cmd.arg(&args.target)
        .args(["--seed", &args.seed.to_string()])
        .arg("--dump")
        .arg(index.to_string())
        .arg(&file)
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    if let Some(h) = &args.hands {
        cmd.arg("--hands").arg(h);
    }
    let _ = cmd.status();
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Fixed(Result<(), String>, bool);

    impl Target for Fixed {
        fn generate(&self, _: u64, _: u64) -> Vec<u8> {
            Vec::new()
        }
        fn run(&mut self, _: &[u8]) -> Result<(), String> {
            if self.1 {
                // A panic caught inside the code under test counts too.
                let _ = std::thread::spawn(|| panic!("inner boom")).join();
            }
            if self.0 == Err("panic".into()) {
                panic!("boom {}", 7);
            }
            self.0.clone()
        }
        fn seeds(&self) -> usize {
            1
        }
    }

    #[test]
    fn panics_and_other_findings_are_reported_with_their_location() {
        install_panic_hook();
        let (k, text) = run_one(&mut Fixed(Err("panic".into()), false), b"").unwrap();
        assert_eq!(k, 'P');
        assert!(
            text.contains("boom 7") && text.contains("driver.rs"),
            "{text}"
        );
        let (k, text) = run_one(&mut Fixed(Ok(()), true), b"").unwrap();
        assert_eq!(k, 'P');
        assert!(text.contains("inner boom"), "{text}");
        let (k, text) = run_one(&mut Fixed(Err("HTTP 500".into()), false), b"").unwrap();
        assert_eq!((k, text.as_str()), ('F', "HTTP 500"));
        assert!(run_one(&mut Fixed(Ok(()), false), b"").is_none());
        // Back to the default hook, which prints other tests' failures.
        drop(std::panic::take_hook());
        assert_eq!(
            signature("panicked at src/a.rs:12:5: index 27 out of range"),
            "src/a.rs:12"
        );
    }
}
