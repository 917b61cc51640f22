//! [`SessionRecorder`]: ticks of the closed loop into a session file, with the writing on its
//! own thread; [`record_simulation`]: a scenario run and recorded.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use dfs_core::dfs::TickOutput;
use dfs_core::hand::{HandModel, Kinematics};
use dfs_core::math::{Isometry, Point, Rotation, Vector};
use dfs_core::object::{RigidObject, Shape};
use dfs_core::operator::Simulation;
use dfs_core::scenario::Scenario;
use dfs_core::Stop;

use foxglove::messages as fg;
use foxglove::Encode;

use super::messages::*;
use super::proto::{
    ContactsProto, GloveFeedbackProto, GloveJointStatesProto, Quantiser, FILE_DESCRIPTOR_SET,
    FORMAT_VERSION,
};
use super::*;
use crate::error::{RecordingError, Result};
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::mcap_io::{SessionWriter, WriteSummary, WriterOptions};

/// Ticks per batch handed to the writer thread (also the Foxglove period, so each batch holds
/// exactly one set of Foxglove messages).
const BATCH_TICKS: u64 = FOXGLOVE_DECIMATION;
/// zstd level of session files: 3, zstd's default. With format 1's JSON, level 1 was both
/// faster and smaller; with format 2's protobuf, level 3 makes a 60 s `sphere-lift` 5 %
/// smaller (13.6 against 14.3 MB before the coarser joint steps) on the writer thread, which
/// runs beside the simulation.
const ZSTD_LEVEL: u32 = 3;
/// Batches in flight between the simulation and the writer thread.
const CHANNEL_BOUND: usize = 8;

/// Topic indices used inside batches: the raw topics, then the Foxglove topics.
const ALL_TOPICS: [&str; 7] = [
    TOPIC_GLOVE_JOINT_STATES,
    TOPIC_GLOVE_FEEDBACK,
    TOPIC_CONTACTS,
    TOPIC_OBJECT_STATE,
    TOPIC_TF,
    TOPIC_SCENE,
    TOPIC_JOINT_STATES,
];

/// Serialised messages of several ticks: protobuf bytes back to back, and per message its
/// topic index, log time and byte range.
#[derive(Default)]
struct Batch {
    data: Vec<u8>,
    items: Vec<(u8, u64, usize, usize)>,
    /// Metadata records to write after the batch's messages.
    metadata: Vec<(String, BTreeMap<String, String>)>,
}

/// Descriptive parameters of a session, written to the `session` metadata record.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionInfo {
    /// Scenario name (or the imported file's name).
    pub scenario: String,
    /// Seed of the operator's noise (empty for imports).
    pub seed: Option<u64>,
    /// The object as JSON (the scenario file's `object`).
    pub object_json: String,
    /// Where the session comes from: `simulation` or `import-glove`.
    pub source: String,
    /// More key-value pairs for the `session` record (e.g. the whole scenario as JSON).
    pub extra: BTreeMap<String, String>,
    /// Ground-truth phases (empty when unknown).
    pub phases: Vec<GroundTruthPhase>,
    /// Wall-clock start written as `started_at`. `None` (the default): the Unix epoch, so that
    /// a simulation, a replay or an import is a pure function of its inputs and the simulator
    /// version, byte for byte (a repeated request finds the session already stored); a live
    /// recording passes the time it started.
    pub started_at: Option<std::time::SystemTime>,
    /// Height of the table's top in the world (m), shown in `/scene`; `None`: no table.
    pub table_height: Option<f64>,
}

/// One tick of the closed loop, as the recorder needs it.
#[derive(Debug, Clone, Copy)]
pub struct TickData<'a> {
    /// Tick time, ns since the session start (the messages' log time).
    pub time_ns: u64,
    /// Measured joint angles θ, one per DOF.
    pub q: &'a [f64],
    /// Operator joint torques τ, one per DOF.
    pub tau: &'a [f64],
    /// Pose of the hand's base link in the world.
    pub base: &'a Isometry,
    /// The DFS output of the tick.
    pub output: &'a TickOutput,
    /// The DFS kinematics of the tick (link poses for `/tf`).
    pub kinematics: &'a Kinematics,
}

/// What a recording wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordSummary {
    /// Ticks recorded.
    pub ticks: u64,
    /// Size of the finished file (bytes).
    pub file_bytes: u64,
    /// What the MCAP writer wrote (messages per topic, chunks, ...).
    pub write: WriteSummary,
}

