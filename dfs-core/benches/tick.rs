//! Criterion benchmark: one DFS tick for glove10 holding the paper's sphere on 4 contacts.
#![allow(missing_docs)] // criterion_group! generates undocumented functions

use criterion::{criterion_group, criterion_main, Criterion};
use dfs_core::fixtures::{glove10_holding_paper_sphere, FrozenSample};
use std::hint::black_box;

fn tick(c: &mut Criterion) {
    let held = glove10_holding_paper_sphere().expect("fixture");
    let frozen = FrozenSample::of(&held);
    let mut dfs = held.dfs;
    c.bench_function("dfs_tick_glove10_paper_sphere_4_contacts", |b| {
        b.iter(|| black_box(frozen.tick(&mut dfs).expect("tick").n_contacts))
    });
}

criterion_group!(benches, tick);
criterion_main!(benches);
