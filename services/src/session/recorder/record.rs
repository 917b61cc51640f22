//! [`SessionRecorder`]: the recording thread's side. Each tick checked and copied into a batch
//! ([`SessionRecorder::record`]), batches handed to the serialiser thread, and the threads
//! joined and the file finished at the end ([`SessionRecorder::finish`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender};
use std::thread::JoinHandle;

use dfs_core::math::Isometry;

use super::foxglove_topics::timestamp;
use super::inputs::{HandFrames, Inputs, Tick, TickInput};
use super::raw::Messages;
use super::threads::SerialiserReport;
use super::{AssistTopic, RecordSummary, TickData, BATCH_TICKS, OVERLAPS_METADATA};
use crate::error::{RecordingError, Result};
use crate::mcap_io::WriteSummary;

/// Overlaps of objects seen so far in a recording.
#[derive(Debug, Clone, Default)]
pub(super) struct OverlapCount {
    ticks: u64,
    first: Option<(u64, usize, usize)>,
}

/// Records ticks into a session file.
///
/// Three threads share the work. The caller's thread ([`record`](Self::record)) only checks
/// that the tick's numbers are finite and copies its inputs (q, τ, the base pose, the
/// [`TickOutput`], and on Foxglove ticks the link poses) into a reused batch; a serialiser
/// thread turns batches of ticks into messages (SI messages, fixed-point quantisation,
/// protobuf) and a writer thread compresses and writes them (zstd, file I/O). Both hand-overs
/// go through bounded channels and their buffers come back for reuse, so memory is bounded and
/// nothing is allocated per tick once warm. Call [`finish`](Self::finish) to close the file and
/// see any error. Dropping an unfinished recorder finishes the file and ignores errors.
pub struct SessionRecorder {
    pub(super) tx: Option<SyncSender<Inputs>>,
    pub(super) recycled: Receiver<Inputs>,
    pub(super) serialiser: Option<JoinHandle<SerialiserReport>>,
    pub(super) writer: Option<JoinHandle<Result<WriteSummary>>>,
    pub(super) inputs: Inputs,
    pub(super) path: PathBuf,
    pub(super) hand: HandFrames,
    /// Messages for naming the field of a tick that holds a non-finite number, on this thread:
    /// their velocities follow the ticks accepted here.
    pub(super) check: Messages,
    pub(super) ticks: u64,
    /// The scene's object names, when it was given as a list ([`SessionInfo::scene`]): the
    /// [`OVERLAPS_METADATA`] record is written at the end.
    pub(super) object_names: Option<Vec<String>>,
    pub(super) overlaps: OverlapCount,
}

impl std::fmt::Debug for SessionRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionRecorder")
            .field("path", &self.path)
            .field("ticks", &self.ticks)
            .finish_non_exhaustive()
    }
}

/// Whether every number of the tick that the raw topics are computed from is finite: q, τ, the
/// base pose, and of the output those [`Messages::fill_raw`] reads (the fingertips' contact
/// frames and penetrations even when not touching, so this may say no to a tick whose
/// messages are all finite: the caller then runs the quantiser to be sure). Cheap: no
/// branch per value, no division.
fn inputs_finite(hand: &HandFrames, tick: &TickData<'_>) -> bool {
    #[inline]
    fn all(xs: &[f64]) -> bool {
        xs.iter().fold(true, |ok, x| ok & x.is_finite())
    }
    fn iso(i: &Isometry) -> bool {
        all(i.translation.vector.as_slice()) & all(i.rotation.coords.as_slice())
    }
    let n = hand.dof;
    let out = tick.output;
    for o in &out.objects[..out.n_objects.min(out.objects.len())] {
        let s = &o.state;
        if !(iso(&s.pose)
            & all(s.linear_velocity.as_slice())
            & all(s.angular_velocity_b.as_slice()))
        {
            return false;
        }
    }
    let mut ok = all(&tick.q[..tick.q.len().min(n)])
        & all(&tick.tau[..tick.tau.len().min(n)])
        & iso(tick.base)
        & all(&out.motor_q[..n])
        & all(&out.motor_qd[..n])
        & all(&out.feedback_torque[..n])
        & iso(&out.object.pose)
        & all(out.object.linear_velocity.as_slice())
        & all(out.object.angular_velocity_b.as_slice())
        & all(out.f_ext_b.as_slice())
        & all(out.object_force_b.as_slice())
        & all(out.table_force_b.as_slice());
    for tip in &out.tips[..hand.n_tips] {
        ok &= all(tip.feedback_force_world.as_slice())
            & all(tip.tip_force_world.as_slice())
            & tip.penetration.is_finite()
            & all(tip.intensity.as_slice())
            & all(tip.transmitted.as_slice())
            & all(tip.feedback.as_slice());
        if let Some(frame) = &tip.frame {
            ok &= all(frame.p_b.as_slice()) & all(frame.rot_b.matrix().as_slice());
        }
    }
    ok
}

