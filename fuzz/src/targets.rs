//! The fuzz targets: one per parser that takes user bytes. Each makes its seeds, generates
//! input `index` deterministically from them, and runs one input through the parser (and the
//! code right behind it that sees the parsed value). A panic is caught by the driver; a
//! target returns `Err` for a finding that is not a panic (an HTTP 5xx).

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::mcap::{self, McapFile};
use crate::rng::Rng;
use crate::seeds::{self, SeedError};
use crate::{bytes, json, xml};

/// Names of the targets.
pub const TARGETS: [&str; 6] = ["session", "urdf", "scenario", "grasp", "skill", "http"];

/// Where a target finds its files and keeps its scratch files.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The shared hands directory (URDF seeds).
    pub hands_dir: PathBuf,
    /// A scratch directory of this process.
    pub scratch: PathBuf,
}

/// One fuzz target.
pub trait Target {
    /// Input `index` of campaign `seed`: the first inputs are the seeds themselves.
    fn generate(&self, seed: u64, index: u64) -> Vec<u8>;
    /// Runs one input; `Err` is a finding other than a panic.
    fn run(&mut self, input: &[u8]) -> Result<(), String>;
    /// Number of seeds.
    fn seeds(&self) -> usize;
}

/// Builds a target by name.
pub fn build(name: &str, setup: &Setup) -> Result<Box<dyn Target>, SeedError> {
    Ok(match name {
        "session" => Box::new(SessionTarget::new(setup)?),
        "urdf" => Box::new(UrdfTarget::new(setup)?),
        "scenario" => Box::new(JsonTarget::new(
            "scenario",
            seeds::scenarios(),
            run_scenario,
        )),
        "grasp" => Box::new(JsonTarget::new("grasp", seeds::grasps(), run_grasp)),
        "skill" => {
            let full = seeds::full_session(&setup.scratch)?;
            Box::new(JsonTarget::new("skill", seeds::skills(&full)?, run_skill))
        }
        "http" => Box::new(crate::http::HttpTarget::new(setup)?),
        other => return Err(SeedError(format!("unknown target {other:?}"))),
    })
}

/// Mutation rounds for one input: mostly 1-3, sometimes up to 8.
pub fn rounds(rng: &mut Rng) -> usize {
    if rng.one_in(8) {
        rng.range(4, 8)
    } else {
        rng.range(1, 3)
    }
}

// ---------------------------------------------------------------------------------------------
// session

/// MCAP sessions: the generic reader, the session reader, ingest's analysis (read, segment)
/// and salvage.
pub struct SessionTarget {
    raw: Vec<Vec<u8>>,
    parsed: Vec<McapFile>,
    scratch: PathBuf,
}

impl SessionTarget {
    /// Records the seed sessions.
    pub fn new(setup: &Setup) -> Result<Self, SeedError> {
        let raw = seeds::sessions(&setup.scratch)?;
        let parsed = raw.iter().filter_map(|b| McapFile::parse(b)).collect();
        Ok(SessionTarget {
            raw,
            parsed,
            scratch: setup.scratch.clone(),
        })
    }
}

/// An MCAP input from seeds: MCAP-aware mutations with fixed CRCs, mostly; raw bytes too.
pub fn generate_mcap(rng: &mut Rng, raw: &[Vec<u8>], parsed: &[McapFile]) -> Vec<u8> {
    let i = rng.below(raw.len());
    let n = rounds(rng);
    if rng.one_in(6) || parsed.is_empty() {
        let mut b = raw[i].clone();
        let other = &raw[rng.below(raw.len())];
        bytes::mutate_n(rng, &mut b, other, n);
        return b;
    }
    let mut f = match McapFile::parse(&raw[i]) {
        Some(f) => f,
        None => parsed[rng.below(parsed.len())].clone(),
    };
    for _ in 0..n {
        mcap::mutate(rng, &mut f, parsed);
    }
    mcap::fix_crcs(rng, &mut f, 16);
    let mut out = f.write();
    if rng.one_in(10) {
        bytes::mutate(rng, &mut out, &[]);
    }
    out
}

impl Target for SessionTarget {
    fn generate(&self, seed: u64, index: u64) -> Vec<u8> {
        if (index as usize) < self.raw.len() {
            return self.raw[index as usize].clone();
        }
        let mut rng = Rng::for_input("session", seed, index);
        generate_mcap(&mut rng, &self.raw, &self.parsed)
    }

