//! What the web page draws in 3D: a hand's links at rest (`GET /api/v1/hands/{id}/geometry`)
//! and a replay's frames (`GET /api/v1/replays/{id}/frames`): the hand's links, the object and
//! the contact forces, sampled from the replay's recording at a bounded rate as compact JSON.

use axum::extract::State;
use dfs_core::hand::{HandModel, Kinematics, LinkShape, Primitive, ShapeSource};
use dfs_core::math::{Isometry, Point, Rotation, Vector};
use serde::{Deserialize, Serialize};
use services::error::Result as RecordingResult;
use services::mcap_io::ReadLimits;
use services::session::{
    hand_shapes, stream_session_file, Contacts, DecodeTopics, GloveJointStates, ObjectState,
    SessionVisitor,
};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::{Id, Name, Query};
use super::state::AppState;

/// A pose: position (m) then orientation as a unit quaternion, `[x, y, z, qx, qy, qz, qw]`.
pub type Pose7 = [f64; 7];

/// One solid of a link, in the link's frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Solid {
    /// `box`, `cylinder` (along its z) or `sphere`.
    pub kind: String,
    /// Box: side lengths; cylinder: `[radius, length]`; sphere: `[radius]` (m).
    pub size: Vec<f64>,
    /// Its pose in the link frame, `[x, y, z, qx, qy, qz, qw]`.
    #[schema(value_type = Vec<f64>, min_items = 7, max_items = 7)]
    pub pose: Pose7,
    /// A fingertip's contact sphere.
    pub fingertip: bool,
}

/// One link of a hand with its solids.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct LinkGeometry {
    /// Link name.
    pub name: String,
    /// Its pose in the base frame with every joint at its rest value (0, or the nearest
    /// limit), `[x, y, z, qx, qy, qz, qw]`.
    #[schema(value_type = Vec<f64>, min_items = 7, max_items = 7)]
    pub pose: Pose7,
    /// Its solids, in the link frame.
    pub shapes: Vec<Solid>,
}

/// A hand's links at rest, for drawing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HandGeometry {
    /// Hand name.
    pub name: String,
    /// Its links.
    pub links: Vec<LinkGeometry>,
    /// The centre of the links' origins (m), where a view looks.
    #[schema(value_type = Vec<f64>, min_items = 3, max_items = 3)]
    pub centre: [f64; 3],
}

/// Parameters of `GET /replays/{id}/frames`.
#[derive(Debug, Clone, Default, Deserialize, IntoParams)]
#[serde(default, deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct FramesParams {
    /// Frames per second of recording, 1 to 100 (default 30).
    #[param(minimum = 1, maximum = 100)]
    pub fps: Option<u32>,
}

/// One contact force of a frame, world frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct FrameContact {
    /// Index of the fingertip (the hand's order).
    pub finger: usize,
    /// Contact point (m).
    #[schema(value_type = Vec<f64>, min_items = 3, max_items = 3)]
    pub point: [f64; 3],
    /// Force of the fingertip on the object (N).
    #[schema(value_type = Vec<f64>, min_items = 3, max_items = 3)]
    pub force: [f64; 3],
}

/// A replay's recording as frames: link and object poses and contact forces, world frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ReplayFrames {
    /// The replay.
    pub replay_id: i64,
    /// The hand.
    pub hand: String,
    /// Fingertip names, in the hand's order.
    pub fingers: Vec<String>,
    /// The hand's links and their solids (in the link frames; `pose` at rest).
    pub links: Vec<LinkGeometry>,
    /// Time of each frame, s since the recording's start.
    pub time_s: Vec<f64>,
    /// The object's pose at each frame, `[x, y, z, qx, qy, qz, qw]`.
    #[schema(value_type = Vec<Vec<f64>>)]
    pub object_pose: Vec<Pose7>,
    /// Each link's pose at each frame (`[frame][link]`, the order of `links`).
    #[schema(value_type = Vec<Vec<Vec<f64>>>)]
    pub link_poses: Vec<Vec<Pose7>>,
    /// The transmitting contacts at each frame.
    pub contacts: Vec<Vec<FrameContact>>,
}

/// The routes of this module.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(hand_geometry))
        .routes(routes!(replay_frames))
}

/// `x` rounded to `1 / per_unit` (dividing, so 0.009 stays 0.009, not 0.009000000000000001).
fn round(x: f64, per_unit: f64) -> f64 {
    (x * per_unit).round() / per_unit
}