impl SessionRecorder {
    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Ticks recorded so far (accepted by [`record`](Self::record)).
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// Records one tick: the raw topics always, the Foxglove topics when the tick index is a
    /// multiple of [`FOXGLOVE_DECIMATION`].
    ///
    /// Fails with [`RecordingError::NonFiniteNumber`], naming the topic and field, if a value
    /// is NaN or infinite: nothing of the tick is written then, its velocities are not taken
    /// as the next tick's reference, and the recorder goes on with the next tick. Fails with
    /// the writer thread's error if it failed.
    ///
    /// This thread only checks and copies the tick; its messages are made on the serialiser
    /// thread. A finite value too large for its fixed-point field (beyond ±2³¹ steps: a force
    /// over 2.1·10⁶ N, a moment over 2147 N·m, a penetration over 2.1 m, a joint velocity over
    /// 2.1·10⁷ rad/s, ...) is found there: that tick is left out just the same (nothing of it is
    /// written, the next velocities are taken from the tick before it), the recording goes on,
    /// and [`finish`](Self::finish) reports the first such refusal as
    /// [`RecordingError::NonFiniteNumber`] (value "… (beyond the field's range)") after
    /// finishing the file.
    pub fn record(&mut self, tick: &TickData<'_>) -> Result<()> {
        let n = self.hand.dof;
        let (q, tau) = (
            &tick.q[..tick.q.len().min(n)],
            &tick.tau[..tick.tau.len().min(n)],
        );
        let view = Tick {
            index: self.ticks,
            time_ns: tick.time_ns,
            q,
            tau,
            base: tick.base,
            output: tick.output,
            body: &tick.body[..tick.body.len().min(self.hand.n_shapes)],
            link_poses: &tick.kinematics.link_poses[..self.hand.links],
        };
        if !inputs_finite(&self.hand, tick) {
            // Name the field as the serialisation would (if none is refused, the non-finite
            // number is one no message carries, and the tick is recorded).
            self.check.raw_topics(&self.hand, &view, None)?;
        }
        let foxglove = view.is_foxglove();
        if foxglove {
            timestamp(tick.time_ns)?;
        }
        self.check.advance(&view);

        let inputs = &mut self.inputs;
        inputs.ticks.push(TickInput {
            index: self.ticks,
            time_ns: tick.time_ns,
            q_len: q.len(),
            tau_len: tau.len(),
            base: *tick.base,
            body_len: view.body.len(),
        });
        inputs.bodies.extend_from_slice(view.body);
        inputs
            .outputs
            .extend_from_slice(std::slice::from_ref(tick.output));
        inputs.joints.extend_from_slice(q);
        inputs
            .joints
            .resize(inputs.joints.len() + (n - q.len()), 0.0);
        inputs.joints.extend_from_slice(tau);
        inputs
            .joints
            .resize(inputs.joints.len() + (n - tau.len()), 0.0);
        if foxglove {
            inputs.link_poses.extend_from_slice(view.link_poses);
        }
        if let Some((i, j)) = tick.output.overlap {
            self.overlaps.ticks += 1;
            self.overlaps.first.get_or_insert((tick.time_ns, i, j));
        }
        self.ticks += 1;
        if self.inputs.ticks.len() >= BATCH_TICKS {
            self.send_inputs()?;
        }
        Ok(())
    }