/// Hand structure needed for `/tf` and the per-finger messages.
struct HandFrames {
    dof: usize,
    n_tips: usize,
    root: usize,
    /// Per joint: (parent link, child link).
    joints: Vec<(usize, usize)>,
}

/// Reused message instances: filled in place every tick, so that serialising the raw topics
/// allocates nothing once warm. The raw topics are filled in SI units, then quantised into
/// their protobuf form ([`super::proto`]); the Foxglove topics are the SDK's own types.
struct Messages {
    joints: GloveJointStates,
    feedback: GloveFeedback,
    contacts: Contacts,
    object: messages::ObjectState,
    joints_pb: GloveJointStatesProto,
    feedback_pb: GloveFeedbackProto,
    contacts_pb: ContactsProto,
    tf: fg::FrameTransforms,
    scene: fg::SceneUpdate,
    fox_joints: fg::JointStates,
    prev_q: Vec<f64>,
    prev_time_ns: Option<u64>,
}

/// Records ticks into a session file. The file is written by a thread of its own; call
/// [`finish`](Self::finish) to close it and see any error. Dropping an unfinished recorder
/// finishes the file and ignores errors.
pub struct SessionRecorder {
    tx: Option<SyncSender<Batch>>,
    recycled: Receiver<Batch>,
    thread: Option<JoinHandle<Result<WriteSummary>>>,
    batch: Batch,
    batch_ticks: u64,
    path: PathBuf,
    hand: HandFrames,
    shape: Shape,
    table_height: Option<f64>,
    msgs: Messages,
    ticks: u64,
}

impl std::fmt::Debug for SessionRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionRecorder")
            .field("path", &self.path)
            .field("ticks", &self.ticks)
            .finish_non_exhaustive()
    }
}

fn v3(v: &Vector) -> Vector3 {
    Vector3::new(v.x, v.y, v.z)
}

