//! Criterion benchmark: one DFS tick for glove10 holding the paper's sphere on 4 contacts.
#![allow(missing_docs)] // criterion_group! generates undocumented functions

use criterion::{criterion_group, criterion_main, Criterion};
use dfs_core::dfs::GloveSample;
use dfs_core::fixtures::{glove10_holding_paper_sphere, HeldSphere};
use std::hint::black_box;

fn tick(c: &mut Criterion) {
    let HeldSphere {
        mut dfs,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().expect("fixture");
    let start = *dfs.object_state();
    c.bench_function("dfs_tick_glove10_paper_sphere_4_contacts", |b| {
        b.iter(|| {
            dfs.set_object_state(start);
            let out = dfs
                .step(black_box(&GloveSample {
                    q: &q,
                    tau: &tau,
                    base,
                }))
                .expect("tick");
            black_box(out.n_contacts)
        })
    });
}

criterion_group!(benches, tick);
criterion_main!(benches);
