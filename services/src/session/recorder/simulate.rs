//! Recording a simulation: [`record_simulation`] runs a scenario and records every tick;
//! [`record_ticks`] records a [`Simulation`] already set up with a recorder.

use std::collections::BTreeMap;

use dfs_core::hand::HandModel;
use dfs_core::operator::Simulation;
use dfs_core::scenario::Scenario;
use dfs_core::Stop;

use super::{RecordSummary, SessionInfo, SessionOut, SessionRecorder, TickData};
use crate::error::{RecordingError, Result};
use crate::session::*;

/// Runs `scenario` (glove10, 1 kHz) for its script's length or `duration` seconds and records
/// every tick into `out`. `progress(done, total)` is called every 100 ticks and at the end.
///
/// A scenario that cannot be set up is [`RecordingError::InvalidInput`] (naming the field) and
/// writes no file. If the simulation fails midway, the file is finished with every tick before the failure
/// (it reads) and [`RecordingError::Simulation`] is returned with the failing tick's time.
pub fn record_simulation<'a>(
    scenario: &Scenario,
    duration: Option<f64>,
    out: impl Into<SessionOut<'a>>,
    progress: impl FnMut(u64, u64),
) -> Result<RecordSummary> {
    record_simulation_until(scenario, duration, out, progress, Stop::never())
}

/// [`record_simulation`] that ends early when `stop` is set: the file is finished with the
/// ticks recorded so far and the error is [`RecordingError::Simulation`] with
/// [`dfs_core::DfsError::Cancelled`]. `stop` is looked at every 100 simulated milliseconds
/// (well under a millisecond of CPU).
pub fn record_simulation_until<'a>(
    scenario: &Scenario,
    duration: Option<f64>,
    out: impl Into<SessionOut<'a>>,
    progress: impl FnMut(u64, u64),
    stop: &Stop,
) -> Result<RecordSummary> {
    // Set-up errors (a bad field, an unreachable object, a bad duration) come before any file.
    let mut sim = Simulation::new(scenario, HandModel::glove10(), duration).map_err(|e| {
        RecordingError::InvalidInput {
            location: format!("scenario {:?}", scenario.name),
            detail: e.to_string(),
        }
    })?;
    // A scene given as a list of objects is recorded as one (every object, the target named);
    // a scenario's one `object` as before.
    let scene = scenario.objects.as_ref().map(|_| sim.scene().clone());
    let object_json = match &scene {
        Some(_) => String::new(),
        None => serde_json::to_string(&scenario.object).unwrap_or_default(),
    };
    let scenario_json = serde_json::to_string(scenario).unwrap_or_default();
    let info = SessionInfo {
        scenario: scenario.name.clone(),
        seed: Some(scenario.seed),
        object_json,
        source: "simulation".to_owned(),
        extra: BTreeMap::from([
            ("scenario_json".to_owned(), scenario_json),
            (
                "duration_s".to_owned(),
                (sim.total_ticks() as f64 * 1e-3).to_string(),
            ),
            (
                "grasp_style".to_owned(),
                dfs_core::names::Named::name(sim.style()).to_owned(),
            ),
            // What touches the object, as imports and live sessions record it: a power
            // grasp's session is exported for import with the whole hand.
            (
                "contacts".to_owned(),
                if sim.dfs().params().whole_hand {
                    "whole_hand"
                } else {
                    "fingertips"
                }
                .to_owned(),
            ),
        ]),
        phases: sim
            .phases()
            .iter()
            .map(|s| GroundTruthPhase {
                name: s.span.phase.name().to_owned(),
                start_ns: s.span.start_ns,
                end_ns: s.span.end_ns,
            })
            .collect(),
        started_at: None,
        table_height: Some(sim.table_height()),
        hand_urdf: None,
        scene,
        assist_topics: false,
    };
    let dfs = sim.dfs();
    let recorder = SessionRecorder::create_to(out.into(), dfs.hand(), dfs.object(), &info)?;
    record_ticks_until(&mut sim, recorder, progress, stop)
}

/// Steps `sim` to its end, recording every tick with `recorder`, then finishes the file.
/// `progress(done, total)` is called every 100 ticks and at the end. If the simulation or a
/// write fails midway, the file is still finished with every tick recorded before it. A tick
/// with a value beyond its field's range is left out of the file and reported at the end (see
/// [`SessionRecorder::record`]).
pub fn record_ticks(
    sim: &mut Simulation,
    recorder: SessionRecorder,
    progress: impl FnMut(u64, u64),
) -> Result<RecordSummary> {
    record_ticks_until(sim, recorder, progress, Stop::never())
}

/// [`record_ticks`] that ends early when `stop` is set (looked at every 100 ticks): the file is
/// finished with the ticks recorded so far and the error is [`RecordingError::Simulation`]
/// with [`dfs_core::DfsError::Cancelled`].
pub fn record_ticks_until(
    sim: &mut Simulation,
    mut recorder: SessionRecorder,
    mut progress: impl FnMut(u64, u64),
    stop: &Stop,
) -> Result<RecordSummary> {
    let total = sim.total_ticks();
    loop {
        let next_time = sim.ticks() * dfs_core::operator::TICK_NS;
        let step = if sim.ticks().is_multiple_of(100) && stop.is_stopped() {
            Err(dfs_core::DfsError::Cancelled)
        } else {
            sim.step()
        };
        match step {
            Ok(true) => {}
            Ok(false) => break,
            Err(source) => {
                // Keep what was recorded: finish the file, then report the failure.
                recorder.finish()?;
                return Err(RecordingError::Simulation {
                    time_ns: next_time,
                    source,
                });
            }
        }
        let (q, tau, base) = sim.sample();
        let tick = TickData {
            time_ns: sim.time_ns(),
            q,
            tau,
            base,
            output: sim.output(),
            body: sim.dfs().body_contacts(),
            kinematics: sim.dfs().kinematics(),
        };
        if let Err(e) = recorder.record(&tick) {
            let _ = recorder.finish();
            return Err(e);
        }
        let done = sim.ticks();
        if done.is_multiple_of(100) || done == total {
            progress(done, total);
        }
    }
    recorder.finish()
}
