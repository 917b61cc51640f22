//! Benchmark helpers for `icms bench store`: synthetic blobs and skills, and latency
//! measurements of filtered queries and k-nearest search.

use std::time::{Duration, Instant};

use dfs_core::contact::ContactModel;
use dfs_core::object::ShapeKind;
use dfs_core::scenario::Phase;
use serde::{Deserialize, Serialize};

use super::{
    NewSkill, ObjectShape, SessionMeta, SkillQuery, SortField, SortKey, SortOrder, Store,
    StoreError, FEATURE_DIM,
};

/// Skills per synthetic session.
pub const SYNTHETIC_SKILLS_PER_SESSION: usize = 1000;
/// Synthetic sessions stored per transaction.
pub const SYNTHETIC_SESSIONS_PER_TRANSACTION: usize = 10;

/// Object shapes the generator draws from.
pub const SYNTHETIC_SHAPES: [ShapeKind; 3] =
    [ShapeKind::Sphere, ShapeKind::Box, ShapeKind::Cylinder];
/// Contact models the generator draws from.
pub const SYNTHETIC_CONTACT_MODELS: [ContactModel; 3] = [
    ContactModel::Frictionless,
    ContactModel::PointWithFriction,
    ContactModel::SoftFinger,
];
/// Grasp types the generator draws from.
pub const SYNTHETIC_GRASP_TYPES: [&str; 4] =
    ["precision-2vf", "precision-3vf", "power-2vf", "power-3vf"];
/// Phases every synthetic skill has.
pub const SYNTHETIC_PHASES: [Phase; 5] = [
    Phase::Grasp,
    Phase::Lift,
    Phase::Hold,
    Phase::Place,
    Phase::Release,
];

/// A small deterministic generator (SplitMix64), enough for synthetic data.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Uniform index in 0..n.
    pub fn index(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// One synthetic skill with plausible ranges (mass 0.05-2 kg, μ 0.3-1.5, ε 0-0.5, ...).
pub fn synthetic_skill(rng: &mut SplitMix64) -> NewSkill {
    let phase_durations: Vec<(Phase, f64)> = SYNTHETIC_PHASES
        .iter()
        .map(|p| (*p, rng.range(0.1, 2.0)))
        .collect();
    let duration_s = phase_durations.iter().map(|p| p.1).sum::<f64>();
    let start_ns = (rng.range(0.0, 5.0) * 1e9) as i64;
    NewSkill {
        object_shape: SYNTHETIC_SHAPES[rng.index(3)].into(),
        object_name: None,
        object_mass: rng.range(0.05, 2.0),
        mu: rng.range(0.3, 1.5),
        contact_count: 2 + rng.index(4) as i64,
        contact_model: SYNTHETIC_CONTACT_MODELS[rng.index(3)],
        grasp_type: SYNTHETIC_GRASP_TYPES[rng.index(4)].into(),
        quality: rng.range(0.0, 0.5),
        volume: rng.range(0.0, 0.01),
        duration_s,
        start_ns,
        end_ns: start_ns + (duration_s * 1e9) as i64,
        phase_durations,
        feature: (0..FEATURE_DIM)
            .map(|_| rng.range(-1.0, 1.0) as f32)
            .collect(),
        params: serde_json::json!({ "synthetic": true }),
        approach: None,
        matched_skill_id: None,
    }
}

/// Deterministic bytes standing for session file number `i`, `len` bytes long (at least 16;
/// distinct for distinct `i`): what store benchmarks and tests ingest when the file's content
/// does not matter (the store does not read a blob).
pub fn synthetic_blob(i: u64, len: usize) -> Vec<u8> {
    let mut rng = SplitMix64::new(i.wrapping_mul(0x1234_5678_9ABC_DEF1) ^ 0xC0FFEE);
    let mut out = format!("fake mcap {i}\n").into_bytes();
    while out.len() < len {
        out.extend_from_slice(&rng.next_u64().to_le_bytes());
    }
    out.truncate(len.max(16));
    out
}

/// What [`generate_synthetic`] did.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GenerateReport {
    /// Sessions created.
    pub sessions: usize,
    /// Skills created.
    pub skills: usize,
    /// Wall time, s.
    pub elapsed_s: f64,
}

