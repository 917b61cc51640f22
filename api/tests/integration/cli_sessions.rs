//! `icms scenarios`, `simulate`, `salvage`, `import-glove` and `export-glove` end to end: the
//! binary as a user runs it, the files it writes read back with the library.

use crate::common;
use common::{icms, simulate_in};

use serde_json::Value;
use services::session::read_session;
use std::path::Path;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn scenarios_lists_every_builtin_with_a_description() {
    let (code, out, err) = icms(&["scenarios", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let names: Vec<&str> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, dfs_core::scenario::Scenario::BUILTINS);
    for e in v.as_array().unwrap() {
        assert!(!e["description"].as_str().unwrap().is_empty());
        assert!(e["duration_s"].as_f64().unwrap() > 0.0);
    }
    let (code, text, _) = icms(&["scenarios"]);
    assert_eq!(code, 0);
    assert_eq!(text.lines().count(), names.len());
}

#[test]
fn simulate_records_a_session_that_reads_back_and_salvage_recovers_a_truncated_copy() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.mcap");
    let (code, stdout, err) = icms(&[
        "simulate",
        "--scenario",
        "box-pinch-lift",
        "--seed",
        "3",
        "--duration",
        "2.5",
        "--out",
        p(&out),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.is_empty(),
        "no progress output when stderr is not a terminal: {err}"
    );
    let report: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(report["ticks"], 2500);
    assert_eq!(report["seed"], 3);
    assert_eq!(report["messages_per_topic"]["/dfs/contacts"], 2500);
    let session = read_session(&out).unwrap();
    assert_eq!(session.ticks(), 2500);
    assert_eq!(session.metadata["seed"], "3");

    // A writer that died mid-file: cut the file at 70 %.
    let bytes = std::fs::read(&out).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 7 / 10]).unwrap();
    assert!(read_session(&cut).is_err());
    let fixed = dir.path().join("fixed.mcap");
    let (code, stdout, err) = icms(&["salvage", p(&cut), "--out", p(&fixed), "--json"]);
    assert_eq!(code, 0, "{err}");
    let report: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(report["input_was_complete"], false);
    assert!(report["messages"].as_u64().unwrap() > 0);
    let salvaged = read_session(&fixed).unwrap();
    assert!(
        salvaged.ticks() >= 1000 && salvaged.ticks() < 2500,
        "{}",
        salvaged.ticks()
    );
    assert_eq!(
        salvaged.joint_states[..],
        session.joint_states[..salvaged.ticks()]
    );
    assert_eq!(salvaged.metadata["scenario"], "box-pinch-lift");
    // A salvage that fails leaves a file already at --out as it was: it was truncated to an
    // empty MCAP (not an MCAP input) or deleted (nothing recoverable).
    let json_file = dir.path().join("j.mcap");
    std::fs::write(&json_file, "{\"not\": \"mcap\"}").unwrap();
    let magic = dir.path().join("magic.mcap");
    std::fs::write(&magic, &bytes[..8]).unwrap();
    for bad in [&json_file, &magic] {
        let (code, _, err) = icms(&["salvage", p(bad), "--out", p(&fixed)]);
        assert_ne!(code, 0, "{}", bad.display());
        assert!(!err.is_empty());
        assert_eq!(read_session(&fixed).unwrap().ticks(), salvaged.ticks());
    }
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".part"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    // The simulated session's /joint_states (foxglove.JointStates, 50 Hz) is a glove recording.
    let import_to = |to: &Path| {
        icms(&[
            "import-glove",
            "--input",
            p(&out),
            "--object",
            "box-pinch-lift",
            "--out",
            p(to),
            "--json",
        ])
    };
    let imported = dir.path().join("imported.mcap");
    let (code, stdout, err) = import_to(&imported);
    assert_eq!(code, 0, "{err}");
    let report: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(report["input_samples"], 125);
    // --out the input: the recording replaced the glove recording it was reading.
    let (code, _, err) = import_to(&out);
    assert_ne!(code, 0);
    assert!(err.contains("is the --input file"), "{err}");
    assert_eq!(read_session(&out).unwrap().ticks(), 2500);
    let back = read_session(&imported).unwrap();
    assert_eq!(back.ticks(), 2481); // 0 … 2480 ms
    assert!(back.phases.is_empty());
}

