//! Tests of the recorder: a recording into any writer, ticks refused and left out, raw
//! messages as prost writes them.

use std::path::{Path, PathBuf};

use dfs_core::hand::HandModel;
use dfs_core::operator::Simulation;
use dfs_core::scenario::{Scenario, Scene};

use super::foxglove_topics::SceneObjects;
use super::inputs::{Batch, HandFrames, Tick};
use super::raw::Messages;
use crate::error::{RecordingError, Result};
use crate::session::proto::GloveJointStatesProto;
use crate::session::*;

use super::*;

#[test]
fn a_recording_into_any_writer_is_the_file_byte_for_byte() {
    /// A writer that cannot seek, whose bytes the test keeps.
    struct Shared(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);
    impl std::io::Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let scenario = Scenario::builtin("sphere-lift", 3).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let file = record_simulation(&scenario, Some(2.5), path.as_path(), |_, _| {}).unwrap();
    let bytes = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let out = SessionOut::Stream {
        out: Box::new(Shared(bytes.clone())),
        name: "memory".into(),
    };
    let streamed = record_simulation(&scenario, Some(2.5), out, |_, _| {}).unwrap();
    let bytes = bytes.lock().unwrap().clone();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert_eq!(
        (file.file_bytes, streamed.file_bytes),
        (bytes.len() as u64, bytes.len() as u64)
    );
    assert_eq!(streamed.write.path, PathBuf::from("memory"));
    assert_eq!(streamed.ticks, 2500);
}

/// What [`record_with`] recorded: per tick its `record` result, time and q.
struct Recorded {
    results: Vec<Result<()>>,
    times: Vec<u64>,
    q: Vec<Vec<f64>>,
    finished: Result<RecordSummary>,
}

/// Records `seconds` of `sphere-lift` into `path`, with `edit(tick position, τ)` applied to
/// each tick's τ (0 for the first tick).
fn record_with(path: &Path, seconds: f64, edit: impl Fn(usize, &mut [f64])) -> Recorded {
    let scenario = Scenario::builtin("sphere-lift", 3).unwrap();
    let mut sim = Simulation::new(&scenario, HandModel::glove10(), Some(seconds)).unwrap();
    let dfs = sim.dfs();
    let mut rec =
        SessionRecorder::create(path, dfs.hand(), dfs.object(), &SessionInfo::default()).unwrap();
    let (mut results, mut times, mut qs) = (Vec::new(), Vec::new(), Vec::new());
    while sim.step().unwrap() {
        let (q, tau, base) = sim.sample();
        let mut tau = tau.to_vec();
        edit(results.len(), &mut tau);
        let tick = TickData {
            time_ns: sim.time_ns(),
            q,
            tau: &tau,
            base,
            output: sim.output(),
            body: sim.dfs().body_contacts(),
            kinematics: sim.dfs().kinematics(),
        };
        results.push(rec.record(&tick));
        times.push(sim.time_ns());
        qs.push(q.to_vec());
    }
    Recorded {
        results,
        times,
        q: qs,
        finished: rec.finish(),
    }
}

#[test]
fn a_value_beyond_its_field_leaves_its_tick_out_and_finish_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.mcap");
    // τ₃ of 10⁵ N·m is 10¹⁰ steps of 10⁻⁵: finite, but beyond an sint32. Ticks 29, 30
    // and 40 (counted from 0; 40 is a Foxglove tick).
    let r = record_with(&path, 0.1, |tick, tau| {
        if [29, 30, 40].contains(&tick) {
            tau[3] = 1e5;
        }
    });
    assert_eq!(r.results.len(), 100);
    assert!(r.results.iter().all(Result::is_ok));
    match r.finished.unwrap_err() {
        RecordingError::NonFiniteNumber { topic, path, value } => {
            assert_eq!(topic, TOPIC_GLOVE_JOINT_STATES);
            assert_eq!(path, "efforts[3]");
            assert!(value.contains("beyond the field's range"), "{value}");
        }
        e => panic!("{e}"),
    }
    // The file is finished without those ticks.
    let session = read_session(&path).unwrap();
    assert_eq!(session.ticks(), 97);
    for topic in RAW_TOPICS {
        assert_eq!(session.message_counts[topic], 97, "{topic}");
    }
    // The Foxglove ticks 0, 20, 60 and 80: not 40.
    assert_eq!(session.message_counts[TOPIC_TF], 4);
    let times: Vec<u64> = session.joint_states.iter().map(|(t, _)| *t).collect();
    for k in [29, 30, 40] {
        assert!(!times.contains(&r.times[k]), "{k}");
    }
    // Velocities after the gap are taken from the last tick recorded before it (28).
    let after = &session.joint_states[times.iter().position(|&t| t == r.times[31]).unwrap()];
    let dt = (r.times[31] - r.times[28]) as f64 * 1e-9;
    for (i, v) in after.1.velocities.iter().enumerate() {
        let expected = (r.q[31][i] - r.q[28][i]) / dt;
        assert!(
            (v - expected).abs() <= 0.0051,
            "{i}: {v} against {expected}"
        );
    }
}

