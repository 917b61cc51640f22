//! Issue 22 (B-E): the web page served by the real `icms serve` at `/`, driven in two real
//! browsers by one flow (`tests/python/web_page.py`, Python's selenium): headless Chromium
//! (Debian's `chromium` and `chromium-driver`) and Firefox ESR (Debian's `firefox-esr` through
//! `geckodriver`, a Rust crate, on a private Xvfb display because Firefox's own headless mode
//! has no WebGL without a GPU), over a data base of 100 000 synthetic skills plus real simulated
//! sessions: the skill list loads, filters and pages; a skill shows its phases, its force plot
//! drawn, its contacts in 3D and its nearest skills; a replay runs and its animation advances
//! (and pauses); a scenario named `<script>alert(1)</script>` is shown as text and runs
//! nothing; the session list is newest first, pages, and filters by scenario and shape; the
//! hands are drawn and an invalid hand upload shows the problem's title and detail; unknown
//! pages answer the HTML not-found page; `/docs` renders the OpenAPI document; and the
//! browser's console has no error (Chromium's browser log; Firefox's WebDriver BiDi log of
//! `console.error`, uncaught exceptions and unhandled rejections). Screenshots go to
//! `target/screenshots/<browser>/`.
//!
//! It prints, per browser, how long after navigation the list of 100 000 skills is on screen
//! and the replay animation's frames per second (requestAnimationFrame); it asserts correctness
//! only, never a time.
//!
//! Needs `selenium` in the test interpreter, `chromium` + `chromedriver`, and `firefox-esr` +
//! `geckodriver` + `Xvfb` on the PATH: `scripts/test` installs them (apt-get for the browsers
//! and Xvfb, `cargo install` for geckodriver). A browser whose programs are missing is
//! skipped, or fails the test under `ICMS_REQUIRE_TOOLS=1`.

use crate::interpreter;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;
use services::store::Store;
use tests::{session_bytes, ServerProcess};

/// Skills in the data base the list is measured on (the figure).
const SYNTHETIC_SKILLS: usize = 100_000;

fn on_path(program: &str) -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join(program))
            .find(|p| p.is_file())
    })
}