fn pose7(iso: &Isometry) -> Pose7 {
    let t = iso.translation.vector;
    let q = iso.rotation.coords; // (i, j, k, w)
                                 // 0.1 mm and 1e-5: far below what a view shows, a third of the JSON.
    [
        round(t.x, 1e4),
        round(t.y, 1e4),
        round(t.z, 1e4),
        round(q.x, 1e5),
        round(q.y, 1e5),
        round(q.z, 1e5),
        round(q.w, 1e5),
    ]
}

fn solid(s: &LinkShape) -> Solid {
    let (kind, size) = match s.primitive {
        Primitive::Box { size } => ("box", vec![size.x, size.y, size.z]),
        Primitive::Cylinder { radius, length } => ("cylinder", vec![radius, length]),
        Primitive::Sphere { radius } => ("sphere", vec![radius]),
    };
    Solid {
        kind: kind.to_owned(),
        size,
        pose: pose7(&s.origin),
        fingertip: s.source == ShapeSource::Fingertip,
    }
}

/// The links of `hand` with their solids and their poses at rest.
fn links_of(hand: &HandModel, urdf: Option<&str>) -> Vec<LinkGeometry> {
    let shapes = hand_shapes(hand, urdf);
    let mut q = vec![0.0; hand.dof()];
    hand.clamp_to_limits(&mut q);
    let mut kin = Box::<Kinematics>::default();
    hand.forward_kinematics(&Isometry::identity(), &q, &mut kin);
    hand.links
        .iter()
        .enumerate()
        .map(|(l, link)| LinkGeometry {
            name: link.name.clone(),
            pose: pose7(&kin.link_poses[l]),
            shapes: shapes.iter().filter(|s| s.link == l).map(solid).collect(),
        })
        .collect()
}