#[test]
fn import_glove_reads_a_csv_and_rejects_bad_columns_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let hand = dfs_core::hand::HandModel::glove10();
    let mut header = vec!["time_s".to_owned()];
    header.extend(hand.dof_names.iter().cloned());
    header.extend(hand.dof_names.iter().map(|n| format!("tau_{n}")));
    let mut text = header.join(",") + "\n";
    for i in 0..200 {
        let q: Vec<String> = (0..hand.dof())
            .map(|d| {
                let mid = 0.5 * (hand.dof_lower[d] + hand.dof_upper[d]);
                format!("{}", mid + 0.01 * (i as f64 * 0.05).sin())
            })
            .collect();
        let tau = vec!["0.01".to_owned(); hand.dof()];
        text += &format!("{},{},{}\n", i as f64 * 0.005, q.join(","), tau.join(","));
    }
    let csv = dir.path().join("glove.csv");
    std::fs::write(&csv, &text).unwrap();
    let (code, stdout, err) = icms(&[
        "import-glove",
        "--input",
        p(&csv),
        "--object",
        r#"{"shape": "sphere", "radius": 0.04, "mass": 0.5, "mu": 0.8, "position": [0.3, 0.0, 0.04]}"#,
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("996 ticks"), "{stdout}");
    let default_out = dir.path().join("glove.session.mcap");
    assert_eq!(read_session(&default_out).unwrap().ticks(), 996);

    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, text.replacen(",0.01\n", ",0.01,7\n", 1)).unwrap();
    let (code, _, err) = icms(&[
        "import-glove",
        "--input",
        p(&bad),
        "--object",
        "sphere-lift",
    ]);
    assert_ne!(code, 0);
    assert!(
        err.contains("bad.csv line 2") && err.contains("columns"),
        "{err}"
    );

    let (code, _, err) = icms(&[
        "import-glove",
        "--input",
        p(&csv),
        "--object",
        r#"{"shape": "sphere", "radius": 0.04, "mass": 0.5, "mu": -1}"#,
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("object.mu"), "{err}");
}

