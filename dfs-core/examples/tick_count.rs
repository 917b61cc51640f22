//! The frozen-sample tick for instruction counts (BENCHMARKS.md, "The tick's instructions given
//! back"): `N` ticks of glove10 holding the paper's sphere on four fingertips, the object reset
//! every tick, as `icms bench tick --scene frozen` and the criterion bench run it. Under
//! valgrind, the instructions of `Dfs::step` alone:
//!
//! ```text
//! cargo build --release -p dfs-core --example tick_count
//! valgrind --tool=callgrind --toggle-collect='dfs_core::dfs::Dfs::step' \
//!     target/release/examples/tick_count 22000
//! ```
//!
//! Run it for two `N` and divide the difference of the counts by the difference of the `N`s: the
//! instructions of one settled tick. `tick_count power-grasp N` runs glove10's power grasp of a
//! cylinder instead (whole-hand contact, the glove closing on it in the loop).
#![allow(missing_docs)]

use dfs_core::fixtures::{glove10_holding_paper_sphere, FrozenSample};
use std::hint::black_box;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (scene, ticks) = match (args.next(), args.next()) {
        (Some(scene), Some(n)) => (scene, n.parse()?),
        (Some(n), None) => ("frozen".to_string(), n.parse()?),
        _ => ("frozen".to_string(), 22_000),
    };
    match scene.as_str() {
        "frozen" => frozen(ticks),
        "power-grasp" => power_grasp(ticks),
        other => Err(format!("unknown scene {other}: frozen or power-grasp").into()),
    }
}

/// The frozen sample (module documentation).
fn frozen(ticks: usize) -> Result<(), Box<dyn std::error::Error>> {
    let held = glove10_holding_paper_sphere()?;
    let frozen = FrozenSample::of(&held);
    let mut dfs = held.dfs;
    let mut contacts = 0;
    for _ in 0..ticks {
        contacts += black_box(frozen.tick(&mut dfs)?).n_contacts;
    }
    println!("{ticks} ticks, {contacts} contacts in all");
    Ok(())
}

/// glove10's power grasp of a cylinder with whole-hand contact
/// (`dfs_core::fixtures::glove10_power_grasp`), its glove closing on it in the loop with a
/// swinging grip, as `tick_allocates_nothing` runs it.
fn power_grasp(ticks: usize) -> Result<(), Box<dyn std::error::Error>> {
    let g = dfs_core::fixtures::glove10_power_grasp()?;
    let mut dfs = g.dfs.clone();
    let mut glove = g.glove();
    let mut contacts = 0;
    for t in 0..ticks {
        let grip = 1.0 + 0.2 * (t as f64 * 0.003).sin();
        g.tick(&mut dfs, &mut glove, grip)?;
        contacts += dfs.output().n_contacts;
    }
    println!("{ticks} ticks, {contacts} contacts in all");
    Ok(())
}
