//! What goes from the recording thread to the serialiser thread and on to the writer thread:
//! the copied inputs of a batch of ticks ([`Inputs`]), one tick as the serialisation reads it
//! ([`Tick`]), the serialised messages ([`Batch`]), and the hand's structure they need
//! ([`HandFrames`]).

use std::collections::BTreeMap;

use dfs_core::dfs::{BodyContact, TickOutput};
use dfs_core::math::Isometry;

use super::BATCH_TICKS;
use crate::session::*;

/// Serialised messages of several ticks: protobuf bytes back to back, and per message its
/// topic index, log time and byte range.
#[derive(Default)]
pub(super) struct Batch {
    pub(super) data: Vec<u8>,
    pub(super) items: Vec<(u8, u64, usize, usize)>,
    /// Metadata records to write after the batch's messages.
    pub(super) metadata: Vec<(String, BTreeMap<String, String>)>,
}

/// What the simulation thread keeps of one tick for the serialiser thread (besides its joint
/// values and link poses, which [`Inputs`] holds in flat arrays).
#[derive(Clone, Copy)]
pub(super) struct TickInput {
    /// The tick's index among the ticks `record` accepted (0 for the first): it decides the
    /// Foxglove ticks and the `/hand` ticks.
    pub(super) index: u64,
    pub(super) time_ns: u64,
    /// How many values of q and of τ the tick gave (at most the DOF count; the rest of their
    /// slots is 0).
    pub(super) q_len: usize,
    pub(super) tau_len: usize,
    pub(super) base: Isometry,
    /// How many whole-hand contacts the tick gave ([`TickData::body`]; at most the hand's
    /// contact shapes).
    pub(super) body_len: usize,
}

/// The inputs of several ticks, copied on the simulation thread: nothing is computed from them
/// there. Reused: cleared and sent back by the serialiser thread.
#[derive(Default)]
pub(super) struct Inputs {
    pub(super) ticks: Vec<TickInput>,
    /// The DFS output of each tick (apart from [`TickInput`] so that it is copied once, with
    /// one `memcpy`, straight from the simulation's).
    pub(super) outputs: Vec<TickOutput>,
    /// Per tick, `dof` slots of q then `dof` of τ.
    pub(super) joints: Vec<f64>,
    /// The whole-hand contacts of each tick ([`TickInput::body_len`] each), in tick order.
    pub(super) bodies: Vec<BodyContact>,
    /// The link poses of the Foxglove ticks (`links` per such tick), in tick order.
    pub(super) link_poses: Vec<Isometry>,
    /// Metadata records to write after the ticks.
    pub(super) metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Messages encoded by the caller (the assistant's): topic index, log time, bytes.
    pub(super) extras: Vec<(u8, u64, Vec<u8>)>,
}

impl Inputs {
    pub(super) fn with_capacity(hand: &HandFrames) -> Self {
        Self {
            ticks: Vec::with_capacity(BATCH_TICKS),
            outputs: Vec::with_capacity(BATCH_TICKS),
            joints: Vec::with_capacity(BATCH_TICKS * 2 * hand.dof),
            bodies: Vec::with_capacity(BATCH_TICKS * hand.n_shapes),
            link_poses: Vec::with_capacity(
                BATCH_TICKS.div_ceil(FOXGLOVE_DECIMATION as usize) * hand.links,
            ),
            metadata: Vec::new(),
            extras: Vec::new(),
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.ticks.is_empty() && self.metadata.is_empty() && self.extras.is_empty()
    }

    pub(super) fn clear(&mut self) {
        self.ticks.clear();
        self.outputs.clear();
        self.joints.clear();
        self.bodies.clear();
        self.link_poses.clear();
        self.metadata.clear();
        self.extras.clear();
    }
}

/// One tick as the serialisation reads it: either borrowed from the caller's [`TickData`] or
/// rebuilt from [`Inputs`] on the serialiser thread.
pub(super) struct Tick<'a> {
    pub(super) index: u64,
    pub(super) time_ns: u64,
    pub(super) q: &'a [f64],
    pub(super) tau: &'a [f64],
    pub(super) base: &'a Isometry,
    pub(super) output: &'a TickOutput,
    /// The whole-hand contacts (empty without).
    pub(super) body: &'a [BodyContact],
    /// Pose of every link (only read on Foxglove ticks; may be empty on others).
    pub(super) link_poses: &'a [Isometry],
}

impl Tick<'_> {
    pub(super) fn is_foxglove(&self) -> bool {
        self.index.is_multiple_of(FOXGLOVE_DECIMATION)
    }
}

/// Hand structure needed for `/tf` and the per-finger messages.
#[derive(Clone)]
pub(super) struct HandFrames {
    pub(super) dof: usize,
    pub(super) n_tips: usize,
    /// Number of contact shapes (whole-hand contacts recorded per tick, at most).
    pub(super) n_shapes: usize,
    /// Number of links (link poses copied per Foxglove tick).
    pub(super) links: usize,
    pub(super) root: usize,
    /// Per joint: (parent link, child link).
    pub(super) joints: Vec<(usize, usize)>,
}

impl HandFrames {
    /// The structure of `hand`.
    pub(super) fn of(hand: &dfs_core::hand::HandModel) -> Self {
        HandFrames {
            dof: hand.dof(),
            n_tips: hand.fingertips.len(),
            n_shapes: hand.contact_shapes.len(),
            links: hand.links.len(),
            root: hand.root,
            joints: hand.joints.iter().map(|j| (j.parent, j.child)).collect(),
        }
    }
}