/// The names of each skill's phases in `icms segment --json` of `path`.
fn skill_phases(path: &Path) -> Vec<Vec<String>> {
    let (code, out, err) = icms(&["segment", p(path), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    v["skills"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            s["phases"]
                .as_array()
                .unwrap()
                .iter()
                .map(|ph| ph["name"].as_str().unwrap().to_owned())
                .collect()
        })
        .collect()
}

#[test]
fn export_glove_then_import_glove_finds_the_same_skills() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("s.mcap");
    simulate_in(dir.path(), "sphere-lift", &["--seed", "1"], p(&session));
    let csv = dir.path().join("s.csv");
    let (code, out, err) = icms(&["export-glove", p(&session), "--out", p(&csv), "--json"]);
    assert_eq!(code, 0, "{err}");
    let report: Value = serde_json::from_str(&out).unwrap();
    let ticks = read_session(&session).unwrap().ticks();
    assert_eq!(report["rows"], ticks);
    assert_eq!(report["hand"], "glove10");
    assert_eq!(report["dofs"].as_array().unwrap().len(), 10);
    let object = report["object"].to_string();
    let (code, text, _) = icms(&["export-glove", p(&session), "--out", p(&csv)]);
    assert_eq!(code, 0);
    assert!(text.contains("import it with: icms import-glove"), "{text}");
    assert!(!text.contains("--whole-hand"), "a fingertip grasp: {text}");

    let again = dir.path().join("again.mcap");
    let import = |extra: &[&str]| {
        let mut args = vec!["import-glove", "--input", p(&csv), "--object", &object];
        args.extend_from_slice(extra);
        icms(&args)
    };
    let (code, out, err) = import(&["--hand", "glove10", "--out", p(&again), "--json"]);
    assert_eq!(code, 0, "{err}");
    let report: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(report["glove_input"], "torques");
    assert_eq!(report["wrist"], "csv");
    assert_eq!(report["hand"], "glove10");
    assert_eq!(report["contact_model"], "soft_finger");
    assert_eq!(report["ticks"], ticks);
    let skills = skill_phases(&session);
    assert_eq!(skills.len(), 1);
    assert_eq!(skill_phases(&again), skills);

    // A calibration that names no DOF of the hand, a fixed base for a recording with wrist
    // poses, another hand's columns, an unknown hand: refused, naming what is wrong.
    let cal = dir.path().join("cal.json");
    std::fs::write(
        &cal,
        r#"{"offsets": {"index_mcp": 0.01, "pinky_twist": 0.1}}"#,
    )
    .unwrap();
    let (code, _, err) = import(&["--calibration", p(&cal), "--out", p(&again)]);
    assert_ne!(code, 0);
    assert!(
        err.contains("cal.json") && err.contains("offsets.pinky_twist"),
        "{err}"
    );
    std::fs::write(&cal, r#"{"offsets": {"index_mcp": 0.01}, "scale": {}}"#).unwrap();
    let (code, _, err) = import(&["--calibration", p(&cal), "--out", p(&again)]);
    assert_ne!(code, 0);
    assert!(
        err.contains("cal.json") && err.contains("unknown field `scale`"),
        "{err}"
    );
    std::fs::write(&cal, r#"{"offsets": {"index_mcp": 0.01}}"#).unwrap();
    let calibrated = dir.path().join("calibrated.mcap");
    let (code, out, err) = import(&["--calibration", p(&cal), "--out", p(&calibrated)]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("torques") && out.contains("wrist csv"),
        "{out}"
    );
    let s = read_session(&calibrated).unwrap();
    assert!(s.metadata["calibration"].contains("index_mcp"));
    let (code, _, err) = import(&["--base", "0,0,0.1", "--out", p(&again)]);
    assert_ne!(code, 0);
    assert!(
        err.contains("--base") && err.contains("wrist poses"),
        "{err}"
    );
    let (code, _, err) = import(&["--hand", "allegro", "--out", p(&again)]);
    assert_ne!(code, 0);
    assert!(
        err.contains("s.csv line 1") && err.contains("allegro"),
        "{err}"
    );
    let (code, _, err) = import(&[
        "--hand",
        "no-such-hand",
        "--data",
        p(dir.path()),
        "--out",
        p(&again),
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("--hand \"no-such-hand\""), "{err}");
    let (code, _, err) = import(&["--calibration", p(&cal), "--out", p(&cal)]);
    assert_ne!(code, 0);
    assert!(err.contains("is the --calibration file"), "{err}");

    // export-glove over its own input, or of a file that is not a session: refused, and no
    // partial file is left behind.
    let (code, _, err) = icms(&["export-glove", p(&session), "--out", p(&session)]);
    assert_ne!(code, 0);
    assert!(err.contains("is the session file"), "{err}");
    let bad = dir.path().join("bad.csv");
    let (code, _, err) = icms(&["export-glove", p(&csv), "--out", p(&bad)]);
    assert_ne!(code, 0);
    assert!(err.contains("s.csv") && err.contains("MCAP"), "{err}");
    assert!(!bad.exists());
    assert!(!dir.path().join("bad.csv.part").exists());

    for (cmd, words) in [
        (
            "import-glove",
            &[
                "--hand",
                "--calibration",
                "--wrist-topic",
                "wrist_qw",
                "tau_<DOF>",
            ][..],
        ),
        ("export-glove", &["--out", "wrist_x"][..]),
    ] {
        let (code, help, _) = icms(&[cmd, "--help"]);
        assert_eq!(code, 0);
        for w in words {
            assert!(help.contains(w), "{cmd} --help lacks {w}: {help}");
        }
    }
}

/// The grasp type of each skill in `icms segment --json` of `path`.
fn skill_types(path: &Path) -> Vec<String> {
    let (code, out, err) = icms(&["segment", p(path), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    v["skills"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let t = &s["grasp_type"];
            format!(
                "{}-{}vf",
                t["label"].as_str().unwrap(),
                t["opposing_virtual_fingers"]
            )
        })
        .collect()
}

#[test]
fn a_power_grasp_exported_says_to_import_it_with_the_whole_hand_and_that_gives_its_skill() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("power.mcap");
    simulate_in(dir.path(), "cylinder-power-grasp", &[], p(&session));
    let types = skill_types(&session);
    assert!(
        types.iter().any(|t| t.starts_with("power")),
        "the simulated wrap is a power grasp: {types:?}"
    );
    let csv = dir.path().join("power.csv");
    let (code, text, err) = icms(&["export-glove", p(&session), "--out", p(&csv)]);
    assert_eq!(code, 0, "{err}");
    let hint = text
        .lines()
        .find_map(|l| l.strip_prefix("import it with: icms "))
        .unwrap_or_else(|| panic!("no import hint: {text}"));
    assert!(hint.ends_with(" --whole-hand"), "{hint}");
    // The hint as a user would paste it: the object between its quotes, the rest words.
    let (before, rest) = hint.split_once(" '").unwrap();
    let (object, after) = rest.split_once('\'').unwrap();
    let again = dir.path().join("again.mcap");
    let mut args: Vec<&str> = before.split_whitespace().collect();
    args.push(object);
    args.extend(after.split_whitespace());
    args.extend(["--out", p(&again)]);
    let (code, _, err) = icms(&args);
    assert_eq!(code, 0, "{args:?}: {err}");
    assert_eq!(skill_types(&again), types);
}

#[test]
fn simulate_rejects_bad_scenario_files_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let base = serde_json::json!({
        "name": "custom",
        "object": { "shape": "sphere", "radius": 0.04, "mass": 0.5, "mu": 0.8 },
        "tasks": [ { "phase": "approach", "duration": 0.2 } ],
    });
    type Edit = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "negative mass",
            Box::new(|v| v["object"]["mass"] = (-1.0).into()),
            "object.mass",
        ),
        (
            "negative mu",
            Box::new(|v| v["object"]["mu"] = (-0.1).into()),
            "object.mu",
        ),
        (
            "unknown shape",
            Box::new(|v| v["object"]["shape"] = "torus".into()),
            "object.shape",
        ),
        (
            "unknown phase",
            Box::new(|v| v["tasks"][0]["phase"] = "juggle".into()),
            "tasks[0].phase",
        ),
        (
            "missing mass",
            Box::new(|v| {
                v["object"].as_object_mut().unwrap().remove("mass");
            }),
            "mass",
        ),
        (
            "unknown field",
            Box::new(|v| v["object"]["colour"] = "red".into()),
            "colour",
        ),
        (
            "zero duration",
            Box::new(|v| v["tasks"][0]["duration"] = 0.0.into()),
            "tasks[0].duration",
        ),
        (
            "a lift height on another phase",
            Box::new(|v| v["tasks"][0]["height"] = 0.3.into()),
            "tasks[0].height",
        ),
    ];
    for (what, edit, field) in cases {
        let mut v = base.clone();
        edit(&mut v);
        let file = dir.path().join("scenario.json");
        std::fs::write(&file, v.to_string()).unwrap();
        let out = dir.path().join("never.mcap");
        let (code, _, err) = icms(&["simulate", "--scenario", p(&file), "--out", p(&out)]);
        assert_ne!(code, 0, "{what} accepted");
        assert!(err.contains(field), "{what}: {err}");
        assert!(!out.exists(), "{what}: no file is written");
    }
    // Content after the scenario, and --out the scenario file itself.
    let file = dir.path().join("trailing.json");
    std::fs::write(&file, format!("{base} {{\"x\": 1}}")).unwrap();
    let out = dir.path().join("never.mcap");
    let (code, _, err) = icms(&["simulate", "--scenario", p(&file), "--out", p(&out)]);
    assert_ne!(code, 0);
    assert!(err.contains("trailing characters"), "{err}");
    let file = dir.path().join("self.json");
    std::fs::write(&file, base.to_string()).unwrap();
    let (code, _, err) = icms(&["simulate", "--scenario", p(&file), "--out", p(&file)]);
    assert_ne!(code, 0);
    assert!(err.contains("is the --scenario file"), "{err}");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), base.to_string());
    // The unedited file is fine.
    let file = dir.path().join("ok.json");
    std::fs::write(&file, base.to_string()).unwrap();
    let out = dir.path().join("ok.mcap");
    let (code, _, err) = icms(&["simulate", "--scenario", p(&file), "--out", p(&out)]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(read_session(&out).unwrap().ticks(), 200);
}