/// A hand's links and solids at rest (every joint at 0 or its nearest limit), base at the
/// origin.
#[utoipa::path(get, path = "/hands/{id}/geometry", tag = "hands",
    params(("id" = String, Path, description = "Hand name")),
    responses(
        (status = 200, description = "The hand's links and their solids", body = HandGeometry),
        (status = 404, description = "No hand of this name", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn hand_geometry(
    State(st): State<AppState>,
    Name(name): Name,
) -> Result<axum::Json<HandGeometry>, Problem> {
    let hand = st.store().get_hand(&name).await?;
    let loaded = hand.load()?;
    let links = links_of(&loaded.model, loaded.urdf.as_deref());
    let n = links.len().max(1) as f64;
    let mut centre = [0.0; 3];
    for l in &links {
        for (c, p) in centre.iter_mut().zip(&l.pose[..3]) {
            *c += p / n;
        }
    }
    Ok(axum::Json(HandGeometry {
        name: loaded.model.name.clone(),
        links,
        centre,
    }))
}

/// A replay's recording as frames for drawing: the hand's links, the object and the contact
/// forces at `fps` frames per second of the recording.
#[utoipa::path(get, path = "/replays/{id}/frames", tag = "replays",
    params(("id" = i64, Path, description = "Replay id"), FramesParams),
    responses(
        (status = 200, description = "The replay's frames", body = ReplayFrames),
        (status = 400, description = "The id is not an integer, fps is out of range, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No replay with this id, or its file is missing", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn replay_frames(
    State(st): State<AppState>,
    Id(id): Id,
    Query(p): Query<FramesParams>,
) -> Result<axum::Json<ReplayFrames>, Problem> {
    let fps = p.fps.unwrap_or(30);
    if !(1..=100).contains(&fps) {
        return Err(Problem::bad_request(format!(
            "fps {fps} is outside 1..=100"
        )));
    }
    let replay = st.store().get_replay(id).await?;
    let hand = st.store().get_hand(&replay.hand).await?.load()?;
    let path = st.store().replay_blob_path(id).await?;
    let _turn = st.ingest_turn().await?;
    let hand_name = replay.hand.clone();
    let frames = tokio::task::spawn_blocking(move || {
        let links = links_of(&hand.model, hand.urdf.as_deref());
        let mut v = Frames::new(hand.model, 1_000_000_000 / u64::from(fps));
        stream_session_file(&path, &ReadLimits::default(), &mut v).map(|_| (v, links))
    })
    .await
    .map_err(|e| Problem::internal(&e))?;
    let (v, links) = frames.map_err(|e| Problem::stored_recording(&format!("replay {id}"), e))?;
    Ok(axum::Json(ReplayFrames {
        replay_id: id,
        hand: hand_name,
        fingers: v.hand.fingertips.iter().map(|t| t.name.clone()).collect(),
        links,
        time_s: v.time_s,
        object_pose: v.object_pose,
        link_poses: v.link_poses,
        contacts: v.contacts_out,
    }))
}

fn iso(p: &services::foxglove::Pose) -> Isometry {
    let o = &p.orientation;
    let q = nalgebra::Quaternion::new(o.w, o.x, o.y, o.z);
    let r = if q.norm() > 1e-9 {
        Rotation::from_quaternion(q)
    } else {
        Rotation::identity()
    };
    Isometry::from_parts(
        nalgebra::Translation3::new(p.position.x, p.position.y, p.position.z),
        r,
    )
}

/// The visitor sampling frames from a replay recording: the latest joint angles and contacts
/// at each `/object/state` sample on or after the next frame's time.
struct Frames {
    hand: HandModel,
    period_ns: u64,
    origin_ns: Option<u64>,
    next_ns: u64,
    q: Vec<f64>,
    contacts: Option<Contacts>,
    kin: Box<Kinematics>,
    time_s: Vec<f64>,
    object_pose: Vec<Pose7>,
    link_poses: Vec<Vec<Pose7>>,
    contacts_out: Vec<Vec<FrameContact>>,
}

impl Frames {
    fn new(hand: HandModel, period_ns: u64) -> Self {
        let dof = hand.dof();
        Frames {
            hand,
            period_ns: period_ns.max(1),
            origin_ns: None,
            next_ns: 0,
            q: vec![0.0; dof],
            contacts: None,
            kin: Box::default(),
            time_s: Vec::new(),
            object_pose: Vec::new(),
            link_poses: Vec::new(),
            contacts_out: Vec::new(),
        }
    }
}

impl SessionVisitor for Frames {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics {
            joint_states: true,
            feedback: false,
            contacts: true,
            object: true,
        }
    }

    fn joint_states(&mut self, _t: u64, m: &GloveJointStates) -> RecordingResult<()> {
        for (q, p) in self.q.iter_mut().zip(&m.positions) {
            *q = *p;
        }
        Ok(())
    }

    fn contacts(&mut self, _t: u64, m: &Contacts) -> RecordingResult<()> {
        match &mut self.contacts {
            Some(c) => c.clone_from(m),
            None => self.contacts = Some(m.clone()),
        }
        Ok(())
    }

    fn object(&mut self, t: u64, m: &ObjectState) -> RecordingResult<()> {
        let origin = *self.origin_ns.get_or_insert(t);
        let since = t.saturating_sub(origin);
        if since < self.next_ns {
            return Ok(());
        }
        self.next_ns = since + self.period_ns;
        let object = iso(&m.pose);
        let base = object * iso(&m.pose_in_hand).inverse();
        self.hand.forward_kinematics(&base, &self.q, &mut self.kin);
        self.time_s.push(round(since as f64 * 1e-9, 1e3));
        self.object_pose.push(pose7(&object));
        self.link_poses.push(
            (0..self.hand.links.len())
                .map(|l| pose7(&self.kin.link_poses[l]))
                .collect(),
        );
        let mut out = Vec::new();
        for (k, f) in self
            .contacts
            .iter()
            .flat_map(|c| c.fingers.iter())
            .enumerate()
        {
            if !f.in_contact || f.object != m.index {
                continue;
            }
            let p = object * Point::new(f.point_b.x, f.point_b.y, f.point_b.z);
            // The transmitted intensities are in the contact frame, whose tangent axes the
            // recording does not hold: the arrow is along the normal (into the object), as
            // long as the whole force.
            let n = object.rotation * Vector::new(f.normal_b.x, f.normal_b.y, f.normal_b.z);
            let tr = &f.transmitted;
            let magnitude = (tr.x * tr.x + tr.y * tr.y + tr.z * tr.z).sqrt();
            let v = n * magnitude;
            out.push(FrameContact {
                finger: k,
                point: [round(p.x, 1e4), round(p.y, 1e4), round(p.z, 1e4)],
                force: [round(v.x, 1e3), round(v.y, 1e3), round(v.z, 1e3)],
            });
        }
        self.contacts_out.push(out);
        Ok(())
    }
}