    /// Logs a message of the assistant's `topic` at session time `t_ns` (written with the
    /// ticks recorded so far; ignored unless the session was created with
    /// [`SessionInfo::assist_topics`]).
    pub fn log_assist(&mut self, topic: AssistTopic, t_ns: u64, msg: &impl prost::Message) {
        let index = match topic {
            AssistTopic::Events => 8,
            AssistTopic::Robot => 9,
        };
        self.inputs.extras.push((index, t_ns, msg.encode_to_vec()));
    }

    /// Adds a metadata record (written after the ticks recorded so far), for records only
    /// known at the end such as a replay's report.
    pub fn add_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.inputs.metadata.push((name.to_owned(), metadata));
        self.send_inputs()
    }

    fn send_inputs(&mut self) -> Result<()> {
        if self.inputs.is_empty() {
            return Ok(());
        }
        let next = match self.recycled.try_recv() {
            Ok(inputs) => inputs,
            Err(_) => Inputs::with_capacity(&self.hand),
        };
        let full = std::mem::replace(&mut self.inputs, next);
        let sent = match &self.tx {
            Some(tx) => tx.send(full).is_ok(),
            None => false,
        };
        if !sent {
            // A thread stopped: report why.
            return Err(self.join().err().unwrap_or(RecordingError::WriterClosed {
                path: self.path.clone(),
            }));
        }
        Ok(())
    }

    /// Closes the channel to the serialiser thread and waits for both threads: the writer's
    /// error first, then the first tick the serialiser refused.
    fn join(&mut self) -> Result<WriteSummary> {
        self.tx = None;
        let report = match self.serialiser.take() {
            Some(handle) => handle.join().ok(),
            None => Some(SerialiserReport::default()),
        };
        let written = match self.writer.take() {
            Some(handle) => handle
                .join()
                .unwrap_or(Err(RecordingError::WriterThreadPanicked)),
            None => Err(RecordingError::WriterClosed {
                path: self.path.clone(),
            }),
        };
        let report = report.ok_or(RecordingError::WriterThreadPanicked)?;
        let write = written?;
        self.ticks -= report.refused;
        match report.first_refusal {
            Some(e) => Err(e),
            None => Ok(write),
        }
    }

    /// Writes the remaining ticks, finishes the file (summary, footer, sync) on the writer
    /// thread and reports what was written. If the serialiser thread left out a tick (a value
    /// beyond its field's range, see [`record`](Self::record)), the file is finished all the
    /// same, without that tick, and the error is the first such refusal.
    pub fn finish(mut self) -> Result<RecordSummary> {
        if let Some(names) = self.object_names.take() {
            let o = &self.overlaps;
            let mut record = BTreeMap::from([("overlap_ticks".to_owned(), o.ticks.to_string())]);
            if let Some((t, i, j)) = o.first {
                let name = |k: usize| names.get(k).cloned().unwrap_or_else(|| k.to_string());
                record.insert("first_overlap_ns".to_owned(), t.to_string());
                record.insert(
                    "first_overlap".to_owned(),
                    format!("{},{}", name(i), name(j)),
                );
            }
            self.inputs
                .metadata
                .push((OVERLAPS_METADATA.to_owned(), record));
        }
        self.send_inputs()?;
        let write = self.join()?;
        Ok(RecordSummary {
            ticks: self.ticks,
            file_bytes: write.bytes,
            write,
        })
    }
}

impl Drop for SessionRecorder {
    fn drop(&mut self) {
        if self.serialiser.is_some() || self.writer.is_some() {
            let _ = self.send_inputs();
            let _ = self.join();
        }
    }
}