/// A browser the flow runs in: its name for the script and the programs it needs.
struct Browser {
    name: &'static str,
    /// Each program (any of the alternatives) on the PATH.
    programs: &'static [&'static [&'static str]],
    install: &'static str,
}

const BROWSERS: [Browser; 2] = [
    Browser {
        name: "chromium",
        programs: &[&["chromium"], &["chromedriver"]],
        install: "Debian: apt-get install chromium chromium-driver",
    },
    Browser {
        name: "firefox",
        programs: &[&["firefox-esr", "firefox"], &["geckodriver"], &["Xvfb"]],
        install: "Debian: apt-get install firefox-esr xvfb; cargo install --locked geckodriver",
    },
];

/// Whether the browser's programs are all there, or why not (panics under
/// `ICMS_REQUIRE_TOOLS`).
fn browser_present(b: &Browser) -> bool {
    let missing: Vec<String> = b
        .programs
        .iter()
        .filter(|alternatives| alternatives.iter().all(|p| on_path(p).is_none()))
        .map(|alternatives| alternatives.join(" or "))
        .collect();
    if missing.is_empty() {
        return true;
    }
    let why = format!(
        "{}: {} not on the PATH ({})",
        b.name,
        missing.join(" and "),
        b.install
    );
    if std::env::var_os("ICMS_REQUIRE_TOOLS").is_some_and(|v| !v.is_empty()) {
        panic!("{why}; scripts/test installs them");
    }
    eprintln!("SKIPPED (a browser check): {why}. Run scripts/test to install them.");
    false
}

/// A session of `sphere-lift` whose scenario is named `name`.
fn session_named(name: &str, seed: u64) -> Vec<u8> {
    let mut s = dfs_core::scenario::Scenario::builtin("sphere-lift", seed).expect("built-in");
    s.name = name.to_owned();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    services::session::record_simulation(&s, None, &path, |_, _| {}).expect("simulation");
    std::fs::read(&path).unwrap()
}

fn first_skill(reply: &tests::Reply) -> i64 {
    assert!(
        reply.status == 201,
        "{}: {}",
        reply.status,
        String::from_utf8_lossy(&reply.body)
    );
    reply.json()["skills"][0]["id"]
        .as_i64()
        .expect("a stored skill")
}

/// Checks what the flow saw in `browser`; `box_sessions` is how many sessions hold a box (at
/// most a page of 50 are shown).
fn check(browser: &str, seen: &Value, box_sessions: usize) {
    let ctx = |what: &str| format!("{browser}: {what}: {seen:#}");
    assert!(seen.get("failure").is_none(), "{}", ctx("failure"));
    assert_eq!(seen["list_rows"], 50, "{}", ctx("list_rows"));
    assert_eq!(seen["filtered_rows"], 50, "{}", ctx("filtered_rows"));
    assert_eq!(seen["filtered_all_box"], true, "{}", ctx("filter"));
    assert_eq!(seen["filtered_sorted_desc"], true, "{}", ctx("sort"));
    assert_eq!(seen["next_page_continues"], true, "{}", ctx("next page"));
    assert!(
        seen["timeline_phases"].as_u64().unwrap() >= 5,
        "{}",
        ctx("phases")
    );
    assert!(
        seen["plot_pixels"].as_u64().unwrap() > 1000,
        "{}",
        ctx("plot")
    );
    assert!(
        seen["plot_series"].as_u64().unwrap() >= 2,
        "{}",
        ctx("plot")
    );
    assert_eq!(seen["contacts_canvas"], 1, "{}", ctx("contacts 3D"));
    assert!(
        seen["similar_rows"].as_u64().unwrap() >= 1,
        "{}",
        ctx("similar")
    );
    assert_eq!(seen["replay_advanced"], true, "{}", ctx("replay"));
    assert_eq!(seen["pause_holds"], true, "{}", ctx("pause"));
    assert_eq!(seen["replay_listed"], 1, "{}", ctx("replay list"));
    assert_eq!(seen["replay_report"], true, "{}", ctx("report"));
    assert_eq!(seen["xss_text_on_skill"], true, "{}", ctx("xss"));
    assert_eq!(seen["xss_text_on_session"], true, "{}", ctx("xss"));
    assert_eq!(seen["xss_text_on_sessions"], true, "{}", ctx("xss"));
    assert_eq!(seen["xss_alert_session"], false, "{}", ctx("xss"));
    assert_eq!(seen["xss_alert"], false, "{}", ctx("xss"));
    assert_eq!(seen["xss_script_elements"], 0, "{}", ctx("xss"));
    assert!(
        seen["foxglove_links"].as_u64().unwrap() >= 3,
        "{}",
        ctx("foxglove")
    );
    // Sessions: newest first (the box session was uploaded last), pages both ways, filters.
    assert_eq!(seen["sessions_rows"], 50, "{}", ctx("sessions"));
    assert_eq!(seen["sessions_newest_first"], true, "{}", ctx("sessions"));
    assert_eq!(
        seen["sessions_first_scenario"],
        "box-pinch-lift",
        "{}",
        ctx("sessions")
    );
    assert_eq!(seen["sessions_next_continues"], true, "{}", ctx("sessions"));
    assert_eq!(seen["sessions_prev_returns"], true, "{}", ctx("sessions"));
    assert_eq!(
        seen["sessions_by_scenario"],
        serde_json::json!(["sphere-lift", "sphere-lift"]),
        "{}",
        ctx("sessions by scenario")
    );
    assert_eq!(
        seen["sessions_by_shape_rows"],
        box_sessions.min(50),
        "{}",
        ctx("by shape")
    );
    assert_eq!(
        seen["sessions_by_shape_all_box"],
        true,
        "{}",
        ctx("by shape")
    );
    assert_eq!(
        seen["sessions_by_shape_newest_first"],
        true,
        "{}",
        ctx("by shape")
    );
    assert_eq!(seen["hand_cards"], 5, "{}", ctx("hands"));
    assert_eq!(seen["hand_canvases"], 5, "{}", ctx("hands"));
    let upload_error = seen["upload_error"].as_str().unwrap();
    assert!(
        upload_error.starts_with("Unprocessable Entity: ") && upload_error.len() > 30,
        "{}",
        ctx("upload error")
    );
    assert!(
        seen["error_bar"]
            .as_str()
            .unwrap()
            .contains("Unprocessable Entity"),
        "{}",
        ctx("error bar")
    );
    assert_eq!(seen["not_found_page"], true, "{}", ctx("not found"));
    assert_eq!(
        seen["docs_title"]
            .as_str()
            .map(|t| t.starts_with("ICMS skill service")),
        Some(true),
        "{}",
        ctx("docs")
    );
    assert!(
        seen["docs_operations"].as_u64().unwrap() >= 20,
        "{}",
        ctx("docs")
    );
    assert_eq!(
        seen["console_errors"],
        serde_json::json!([]),
        "{}",
        ctx("console errors")
    );
}

/// Runs the flow in `browser` against `base`, replaying `skill`; what it saw.
async fn run_flow(python: &Path, browser: &str, base: &str, skill: i64, xss_skill: i64) -> Value {
    let shots = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../target/screenshots")
        .join(browser);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/web_page.py");
    let mut cmd = Command::new(python);
    cmd.arg(&script)
        .args([browser, base, &skill.to_string(), &xss_skill.to_string()])
        .arg(&shots);
    let started = Instant::now();
    let out =
        tokio::task::spawn_blocking(move || cmd.output().expect("running the browser script"))
            .await
            .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "the browser script failed in {browser}:\n{stdout}\n{stderr}"
    );
    let line = stdout
        .lines()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| {
            panic!("no JSON from the browser script in {browser}:\n{stdout}\n{stderr}")
        });
    let seen: Value = serde_json::from_str(line).unwrap();
    eprintln!("web_page ({browser}): {seen:#}");
    // Printed, never asserted: wall-clock figures of a shared machine.
    println!(
        "web_page ({browser} {}): the list of {SYNTHETIC_SKILLS} skills was on screen {:.0} ms \
         after navigation started (DOMContentLoaded {:.0} ms); the replay animation ran at {:.1} \
         frames/s (requestAnimationFrame); the whole flow took {:.1} s (browser start {:.1} s)",
        seen["browser_version"].as_str().unwrap_or("?"),
        seen["list_rendered_ms"].as_f64().unwrap_or(f64::NAN),
        seen["list_dom_content_loaded_ms"]
            .as_f64()
            .unwrap_or(f64::NAN),
        seen["animation_fps"].as_f64().unwrap_or(f64::NAN),
        started.elapsed().as_secs_f64(),
        seen["browser_start_s"].as_f64().unwrap_or(f64::NAN),
    );
    seen
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_web_page_works_in_headless_chromium_and_firefox() {
    let Some(python) = interpreter::python_with(&["selenium"]) else {
        return;
    };
    let browsers: Vec<&Browser> = BROWSERS.iter().filter(|b| browser_present(b)).collect();
    if browsers.is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let started = Instant::now();
    {
        let store = Store::open(dir.path()).await.expect("data base");
        services::store::bench::generate_synthetic(&store, SYNTHETIC_SKILLS, 22)
            .await
            .expect("synthetic skills");
        store.close().await;
    }
    eprintln!(
        "web_page: {SYNTHETIC_SKILLS} synthetic skills stored in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let data = dir.path().to_str().unwrap();
    let server = ServerProcess::start(
        env!("CARGO_BIN_EXE_icms-e2e"),
        dir.path(),
        // Every replay answered 202 with its job: the page follows the job to its replay.
        &["--no-demo", "--data", data, "--job-wait", "0"],
        "warn",
    );
    let c = &server.client;
    // A sphere-lift skill for each browser to replay (its own, so each sees one replay).
    let mut replay_skills = Vec::new();
    for seed in [1, 3] {
        replay_skills.push(first_skill(
            &c.upload(&session_bytes("sphere-lift", seed, None), None)
                .await,
        ));
    }
    let xss = "<script>alert(1)</script>";
    let xss_skill = first_skill(&c.upload(&session_named(xss, 2), None).await);
    // A box session, the newest, for the filters and the session list's order.
    first_skill(
        &c.upload(&session_bytes("box-pinch-lift", 1, None), None)
            .await,
    );

    let box_sessions = c.get("/api/v1/sessions?shape=box&limit=1000").await.json()["items"]
        .as_array()
        .unwrap()
        .len();
    assert!(box_sessions >= 2, "{box_sessions} box sessions");
    let mut seen = Vec::new();
    for (browser, skill) in browsers.iter().zip(&replay_skills) {
        seen.push(run_flow(&python, browser.name, &c.base, *skill, xss_skill).await);
    }
    for ((browser, skill), seen) in browsers.iter().zip(&replay_skills).zip(&seen) {
        check(browser.name, seen, box_sessions);
        // The replay is stored like one over the API.
        let replays = c
            .get(&format!("/api/v1/skills/{skill}/replays"))
            .await
            .json();
        assert_eq!(
            replays["items"].as_array().unwrap().len(),
            1,
            "{}: {replays}",
            browser.name
        );
    }
    server.terminate();
    let (code, log) = server
        .wait_within(Duration::from_secs(30))
        .expect("icms serve stops on SIGTERM");
    assert_eq!(code, Some(0), "{log}");
}
