//! A full disk during `icms ingest`: an error naming the problem, no partial rows, no stray
//! files, and the data base still works afterwards. The disk is "filled" with the file-size
//! resource limit (`ulimit -f`, SIGXFSZ ignored), which makes writes past the limit fail the
//! way writes on a full disk do, without needing a small file system.

use crate::common;
use common::{icms_in as icms, simulate_in};

use std::path::Path;
use std::process::Command;

use serde_json::Value;

/// Runs `icms ARGS` in `dir` with writes limited to `limit_kib` KiB per file.
fn icms_with_file_limit(dir: &Path, limit_kib: u64, args: &[&str]) -> (i32, String) {
    // dash and bash both count `ulimit -f` in 512-byte or 1024-byte blocks; `-f` with the
    // value in 512-byte blocks is the smaller (stricter) reading for both.
    let script = format!(
        "trap '' XFSZ; ulimit -f {}; exec \"$0\" \"$@\"",
        limit_kib * 2
    );
    let out = Command::new("sh")
        .current_dir(dir)
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_icms"))
        .args(args)
        .output()
        .expect("run sh");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn files_under(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

fn create_data_base(data: &Path) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let store = services::store::Store::open(data).await.unwrap();
        store.close().await;
    });
}

fn skill_count(dir: &Path) -> usize {
    let (c, out, e) = icms(dir, &["skills", "--json"]);
    assert_eq!(c, 0, "{e}");
    let v: Value = serde_json::from_str(&out).unwrap();
    v["items"].as_array().unwrap().len()
}

#[test]
fn a_full_disk_during_ingest_is_an_error_and_leaves_no_partial_rows_or_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "box-pinch-lift", &["--seed", "2"], "s.mcap");
    let size_kib = std::fs::metadata(d.join("s.mcap")).unwrap().len() / 1024;
    assert!(
        size_kib > 256,
        "the session must be larger than the limit ({size_kib} KiB)"
    );
    // The data base exists and is migrated before the disk fills up (as after `icms serve` or
    // an earlier ingest; `icms skills` only reads and would refuse a missing one).
    create_data_base(&d.join("icms-data"));
    assert_eq!(skill_count(d), 0);
    let before = files_under(&d.join("icms-data"));

    let (c, stderr) = icms_with_file_limit(d, 128, &["ingest", "s.mcap"]);
    assert_ne!(c, 0, "ingest on a full disk must fail");
    assert!(
        stderr.contains("File too large") || stderr.to_lowercase().contains("full"),
        "the error says why: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    // No partial rows, no blob, no temporary file left behind.
    assert_eq!(skill_count(d), 0);
    let after: Vec<String> = files_under(&d.join("icms-data"))
        .into_iter()
        .filter(|f| !f.ends_with("-shm") && !f.ends_with("-wal"))
        .collect();
    let before: Vec<String> = before
        .into_iter()
        .filter(|f| !f.ends_with("-shm") && !f.ends_with("-wal"))
        .collect();
    assert_eq!(after, before, "files changed by a failed ingest");

    // With space again the same file ingests normally.
    let (c, out, e) = icms(d, &["ingest", "s.mcap", "--json"]);
    assert_eq!(c, 0, "{e}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["sessions"][0]["created"], Value::Bool(true));
    assert_eq!(skill_count(d), 1);
}