/// `--variant`: the built-in scenario's variant for the seed, recorded with its scenario
/// (reaches varied, objects perturbed, in `table-three` the target drawn); only for a
/// built-in scenario's name.
#[test]
fn simulate_variant_records_the_builtin_scenarios_variant_for_the_seed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v.mcap");
    let (code, stdout, err) = icms(&[
        "simulate",
        "--scenario",
        "table-three",
        "--seed",
        "4",
        "--variant",
        "--out",
        p(&out),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let report: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(
        (&report["variant"], &report["seed"]),
        (&true.into(), &4.into())
    );
    let session = read_session(&out).unwrap();
    let recorded: dfs_core::scenario::Scenario =
        serde_json::from_str(&session.metadata["scenario_json"]).unwrap();
    assert_eq!(
        recorded,
        dfs_core::scenario::Scenario::variant("table-three", 4).unwrap()
    );
    assert!(recorded.vary_reach);
    assert_eq!(session.metadata["target"], recorded.target.unwrap());
    // Without it, the scenario itself: no `variant` in the report.
    let plain = dir.path().join("plain.mcap");
    let (code, stdout, err) = icms(&[
        "simulate",
        "--scenario",
        "box-pinch-lift",
        "--duration",
        "0.5",
        "--out",
        p(&plain),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let report: Value = serde_json::from_str(&stdout).unwrap();
    assert!(report.get("variant").is_none(), "{report}");
    // A scenario file has no variant.
    let file = dir.path().join("mine.json");
    std::fs::write(&file, "{}").unwrap();
    let never = dir.path().join("never.mcap");
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        p(&file),
        "--variant",
        "--out",
        p(&never),
    ]);
    assert_ne!(code, 0);
    assert!(
        err.contains("--variant takes a built-in scenario's name"),
        "{err}"
    );
    assert!(!never.exists());
}

#[test]
fn simulate_refuses_a_duration_shorter_than_the_shortest_phase() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("short.mcap");
    for d in ["0.001", "0.049", "0", "-1", "3601"] {
        let (code, _, err) = icms(&[
            "simulate",
            "--scenario",
            "sphere-lift",
            "--duration",
            d,
            "--out",
            p(&out),
        ]);
        assert_ne!(code, 0, "--duration {d}");
        assert!(
            err.contains("duration") && err.contains("0.05 to 3600 s"),
            "{d}: {err}"
        );
        assert!(!out.exists(), "--duration {d} left a file");
    }
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        "sphere-lift",
        "--duration",
        "0.05",
        "--out",
        p(&out),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(read_session(&out).unwrap().ticks(), 50);
}

#[test]
fn simulate_names_the_unknown_scenario() {
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        "juggling",
        "--out",
        "/nonexistent/x.mcap",
    ]);
    assert_ne!(code, 0);
    assert!(
        err.contains("juggling") && err.contains("sphere-lift"),
        "{err}"
    );
}
