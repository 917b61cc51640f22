//! The two threads behind a [`SessionRecorder`]: the serialiser ([`Serialiser::run`]: tick
//! inputs into protobuf messages) and the writer ([`writer_thread`]: messages and metadata
//! into the MCAP file, and to a [`LiveView`]).
//!
//! [`SessionRecorder`]: super::SessionRecorder

use std::sync::mpsc::{Receiver, SyncSender};

use super::foxglove_topics::SceneObjects;
use super::inputs::{Batch, HandFrames, Inputs, Tick};
use super::live_view::LiveView;
use super::raw::Messages;
use super::{ALL_TOPICS, BATCH_TICKS};
use crate::error::{RecordingError, Result};
use crate::mcap_io::{SessionWriter, WriteSummary};
use crate::session::hand_scene::HandScene;
use crate::session::*;

/// The serialiser thread's state: the hand, the scene and the reused messages.
pub(super) struct Serialiser {
    pub(super) hand: HandFrames,
    pub(super) scene: SceneObjects,
    pub(super) table_height: Option<f64>,
    pub(super) hand_scene: HandScene,
    pub(super) msgs: Messages,
}

/// What the serialiser thread reports when its input ends.
#[derive(Default)]
pub(super) struct SerialiserReport {
    /// Ticks it left out (a value too large for its field).
    pub(super) refused: u64,
    /// The first of those refusals.
    pub(super) first_refusal: Option<RecordingError>,
}

impl Serialiser {
    /// Turns batches of tick inputs into batches of messages for the writer thread, until the
    /// input channel closes or the writer thread stops.
    pub(super) fn run(
        mut self,
        rx: Receiver<Inputs>,
        recycle: SyncSender<Inputs>,
        tx: SyncSender<Batch>,
        recycled: Receiver<Batch>,
    ) -> SerialiserReport {
        let mut report = SerialiserReport::default();
        let (n, links) = (self.hand.dof, self.hand.links);
        for mut inputs in rx {
            let mut batch = recycled.try_recv().unwrap_or_else(|_| Batch {
                data: Vec::with_capacity(256 * 1024),
                items: Vec::with_capacity(BATCH_TICKS * (RAW_TOPICS.len() + 1)),
                metadata: Vec::new(),
            });
            let (mut poses, mut bodies) = (0, 0);
            for (k, (input, output)) in inputs.ticks.iter().zip(&inputs.outputs).enumerate() {
                let joints = &inputs.joints[2 * n * k..2 * n * (k + 1)];
                let mut tick = Tick {
                    index: input.index,
                    time_ns: input.time_ns,
                    q: &joints[..input.q_len],
                    tau: &joints[n..n + input.tau_len],
                    base: &input.base,
                    output,
                    body: &inputs.bodies[bodies..bodies + input.body_len],
                    link_poses: &[],
                };
                bodies += input.body_len;
                if tick.is_foxglove() {
                    tick.link_poses = &inputs.link_poses[poses..poses + links];
                    poses += links;
                }
                let (start_items, start_data) = (batch.items.len(), batch.data.len());
                if let Err(e) = self.serialise_tick(&tick, &mut batch) {
                    batch.items.truncate(start_items);
                    batch.data.truncate(start_data);
                    report.refused += 1;
                    report.first_refusal.get_or_insert(e);
                }
            }
            for (topic, t, bytes) in inputs.extras.drain(..) {
                let start = batch.data.len();
                batch.data.extend_from_slice(&bytes);
                batch.items.push((topic, t, start, batch.data.len()));
            }
            batch.metadata.append(&mut inputs.metadata);
            inputs.clear();
            let _ = recycle.try_send(inputs);
            if tx.send(batch).is_err() {
                // The writer thread stopped: its own result says why.
                break;
            }
        }
        report
    }

    /// All the messages of one tick at the end of `batch`; on an error, the batch holds part of
    /// them (the caller cuts them off) and the velocities' reference is left as it was.
    fn serialise_tick(&mut self, tick: &Tick<'_>, batch: &mut Batch) -> Result<()> {
        let t = tick.time_ns;
        let m = &mut self.msgs;
        m.raw_topics(&self.hand, tick, Some(batch))?;
        if tick.is_foxglove() {
            m.fill_foxglove(&self.hand, &self.scene, self.table_height, tick)?;
            push(batch, 4, t, &m.tf);
            push(batch, 5, t, &m.scene);
            push(batch, 6, t, &m.fox_joints);
            if let Some(hand) = self.hand_scene.due(tick.index, t) {
                push(batch, 7, t, hand);
            }
        }
        m.advance(tick);
        Ok(())
    }
}

/// Encodes `msg` (protobuf) at the end of the batch.
fn push<M: prost::Message>(batch: &mut Batch, topic: u8, t: u64, msg: &M) {
    let start = batch.data.len();
    msg.encode_raw(&mut batch.data);
    batch.items.push((topic, t, start, batch.data.len()));
}

pub(super) fn writer_thread(
    mut writer: SessionWriter,
    rx: Receiver<Batch>,
    recycle: SyncSender<Batch>,
    view: Option<LiveView>,
) -> Result<WriteSummary> {
    // The assistant's topics are registered only in sessions that have them.
    let handles: Vec<_> = ALL_TOPICS.iter().map(|t| writer.topic(t).ok()).collect();
    for mut batch in rx {
        for &(topic, t, start, end) in &batch.items {
            let Some(handle) = handles[topic as usize] else {
                continue;
            };
            writer.write_to(handle, t, &batch.data[start..end])?;
            if let Some(view) = &view {
                view.publish(topic, t, &batch.data[start..end]);
            }
        }
        for (name, metadata) in batch.metadata.drain(..) {
            writer.add_metadata(&name, metadata)?;
        }
        batch.data.clear();
        batch.items.clear();
        let _ = recycle.try_send(batch);
    }
    writer.finish()
}