/// Inserts `n_skills` synthetic skills, [`SYNTHETIC_SKILLS_PER_SESSION`] per synthetic session
/// (a tiny fake blob each), [`SYNTHETIC_SESSIONS_PER_TRANSACTION`] sessions per transaction on
/// a connection with a large page cache, drawn from `seed`; then refreshes the planner
/// statistics. Deterministic for a seed; a second call with the same seed stores nothing new.
pub async fn generate_synthetic(
    store: &Store,
    n_skills: usize,
    seed: u64,
) -> Result<GenerateReport, StoreError> {
    let started = Instant::now();
    let mut rng = SplitMix64::new(seed);
    let mut done = 0;
    let mut sessions = 0;
    while done < n_skills {
        let mut batch = Vec::new();
        while done < n_skills && batch.len() < SYNTHETIC_SESSIONS_PER_TRANSACTION {
            let n = SYNTHETIC_SKILLS_PER_SESSION.min(n_skills - done);
            let skills: Vec<NewSkill> = (0..n).map(|_| synthetic_skill(&mut rng)).collect();
            let blob = format!("ICMS synthetic session seed={seed} index={sessions}\n");
            let meta = SessionMeta {
                scenario: Some("synthetic".into()),
                seed: Some(seed),
                hand: "glove10".into(),
                object_shape: skills[0].object_shape,
                object_mass: skills[0].object_mass,
                mu: skills[0].mu,
                duration_ns: 0,
                started_at: None,
                extra: serde_json::Value::Null,
            };
            batch.push((blob.into_bytes(), meta, skills));
            done += n;
            sessions += 1;
        }
        store.bulk_ingest(batch).await?;
    }
    store.optimize().await?;
    Ok(GenerateReport {
        sessions,
        skills: done,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// Latency distribution of repeated calls.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Timing {
    /// Number of calls measured.
    pub n: usize,
    /// Median, ms.
    pub p50_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Slowest, ms.
    pub max_ms: f64,
}

impl Timing {
    /// Percentiles of `samples` (any order; empty gives zeros).
    pub fn from_samples(mut samples: Vec<Duration>) -> Timing {
        samples.sort_unstable();
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let pick = |q: f64| {
            if samples.is_empty() {
                0.0
            } else {
                ms(samples[((samples.len() - 1) as f64 * q).round() as usize])
            }
        };
        Timing {
            n: samples.len(),
            p50_ms: pick(0.5),
            p99_ms: pick(0.99),
            max_ms: pick(1.0),
        }
    }
}

/// A random filtered query like a user's: shape, a 0.2 kg mass window, a minimum quality,
/// best quality first, 50 per page.
pub fn random_filtered_query(rng: &mut SplitMix64) -> SkillQuery {
    let mass_min = rng.range(0.05, 1.8);
    SkillQuery {
        object_shape: Some(ObjectShape::Known(SYNTHETIC_SHAPES[rng.index(3)])),
        mass_min: Some(mass_min),
        mass_max: Some(mass_min + 0.2),
        min_quality: Some(rng.range(0.0, 0.3)),
        sort: SortKey::new(SortField::Quality, SortOrder::Desc),
        limit: 50,
        ..SkillQuery::default()
    }
}

/// Times `iterations` random filtered queries ([`random_filtered_query`]) after 10 warm-ups.
pub async fn time_filtered_queries(
    store: &Store,
    iterations: usize,
    seed: u64,
) -> Result<Timing, StoreError> {
    let mut rng = SplitMix64::new(seed);
    for _ in 0..10 {
        store.query_skills(&random_filtered_query(&mut rng)).await?;
    }
    let mut samples = Vec::with_capacity(iterations);
    for _ in 0..iterations {
        let q = random_filtered_query(&mut rng);
        let t = Instant::now();
        store.query_skills(&q).await?;
        samples.push(t.elapsed());
    }
    Ok(Timing::from_samples(samples))
}

/// Times `iterations` k-nearest searches for random feature vectors.
pub fn time_nearest(
    store: &Store,
    iterations: usize,
    k: usize,
    seed: u64,
) -> Result<Timing, StoreError> {
    let mut rng = SplitMix64::new(seed);
    let mut samples = Vec::with_capacity(iterations);
    for _ in 0..iterations {
        let f: Vec<f32> = (0..FEATURE_DIM)
            .map(|_| rng.range(-1.0, 1.0) as f32)
            .collect();
        let t = Instant::now();
        store.nearest(&f, k)?;
        samples.push(t.elapsed());
    }
    Ok(Timing::from_samples(samples))
}
