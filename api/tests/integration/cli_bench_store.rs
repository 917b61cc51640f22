//! `icms bench store`: the store benchmark runs on a fresh data directory, reports every
//! figure, leaves nothing behind unless asked to keep it, and refuses sizes outside its range.
//! No test asserts a time.

use crate::common;
use common::icms;

use serde_json::Value;

#[test]
fn the_store_benchmark_reports_every_figure_and_cleans_up() {
    let parent = tempfile::tempdir().unwrap();
    let dir = parent.path().to_str().unwrap();
    let (c, out, e) = icms(&["bench", "store", "--skills", "2000", "--dir", dir, "--json"]);
    assert_eq!(c, 0, "{e}");
    let r: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"));
    assert_eq!(r["skills"], 2000, "{r}");
    let ingest = r["ingest"].as_array().unwrap();
    assert_eq!(ingest.len(), 2, "{r}");
    for i in ingest {
        assert!(i["sessions_per_second"].as_f64().unwrap() > 0.0, "{r}");
    }
    assert_eq!(ingest[1]["blob_bytes"], 2 * 1024 * 1024, "{r}");
    for t in ["filtered_query", "nearest"] {
        let t = &r[t];
        assert!(t["n"].as_u64().unwrap() >= 200, "{r}");
        let (p50, p99, max) = (
            t["p50_ms"].as_f64().unwrap(),
            t["p99_ms"].as_f64().unwrap(),
            t["max_ms"].as_f64().unwrap(),
        );
        assert!(0.0 < p50 && p50 <= p99 && p99 <= max, "{r}");
    }
    assert!(r["reopen_seconds"].as_f64().unwrap() > 0.0, "{r}");
    assert_eq!(
        std::fs::read_dir(parent.path()).unwrap().count(),
        0,
        "the data directory was removed"
    );
}

#[test]
fn a_store_size_outside_the_range_is_refused_naming_it() {
    let (c, out, e) = icms(&["bench", "store", "--skills", "10"]);
    assert_ne!(c, 0, "{out}");
    assert!(e.contains("--skills"), "{e}");
}