#[test]
fn a_non_finite_value_is_refused_at_once_naming_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("inf.mcap");
    let r = record_with(&path, 0.05, |tick, tau| {
        if tick == 20 {
            tau[4] = f64::NEG_INFINITY;
        }
    });
    let refused: Vec<_> = r
        .results
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.as_ref().err().map(|e| (i, e.to_string())))
        .collect();
    assert_eq!(refused.len(), 1, "{refused:?}");
    assert_eq!(refused[0].0, 20);
    assert!(refused[0].1.contains("efforts[4]"), "{}", refused[0].1);
    assert_eq!(r.finished.unwrap().ticks, 49);
    assert_eq!(read_session(&path).unwrap().ticks(), 49);
}

#[test]
fn each_raw_message_is_the_one_prost_writes_for_its_decoding() {
    for (name, seconds) in [("cylinder-power-grasp", 3.0), ("table-three", 3.5)] {
        let scenario = Scenario::builtin(name, 5).unwrap();
        let mut sim = Simulation::new(&scenario, HandModel::glove10(), Some(seconds)).unwrap();
        let scene = scenario.objects.as_ref().map(|_| sim.scene().clone());
        raw_messages_are_canonical(&mut sim, scene.as_ref());
    }
}

/// Records `sim` to its end into messages, each checked to be prost's own encoding.
fn raw_messages_are_canonical(sim: &mut Simulation, scene: Option<&Scene>) {
    use super::super::proto::{ContactsProto, GloveFeedbackProto, ObjectStateProto};
    use prost::Message;
    /// `bytes` decoded as `M`, checked to be prost's own encoding of it.
    fn canonical<M: Message + Default>(bytes: &[u8]) -> M {
        let m = M::decode(bytes).unwrap();
        assert_eq!(m.encode_to_vec(), bytes);
        m
    }
    let hand = sim.dfs().hand().clone();
    let frames = HandFrames::of(&hand);
    let mut m = Messages::new(&hand, &SceneObjects::new(sim.dfs().object(), scene));
    let mut batch = Batch::default();
    let mut touching = 0;
    while sim.step().unwrap() {
        let (q, tau, base) = sim.sample();
        let tick = Tick {
            index: sim.ticks(),
            time_ns: sim.time_ns(),
            q,
            tau,
            base,
            output: sim.output(),
            body: sim.dfs().body_contacts(),
            link_poses: &[],
        };
        batch.data.clear();
        batch.items.clear();
        m.raw_topics(&frames, &tick, Some(&mut batch)).unwrap();
        m.advance(&tick);
        let bytes = |k: usize| &batch.data[batch.items[k].2..batch.items[k].3];
        let joints: GloveJointStatesProto = canonical(bytes(0));
        assert_eq!(joints.names, hand.dof_names);
        assert_eq!(joints.positions_e5.len(), hand.dof());
        let feedback: GloveFeedbackProto = canonical(bytes(1));
        assert_eq!(feedback.names, hand.dof_names);
        let contacts: ContactsProto = canonical(bytes(2));
        touching += contacts.fingers.iter().filter(|f| f.touching).count();
        let object = canonical::<ObjectStateProto>(bytes(3));
        if let Some(scene) = scene {
            assert_eq!(object.index as usize, scene.target);
            assert_eq!(object.objects.len(), scene.objects.len());
            assert_eq!(object.objects[scene.target].pose, object.pose);
            for f in contacts.fingers.iter().filter(|f| f.touching) {
                assert_eq!(f.object as usize, scene.target);
            }
        } else {
            assert!(object.objects.is_empty() && object.index == 0);
        }
    }
    assert!(touching > 1000, "{touching}");
}
