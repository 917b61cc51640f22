//! Store speed figures (ignored by default; run in release):
//! `cargo test --release -p services --test store_bench -- --ignored --nocapture`.
//! `ICMS_BENCH_SKILLS` sets the number of synthetic skills (default 100 000), `ICMS_BENCH_DIR`
//! where the temporary data directory goes, and `ICMS_BENCH_KEEP=1` keeps it.

mod store_common;

use std::time::Instant;

use services::store::bench::{generate_synthetic, time_filtered_queries, time_nearest};
use services::store::Store;
use store_common::{fake_mcap, meta, skills};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "benchmark: run in release with --ignored --nocapture"]
async fn measure_ingest_query_and_nearest_speeds() {
    let tmp = tempfile::tempdir_in(std::env::var("ICMS_BENCH_DIR").unwrap_or_else(|_| ".".into()))
        .unwrap();
    let store = Store::open(tmp.path()).await.unwrap();
    for (label, size) in [("200 KiB", 200 * 1024), ("2 MiB", 2 * 1024 * 1024)] {
        let files: Vec<Vec<u8>> = (0..50u64)
            .map(|i| fake_mcap(i * 1000 + size as u64, size))
            .collect();
        let t = Instant::now();
        for (i, f) in files.iter().enumerate() {
            store
                .ingest(f, meta(i as u64, 2), skills(i as u64, 2))
                .await
                .unwrap();
        }
        let s = t.elapsed().as_secs_f64();
        println!(
            "ingest: 50 sessions of {label} with 2 skills each in {:.3} s = {:.0} sessions/s",
            s,
            50.0 / s
        );
    }

    let n: usize = std::env::var("ICMS_BENCH_SKILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100_000);
    let report = generate_synthetic(&store, n, 1).await.unwrap();
    println!(
        "generate: {} skills in {} sessions in {:.1} s ({:.0} skills/s)",
        report.skills,
        report.sessions,
        report.elapsed_s,
        report.skills as f64 / report.elapsed_s
    );
    let q = time_filtered_queries(&store, 1000, 2).await.unwrap();
    println!(
        "filtered query over {n} skills: p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
        q.p50_ms, q.p99_ms, q.max_ms
    );
    let k = time_nearest(&store, 200, 10, 3).unwrap();
    println!(
        "nearest k=10 over {n} skills: p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
        k.p50_ms, k.p99_ms, k.max_ms
    );
    let t = Instant::now();
    drop(store);
    let store = Store::open(tmp.path()).await.unwrap();
    println!(
        "reopen with index load: {:.3} s, {} skills",
        t.elapsed().as_secs_f64(),
        store.skill_count()
    );
    if std::env::var_os("ICMS_BENCH_KEEP").is_some() {
        println!("kept {:?}", tmp.keep());
    }
}