    fn run(&mut self, input: &[u8]) -> Result<(), String> {
        let limits = services::mcap_io::ReadLimits::default();
        let generic = services::mcap_io::read_session_bytes(input, &limits);
        if let Ok(s) = &generic {
            // The accessors a caller uses on a read session.
            let _ = s.message_counts();
            for t in s.topics.values() {
                let _ = t.json_values();
            }
        }
        let _ = services::session::read_session_bytes(input, "fuzz.mcap", &limits);
        let _ = services::ingest::analyse(input, "fuzz.mcap");
        // Salvage reads a file the writer left behind (`icms salvage`): every fourth input
        // (by length), as it goes through the file system.
        if !input.len().is_multiple_of(4) {
            return Ok(());
        }
        let inp = self.scratch.join("salvage-in.mcap");
        let out = self.scratch.join("salvage-out.mcap");
        if std::fs::write(&inp, input).is_ok() && services::mcap_io::salvage(&inp, &out).is_ok() {
            let _ = services::session::read_session(&out);
        }
        Ok(())
    }

    fn seeds(&self) -> usize {
        self.raw.len()
    }
}

// ---------------------------------------------------------------------------------------------
// urdf

/// A URDF target input: `u32` LE length of the spec JSON, the spec JSON, the URDF text.
pub fn encode_hand(spec: &[u8], urdf: &[u8]) -> Vec<u8> {
    let mut out = (spec.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(spec);
    out.extend_from_slice(urdf);
    out
}

/// The spec and URDF of an input (as text, invalid UTF-8 replaced as a JSON body would
/// refuse it anyway).
pub fn decode_hand(input: &[u8]) -> (String, String) {
    let n = input
        .get(..4)
        .map_or(0, |b| {
            u32::from_le_bytes(b.try_into().unwrap_or_default()) as usize
        })
        .min(input.len().saturating_sub(4));
    let rest = input.get(4..).unwrap_or_default();
    (
        String::from_utf8_lossy(&rest[..n]).into_owned(),
        String::from_utf8_lossy(&rest[n..]).into_owned(),
    )
}

/// A mutated hand: the spec (JSON-aware), the URDF (URDF-aware), or both.
pub fn mutate_hand(rng: &mut Rng, hands: &[seeds::HandSeed], specs: &[Value]) -> (Vec<u8>, String) {
    let h = rng.pick(hands);
    let urdfs: Vec<&str> = hands.iter().map(|h| h.urdf.as_str()).collect();
    let mut spec = serde_json::to_vec(&h.spec).unwrap_or_default();
    let mut urdf = h.urdf.clone();
    let which = rng.below(3);
    let n = rounds(rng);
    if which != 1 {
        spec = json::mutate_value_text(rng, &h.spec, specs, n);
    }
    if which != 0 {
        for _ in 0..n {
            xml::mutate(rng, &mut urdf, &urdfs);
        }
    }
    (spec, urdf)
}

/// Robot hands: `services::replay::load_hand_from_texts` (spec JSON + URDF, the loader the
/// upload endpoint and `icms hands SPEC.json` use).
pub struct UrdfTarget {
    hands: Vec<seeds::HandSeed>,
    specs: Vec<Value>,
}

impl UrdfTarget {
    /// Reads the hands.
    pub fn new(setup: &Setup) -> Result<Self, SeedError> {
        let hands = seeds::hands(&setup.hands_dir)?;
        let specs = hands.iter().map(|h| h.spec.clone()).collect();
        Ok(UrdfTarget { hands, specs })
    }
}

impl Target for UrdfTarget {
    fn generate(&self, seed: u64, index: u64) -> Vec<u8> {
        if let Some(h) = self.hands.get(index as usize) {
            return encode_hand(
                &serde_json::to_vec(&h.spec).unwrap_or_default(),
                h.urdf.as_bytes(),
            );
        }
        let mut rng = Rng::for_input("urdf", seed, index);
        let (spec, urdf) = mutate_hand(&mut rng, &self.hands, &self.specs);
        encode_hand(&spec, urdf.as_bytes())
    }

    fn run(&mut self, input: &[u8]) -> Result<(), String> {
        let (spec, urdf) = decode_hand(input);
        if let Ok(hand) = services::replay::load_hand_from_texts(&spec, &urdf, "fuzz") {
            // What `icms hands` and the hand endpoints show of a loaded hand.
            let m = &hand.model;
            let _ = (m.dof(), m.fingertips.len(), hand.thumb);
        }
        Ok(())
    }

    fn seeds(&self) -> usize {
        self.hands.len()
    }
}

// ---------------------------------------------------------------------------------------------
// JSON targets: scenario, grasp, skill

/// A target whose input is one JSON document.
pub struct JsonTarget {
    name: &'static str,
    seeds: Vec<Value>,
    run: fn(&[u8]) -> Result<(), String>,
}

impl JsonTarget {
    /// A JSON target over `seeds`.
    pub fn new(
        name: &'static str,
        seeds: Vec<Value>,
        run: fn(&[u8]) -> Result<(), String>,
    ) -> Self {
        JsonTarget { name, seeds, run }
    }
}

impl Target for JsonTarget {
    fn generate(&self, seed: u64, index: u64) -> Vec<u8> {
        if let Some(s) = self.seeds.get(index as usize) {
            return serde_json::to_vec_pretty(s).unwrap_or_default();
        }
        let mut rng = Rng::for_input(self.name, seed, index);
        let s = rng.pick(&self.seeds).clone();
        let n = rounds(&mut rng);
        json::mutate_value_text(&mut rng, &s, &self.seeds, n)
    }

    fn run(&mut self, input: &[u8]) -> Result<(), String> {
        (self.run)(input)
    }

    fn seeds(&self) -> usize {
        self.seeds.len()
    }
}

/// Scenario files (`icms simulate --scenario FILE`, and the scenario object of `POST
/// /api/v1/simulations`): parsed as the CLI does, resolved, and the simulation set up with
/// glove10 (not stepped), with and without a duration.
fn run_scenario(input: &[u8]) -> Result<(), String> {
    let text = String::from_utf8_lossy(input);
    let Ok(s) = api::cli::parse_json::<dfs_core::scenario::Scenario>(&text) else {
        // The HTTP endpoint parses into a Value first, then the scenario from it.
        if let Ok(v) = serde_json::from_slice::<Value>(input) {
            let _ = serde_path_to_value::<dfs_core::scenario::Scenario>(v);
        }
        return Ok(());
    };
    if s.resolve().is_ok() {
        let _ = s.duration();
        // Setting up searches for a reachable grasp (IK): once per input, with or without a
        // duration by the input's length.
        let hand = dfs_core::hand::HandModel::glove10();
        let duration = input.len().is_multiple_of(2).then_some(0.5);
        let _ = dfs_core::operator::Simulation::new(&s, hand, duration);
    }
    Ok(())
}

fn serde_path_to_value<T: serde::de::DeserializeOwned>(v: Value) -> Option<T> {
    serde_json::from_value(v).ok()
}

/// Grasp files (`icms dfs-static --grasp FILE`): parsed as the CLI does, then analysed.
fn run_grasp(input: &[u8]) -> Result<(), String> {
    let text = String::from_utf8_lossy(input);
    if let Ok(g) = api::cli::parse_json::<dfs_core::spec::GraspSpec>(&text) {
        let _ = dfs_core::statics::analyse(&g, 1.0);
        let _ = dfs_core::statics::analyse(&g, 2.5);
    }
    Ok(())
}

/// Skill JSON (`icms replay --skill FILE`): `services::replay::skill_spec_from_json`, then
/// the replay's timeline and key poses (no planning: that is the replay's long work).
fn run_skill(input: &[u8]) -> Result<(), String> {
    let Ok(v) = serde_json::from_slice::<Value>(input) else {
        return Ok(());
    };
    if let Ok(spec) = services::replay::skill_spec_from_json(&v, "fuzz") {
        let tl = spec.timeline();
        let _ = spec.start_pose();
        for k in 0..=8 {
            let _ = spec.key_pose(k as f64 / 8.0);
            let _ = spec.reference_in(&tl, tl.end * k as f64 / 8.0);
        }
    }
    Ok(())
}

/// The default scratch directory's parent: `/dev/shm` when there is one (the HTTP target's
/// SQLite store and salvage files are rewritten constantly), else the system temp dir.
pub fn scratch_parent() -> PathBuf {
    let shm = Path::new("/dev/shm");
    if shm.is_dir() {
        shm.to_path_buf()
    } else {
        std::env::temp_dir()
    }
}