fn quat(r: &Rotation) -> Quaternion {
    let q = r.quaternion();
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn pose(iso: &Isometry) -> Pose {
    Pose {
        position: v3(&iso.translation.vector),
        orientation: quat(&iso.rotation),
    }
}

fn intensity(c: &dfs_core::contact::Intensity) -> Intensity4 {
    Intensity4 {
        x: c[0],
        y: c[1],
        z: c[2],
        torsion: c[3],
    }
}

fn wrench6(w: &dfs_core::math::Wrench) -> [f64; 6] {
    [w[0], w[1], w[2], w[3], w[4], w[5]]
}

impl SessionRecorder {
    /// Creates `out` (truncating it), writes the `session` and `ground_truth` metadata and the
    /// channels, and starts the writer thread.
    pub fn create(
        out: impl AsRef<Path>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        let path = out.as_ref().to_path_buf();
        let options = WriterOptions {
            compression_level: ZSTD_LEVEL,
            message_indexes: false,
            ..WriterOptions::default()
        };
        let mut writer = SessionWriter::create_with_options(&path, options)?;
        let mut meta = BTreeMap::new();
        meta.insert("scenario".to_owned(), info.scenario.clone());
        meta.insert(
            "seed".to_owned(),
            info.seed.map(|s| s.to_string()).unwrap_or_default(),
        );
        meta.insert("hand".to_owned(), hand.name.clone());
        meta.insert("object".to_owned(), info.object_json.clone());
        meta.insert("rate_hz".to_owned(), RATE_HZ.to_string());
        meta.insert(
            "software_version".to_owned(),
            env!("CARGO_PKG_VERSION").to_owned(),
        );
        meta.insert(
            "started_at".to_owned(),
            rfc3339_utc(info.started_at.unwrap_or(std::time::UNIX_EPOCH)),
        );
        meta.insert("source".to_owned(), info.source.clone());
        meta.insert("format_version".to_owned(), FORMAT_VERSION.to_string());
        meta.insert(
            "foxglove_rate_hz".to_owned(),
            (u64::from(RATE_HZ) / FOXGLOVE_DECIMATION).to_string(),
        );
        for (k, v) in &info.extra {
            meta.entry(k.clone()).or_insert_with(|| v.clone());
        }
        writer.add_metadata(SESSION_METADATA, meta)?;
        let phases =
            serde_json::to_string(&info.phases).map_err(|e| RecordingError::Serialize {
                topic: GROUND_TRUTH_METADATA.to_owned(),
                detail: e.to_string(),
            })?;
        writer.add_metadata(
            GROUND_TRUTH_METADATA,
            BTreeMap::from([("phases".to_owned(), phases)]),
        )?;
        for (topic, schema) in RAW_TOPICS.iter().zip(RAW_SCHEMA_NAMES) {
            writer.register_protobuf_channel(topic, schema, FILE_DESCRIPTOR_SET)?;
        }
        register_foxglove::<fg::FrameTransforms>(&mut writer, TOPIC_TF)?;
        register_foxglove::<fg::SceneUpdate>(&mut writer, TOPIC_SCENE)?;
        register_foxglove::<fg::JointStates>(&mut writer, TOPIC_JOINT_STATES)?;

        let (tx, rx) = sync_channel::<Batch>(CHANNEL_BOUND);
        let (recycle_tx, recycled) = channel::<Batch>();
        let thread = std::thread::Builder::new()
            .name("icms-session-writer".into())
            .spawn(move || writer_thread(writer, rx, recycle_tx))
            .map_err(|e| RecordingError::io("starting the session writer thread", e))?;

        let frames = HandFrames {
            dof: hand.dof(),
            n_tips: hand.fingertips.len(),
            root: hand.root,
            joints: hand.joints.iter().map(|j| (j.parent, j.child)).collect(),
        };
        let msgs = Messages::new(hand);
        Ok(Self {
            tx: Some(tx),
            recycled,
            thread: Some(thread),
            batch: Batch {
                data: Vec::with_capacity(64 * 1024),
                items: Vec::with_capacity(BATCH_TICKS as usize * ALL_TOPICS.len()),
                metadata: Vec::new(),
            },
            batch_ticks: 0,
            path,
            hand: frames,
            shape: object.shape,
            table_height: info.table_height,
            msgs,
            ticks: 0,
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Ticks recorded so far.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// Records one tick: the raw topics always, the Foxglove topics when the tick index is a
    /// multiple of [`FOXGLOVE_DECIMATION`]. Fails with [`RecordingError::NonFiniteNumber`] if a
    /// value is NaN or infinite (nothing of the tick is written then), or with the writer
    /// thread's error if it failed.
    pub fn record(&mut self, tick: &TickData<'_>) -> Result<()> {
        let start_items = self.batch.items.len();
        let start_data = self.batch.data.len();
        let result = self.serialise_tick(tick);
        if let Err(e) = result {
            self.batch.items.truncate(start_items);
            self.batch.data.truncate(start_data);
            return Err(e);
        }
        self.ticks += 1;
        self.batch_ticks += 1;
        if self.batch_ticks >= BATCH_TICKS {
            self.send_batch()?;
        }
        Ok(())
    }

    fn serialise_tick(&mut self, tick: &TickData<'_>) -> Result<()> {
        let t = tick.time_ns;
        let m = &mut self.msgs;
        m.fill_raw(&self.hand, tick);
        let mut q = Quantiser::default();
        q.joint_states(&m.joints, &mut m.joints_pb);
        refused(&q, 0)?;
        push(&mut self.batch, 0, t, &m.joints_pb);
        q.feedback(&m.feedback, &mut m.feedback_pb);
        refused(&q, 1)?;
        push(&mut self.batch, 1, t, &m.feedback_pb);
        q.contacts(&m.contacts, &mut m.contacts_pb);
        refused(&q, 2)?;
        push(&mut self.batch, 2, t, &m.contacts_pb);
        let object = q.object(&m.object);
        refused(&q, 3)?;
        push(&mut self.batch, 3, t, &object);
        if self.ticks.is_multiple_of(FOXGLOVE_DECIMATION) {
            m.fill_foxglove(&self.hand, &self.shape, self.table_height, tick)?;
            push(&mut self.batch, 4, t, &m.tf);
            push(&mut self.batch, 5, t, &m.scene);
            push(&mut self.batch, 6, t, &m.fox_joints);
        }
        m.advance(tick);
        Ok(())
    }

    /// Adds a metadata record (written after the ticks recorded so far), for records only
    /// known at the end such as a replay's report.
    pub fn add_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.batch.metadata.push((name.to_owned(), metadata));
        self.send_batch()
    }

    fn send_batch(&mut self) -> Result<()> {
        if self.batch.items.is_empty() && self.batch.metadata.is_empty() {
            return Ok(());
        }
        let next = self.recycled.try_recv().unwrap_or_else(|_| Batch {
            data: Vec::with_capacity(self.batch.data.capacity()),
            items: Vec::with_capacity(self.batch.items.capacity()),
            metadata: Vec::new(),
        });
        let full = std::mem::replace(&mut self.batch, next);
        self.batch_ticks = 0;
        let sent = match &self.tx {
            Some(tx) => tx.send(full).is_ok(),
            None => false,
        };
        if !sent {
            // The writer thread stopped: report its error.
            return Err(self.join().err().unwrap_or(RecordingError::WriterClosed {
                path: self.path.clone(),
            }));
        }
        Ok(())
    }

    fn join(&mut self) -> Result<WriteSummary> {
        self.tx = None;
        match self.thread.take() {
            Some(handle) => handle
                .join()
                .unwrap_or(Err(RecordingError::WriterThreadPanicked)),
            None => Err(RecordingError::WriterClosed {
                path: self.path.clone(),
            }),
        }
    }

    /// Writes the remaining ticks, finishes the file (summary, footer, sync) on the writer
    /// thread and reports what was written.
    pub fn finish(mut self) -> Result<RecordSummary> {
        self.send_batch()?;
        let write = self.join()?;
        let file_bytes = std::fs::metadata(&self.path)
            .map_err(|e| RecordingError::io(format!("reading {}", self.path.display()), e))?
            .len();
        Ok(RecordSummary {
            ticks: self.ticks,
            file_bytes,
            write,
        })
    }
}

impl Drop for SessionRecorder {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.send_batch();
            let _ = self.join();
        }
    }
}

/// Encodes `msg` (protobuf) at the end of the batch.
fn push<M: prost::Message>(batch: &mut Batch, topic: u8, t: u64, msg: &M) {
    let start = batch.data.len();
    msg.encode_raw(&mut batch.data);
    batch.items.push((topic, t, start, batch.data.len()));
}

/// The quantiser's refusal as the recorder's error: a value of raw topic `topic` that is not
/// finite or too large for its field (nothing of the tick is written then).
fn refused(q: &Quantiser, topic: u8) -> Result<()> {
    match &q.refused {
        None => Ok(()),
        Some((field, value)) => Err(RecordingError::NonFiniteNumber {
            topic: ALL_TOPICS[topic as usize].to_owned(),
            path: field.clone(),
            value: if value.is_finite() {
                format!("{value} (beyond the field's range)")
            } else {
                value.to_string()
            },
        }),
    }
}

/// Registers a Foxglove topic with the SDK's schema of `T` (a `FileDescriptorSet` of the
/// official `.proto`).
fn register_foxglove<T: Encode>(writer: &mut SessionWriter, topic: &str) -> Result<()> {
    let schema = T::get_schema().ok_or_else(|| RecordingError::Serialize {
        topic: topic.to_owned(),
        detail: "the Foxglove SDK has no schema for it".to_owned(),
    })?;
    writer.register_protobuf_channel(topic, &schema.name, &schema.data)
}

fn writer_thread(
    mut writer: SessionWriter,
    rx: Receiver<Batch>,
    recycle: std::sync::mpsc::Sender<Batch>,
) -> Result<WriteSummary> {
    for mut batch in rx {
        for &(topic, t, start, end) in &batch.items {
            writer.write_raw(ALL_TOPICS[topic as usize], t, &batch.data[start..end])?;
        }
        for (name, metadata) in batch.metadata.drain(..) {
            writer.add_metadata(&name, metadata)?;
        }
        batch.data.clear();
        batch.items.clear();
        let _ = recycle.send(batch);
    }
    writer.finish()
}

impl Messages {
    fn new(hand: &HandModel) -> Self {
        let n = hand.dof();
        let names = hand.dof_names.clone();
        let tip_names: Vec<String> = hand.fingertips.iter().map(|t| t.name.clone()).collect();
        let joints = GloveJointStates {
            names: names.clone(),
            positions: vec![0.0; n],
            velocities: vec![0.0; n],
            efforts: vec![0.0; n],
        };
        let feedback = GloveFeedback {
            names: names.clone(),
            motor_positions: vec![0.0; n],
            motor_velocities: vec![0.0; n],
            feedback_torques: vec![0.0; n],
            fingers: tip_names
                .iter()
                .map(|name| FingerFeedback {
                    name: name.clone(),
                    ..FingerFeedback::default()
                })
                .collect(),
        };
        let contacts = Contacts {
            n_contacts: 0,
            fingers: tip_names
                .iter()
                .map(|name| FingerContact {
                    name: name.clone(),
                    ..FingerContact::default()
                })
                .collect(),
        };
        let root_name = hand.links[hand.root].name.clone();
        let transform = |parent: &str, child: &str| fg::FrameTransform {
            parent_frame_id: parent.to_owned(),
            child_frame_id: child.to_owned(),
            ..fg::FrameTransform::default()
        };
        let mut transforms = vec![transform(WORLD_FRAME, &root_name)];
        transforms.extend(
            hand.joints
                .iter()
                .map(|j| transform(&hand.links[j.parent].name, &hand.links[j.child].name)),
        );
        transforms.push(transform(WORLD_FRAME, OBJECT_FRAME));
        let entity = fg::SceneEntity {
            frame_id: WORLD_FRAME.to_owned(),
            id: OBJECT_FRAME.to_owned(),
            frame_locked: false,
            ..fg::SceneEntity::default()
        };
        let fox_joints = fg::JointStates {
            timestamp: None,
            joints: names
                .iter()
                .map(|name| fg::JointState {
                    name: name.clone(),
                    position: Some(0.0),
                    velocity: Some(0.0),
                    acceleration: None,
                    effort: Some(0.0),
                })
                .collect(),
        };
        Self {
            joints_pb: GloveJointStatesProto::default(),
            feedback_pb: GloveFeedbackProto::default(),
            contacts_pb: ContactsProto::default(),
            joints,
            feedback,
            contacts,
            object: messages::ObjectState::default(),
            tf: fg::FrameTransforms { transforms },
            scene: fg::SceneUpdate {
                deletions: Vec::new(),
                entities: vec![entity],
            },
            fox_joints,
            prev_q: vec![0.0; n],
            prev_time_ns: None,
        }
    }

    fn fill_raw(&mut self, hand: &HandFrames, tick: &TickData<'_>) {
        let n = hand.dof;
        let out = tick.output;
        let dt = match self.prev_time_ns {
            Some(prev) if tick.time_ns > prev => (tick.time_ns - prev) as f64 * 1e-9,
            _ => 0.0,
        };
        for i in 0..n {
            let q = tick.q.get(i).copied().unwrap_or(0.0);
            self.joints.positions[i] = q;
            self.joints.velocities[i] = if dt > 0.0 {
                (q - self.prev_q[i]) / dt
            } else {
                0.0
            };
            self.joints.efforts[i] = tick.tau.get(i).copied().unwrap_or(0.0);
            self.feedback.motor_positions[i] = out.motor_q[i];
            self.feedback.motor_velocities[i] = out.motor_qd[i];
            self.feedback.feedback_torques[i] = out.feedback_torque[i];
        }
        self.contacts.n_contacts = out.n_contacts as u32;
        for k in 0..hand.n_tips {
            let tip = &out.tips[k];
            let fb = &mut self.feedback.fingers[k];
            fb.feedback_force_world = v3(&tip.feedback_force_world);
            fb.tip_force_world = v3(&tip.tip_force_world);
            let c = &mut self.contacts.fingers[k];
            c.touching = tip.touching;
            c.in_contact = tip.in_contact;
            match (&tip.frame, tip.touching) {
                (Some(frame), true) => {
                    c.point_b = v3(&frame.p_b);
                    c.normal_b = v3(&frame.normal_b());
                    c.penetration = tip.penetration;
                }
                _ => {
                    c.point_b = Vector3::default();
                    c.normal_b = Vector3::default();
                    c.penetration = 0.0;
                }
            }
            c.intensity = intensity(&tip.intensity);
            c.transmitted = intensity(&tip.transmitted);
            c.feedback = intensity(&tip.feedback);
            c.slip = tip.slip;
            c.in_cone = !tip.slip;
        }
        let o = &mut self.object;
        o.pose = pose(&out.object.pose);
        o.linear_velocity = v3(&out.object.linear_velocity);
        o.angular_velocity_b = v3(&out.object.angular_velocity_b);
        o.f_ext_b = wrench6(&out.f_ext_b);
        o.object_force_b = wrench6(&out.object_force_b);
        o.table_force_b = wrench6(&out.table_force_b);
        o.pose_in_hand = pose(&(tick.base.inverse() * out.object.pose));
    }

    /// The tick just recorded becomes the one the next velocities are taken from (not called
    /// for a refused tick, which records nothing).
    fn advance(&mut self, tick: &TickData<'_>) {
        for (prev, &q) in self.prev_q.iter_mut().zip(tick.q) {
            *prev = q;
        }
        self.prev_time_ns = Some(tick.time_ns);
    }

    fn fill_foxglove(
        &mut self,
        hand: &HandFrames,
        shape: &Shape,
        table_height: Option<f64>,
        tick: &TickData<'_>,
    ) -> Result<()> {
        let stamp = Some(timestamp(tick.time_ns)?);
        let kin = tick.kinematics;
        let out = tick.output;
        let tfs = &mut self.tf.transforms;
        let set = |tf: &mut fg::FrameTransform, iso: &Isometry| {
            tf.timestamp = stamp;
            tf.translation = Some(fg_vector(&iso.translation.vector));
            tf.rotation = Some(fg_quaternion(&iso.rotation));
        };
        set(&mut tfs[0], &kin.link_poses[hand.root]);
        for (j, &(parent, child)) in hand.joints.iter().enumerate() {
            let rel = kin.link_poses[parent].inverse() * kin.link_poses[child];
            set(&mut tfs[1 + j], &rel);
        }
        let last = tfs.len() - 1;
        set(&mut tfs[last], &out.object.pose);

        let object_pose = &out.object.pose;
        let entity = &mut self.scene.entities[0];
        entity.timestamp = stamp;
        entity.spheres.clear();
        entity.cubes.clear();
        entity.cylinders.clear();
        entity.arrows.clear();
        let p = Some(fg_pose(object_pose));
        let colour = Some(rgba(0.25, 0.5, 0.85, 0.8));
        let size = |x: f64, y: f64, z: f64| Some(fg::Vector3 { x, y, z });
        match *shape {
            Shape::Sphere { radius } => entity.spheres.push(fg::SpherePrimitive {
                pose: p,
                size: size(2.0 * radius, 2.0 * radius, 2.0 * radius),
                color: colour,
            }),
            Shape::Box { half_extents: h } => entity.cubes.push(fg::CubePrimitive {
                pose: p,
                size: size(2.0 * h[0], 2.0 * h[1], 2.0 * h[2]),
                color: colour,
            }),
            Shape::Cylinder {
                radius,
                half_height,
            } => entity.cylinders.push(fg::CylinderPrimitive {
                pose: p,
                size: size(2.0 * radius, 2.0 * radius, 2.0 * half_height),
                bottom_scale: 1.0,
                top_scale: 1.0,
                color: colour,
            }),
        }
        for tip in out.tips.iter().take(hand.n_tips) {
            let Some(frame) = tip.frame.filter(|_| tip.in_contact) else {
                continue;
            };
            let t = &tip.transmitted;
            let f_world = object_pose.rotation * (frame.rot_b * Vector::new(t[0], t[1], t[2]));
            let magnitude = f_world.norm();
            if magnitude.is_nan() || magnitude <= 1e-9 {
                continue;
            }
            let point_world = object_pose * Point::from(frame.p_b);
            let rotation =
                Rotation::rotation_between(&Vector::x(), &f_world).unwrap_or_else(|| {
                    // Antiparallel to +x: half a turn about z.
                    Rotation::from_axis_angle(&Vector::z_axis(), std::f64::consts::PI)
                });
            let length = ARROW_M_PER_N * magnitude;
            let head = (0.25 * length).min(0.01);
            entity.arrows.push(fg::ArrowPrimitive {
                pose: Some(fg::Pose {
                    position: Some(fg_vector(&point_world.coords)),
                    orientation: Some(fg_quaternion(&rotation)),
                }),
                shaft_length: length - head,
                shaft_diameter: 0.003,
                head_length: head,
                head_diameter: 0.007,
                color: Some(if tip.slip {
                    rgba(1.0, 0.6, 0.0, 1.0)
                } else {
                    rgba(0.9, 0.1, 0.1, 1.0)
                }),
            });
        }

        // The table: a slab of TABLE_SIZE_M square under the world origin, its top at the
        // table's height (in every update, so that a viewer opening the file mid-way sees it).
        if let Some(h) = table_height {
            if self.scene.entities.len() < 2 {
                self.scene.entities.push(fg::SceneEntity {
                    frame_id: WORLD_FRAME.to_owned(),
                    id: TABLE_ENTITY.to_owned(),
                    ..fg::SceneEntity::default()
                });
            }
            let table = &mut self.scene.entities[1];
            table.timestamp = stamp;
            table.cubes.clear();
            table.cubes.push(fg::CubePrimitive {
                pose: Some(fg_pose(&Isometry::translation(
                    0.0,
                    0.0,
                    h - 0.5 * TABLE_THICKNESS_M,
                ))),
                size: size(TABLE_SIZE_M, TABLE_SIZE_M, TABLE_THICKNESS_M),
                color: Some(rgba(0.55, 0.45, 0.35, 1.0)),
            });
        }

        self.fox_joints.timestamp = stamp;
        for (i, j) in self.fox_joints.joints.iter_mut().enumerate() {
            j.position = Some(self.joints.positions[i]);
            j.velocity = Some(self.joints.velocities[i]);
            j.effort = Some(self.joints.efforts[i]);
        }
        Ok(())
    }
}

/// Id of the table's entity in `/scene`.
pub const TABLE_ENTITY: &str = "table";
/// Side of the table shown in `/scene` (m).
const TABLE_SIZE_M: f64 = 1.0;
/// Thickness of the table shown in `/scene` (m).
const TABLE_THICKNESS_M: f64 = 0.02;

/// A Foxglove timestamp of `ns` since the session's start.
fn timestamp(ns: u64) -> Result<fg::Timestamp> {
    let sec = u32::try_from(ns / 1_000_000_000).map_err(|_| RecordingError::Serialize {
        topic: TOPIC_TF.to_owned(),
        detail: format!("log time {ns} ns is past what a Foxglove timestamp holds"),
    })?;
    Ok(fg::Timestamp::new(sec, (ns % 1_000_000_000) as u32))
}

fn fg_vector(v: &Vector) -> fg::Vector3 {
    fg::Vector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

fn fg_quaternion(r: &Rotation) -> fg::Quaternion {
    let q = r.quaternion();
    fg::Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn fg_pose(iso: &Isometry) -> fg::Pose {
    fg::Pose {
        position: Some(fg_vector(&iso.translation.vector)),
        orientation: Some(fg_quaternion(&iso.rotation)),
    }
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> fg::Color {
    fg::Color { r, g, b, a }
}

/// Runs `scenario` (glove10, 1 kHz) for its script's length or `duration` seconds and records
/// every tick into `out`. `progress(done, total)` is called every 100 ticks and at the end.
///
/// A scenario that cannot be set up is [`RecordingError::InvalidInput`] (naming the field) and
/// writes no file. If the simulation fails midway, the file is finished with every tick before the failure
/// (it reads) and [`RecordingError::Simulation`] is returned with the failing tick's time.
pub fn record_simulation(
    scenario: &Scenario,
    duration: Option<f64>,
    out: &Path,
    progress: impl FnMut(u64, u64),
) -> Result<RecordSummary> {
    record_simulation_until(scenario, duration, out, progress, Stop::never())
}

/// [`record_simulation`] that ends early when `stop` is set: the file is finished with the
/// ticks recorded so far and the error is [`RecordingError::Simulation`] with
/// [`dfs_core::DfsError::Cancelled`]. `stop` is looked at every 100 simulated milliseconds
/// (well under a millisecond of CPU).
pub fn record_simulation_until(
    scenario: &Scenario,
    duration: Option<f64>,
    out: &Path,
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
    let object_json = serde_json::to_string(&scenario.object).unwrap_or_default();
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
            ("grasp_style".to_owned(), format!("{:?}", sim.style())),
        ]),
        phases: sim
            .phases()
            .iter()
            .map(|s| GroundTruthPhase {
                name: s.phase.name().to_owned(),
                start_ns: s.start_ns,
                end_ns: s.end_ns,
            })
            .collect(),
        started_at: None,
        table_height: Some(sim.table_height()),
    };
    let dfs = sim.dfs();
    let recorder = SessionRecorder::create(out, dfs.hand(), dfs.object(), &info)?;
    record_ticks_until(&mut sim, recorder, progress, stop)
}

/// Steps `sim` to its end, recording every tick with `recorder`, then finishes the file.
/// `progress(done, total)` is called every 100 ticks and at the end. If the simulation or a
/// write fails midway, the file is still finished with every tick recorded before it.
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
