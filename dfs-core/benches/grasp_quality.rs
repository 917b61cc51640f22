//! Criterion benchmark: GraspIt!-style grasp quality (ε and the volume of the grasp wrench
//! space) of the paper's sphere grasp, the replay planner's typical input.
#![allow(missing_docs)] // criterion_group! generates undocumented functions

use criterion::{criterion_group, criterion_main, Criterion};
use dfs_core::contact::{ContactModel, Friction};
use dfs_core::fixtures::paper_sphere_contacts;
use dfs_core::grasp::quality::{grasp_quality, QualityParams};
use std::hint::black_box;

fn quality(c: &mut Criterion) {
    let contacts = paper_sphere_contacts();
    let friction = Friction {
        mu: 1.5,
        mu_torsion: 0.005,
    };
    let params = QualityParams::default();
    // 4 soft fingers × (8 + 2 × 5 + 2) points of the elliptic cone = 80 primitive wrenches.
    c.bench_function("grasp_quality_paper_sphere_soft_finger_80", |b| {
        b.iter(|| {
            grasp_quality(
                black_box(&contacts),
                ContactModel::SoftFinger,
                &friction,
                &params,
            )
            .expect("quality")
        })
    });
    // 4 point contacts × 8 cone edges = 32.
    c.bench_function("grasp_quality_paper_sphere_point_32", |b| {
        b.iter(|| {
            grasp_quality(
                black_box(&contacts),
                ContactModel::PointWithFriction,
                &friction,
                &params,
            )
            .expect("quality")
        })
    });
}

criterion_group!(benches, quality);
criterion_main!(benches);
