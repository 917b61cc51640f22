//! Segmentation of a session into skills (one per grasp) and their hand-independent
//! parameters, and scoring against ground truth.
//!
//! # Method
//!
//! The primary cue is the motion of the hand's base link, `base = object pose ∘ pose_in_hand⁻¹`,
//! resampled by timestamp onto a 1 ms grid (dropped samples are interpolated). Its speed
//! (linear plus [`SegmentParams::rotation_radius`] × angular, central differences over
//! ±[`SegmentParams::speed_window_s`]) is thresholded with hysteresis into *moves*; moves that
//! are too short or too small are dropped. A hand move is close to a minimum-jerk profile, so
//! each move's start and end are refined from its progress curve: the times at which it has
//! covered 10 %, 50 % and 90 % of its displacement give its centre and duration (for a
//! minimum-jerk profile the 10-90 % time is 50.7 % of the whole), which is much less biased
//! than a speed threshold. The thresholds cut off a move's slow start and end, which for a long,
//! gentle move (a retreat that `--duration` stretches over the rest of the session) is seconds:
//! each fast move extends outward while the speed over a 3× wider window (the one a second pass
//! uses to find slow moves in the rests) stays above a quarter of the exit threshold, and the
//! progress window is widened to the fitted start and end (within
//! the rests around the move) and fitted again until it holds the whole move. A rest whose ends
//! are [`SegmentParams::slow_move_m`] apart holds a move too slow for either threshold.
//!
//! Contact *episodes* (at least two fingers transmitting force, with minimum duration and gap
//! merging) are the candidate grasps; a single finger bumping into the object is not one.
//!
//! # What counts as a grasp
//!
//! An episode yields a skill only if its contacts carried the object: while at least two
//! fingertips transmitted force, the object moved [`SegmentParams::min_carry_m`] (5 mm) or more
//! from where it was when they closed on it, and moved with the hand (its displacement relative
//! to the hand's base less than half its displacement in the world); and the skill has at least
//! two contacts (fingertips touching for 30 % of the held part) that oppose each other (mean
//! normals more than 90° apart). Fingers that squeeze an object they cannot lift (too heavy, too small, μ = 0),
//! or push or knock it away, make no skill: such a session is stored with zero skills. An object
//! lifted and then dropped (`box-slip`) is a grasp: it was carried.
//!
//! Around each episode the moves and the rests between them are labelled by a small
//! grammar: moves before the first touch are `approach` (and the last of two or more is
//! `preshape`); the rest from the last of them to the first move in contact is `grasp`; moves in
//! contact are `lift` (mostly up), `place` (mostly down) or `transport` (otherwise, or a turn);
//! rests between them are `hold`, the rest after a `place` is `release`; the first move after
//! the episode is `retreat`. The object's motion is not needed for the boundaries.

use std::collections::BTreeMap;

use dfs_core::contact::{ContactFrame, ContactModel, Friction};
use dfs_core::grasp::quality::{grasp_quality, QualityParams};
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::object::{Shape, ShapeKind};
use dfs_core::scenario::{Phase, ScenarioObject};
use dfs_core::DfsError;
use serde::{Deserialize, Serialize};

use crate::error::RecordingError;
use crate::foxglove::Pose;
use crate::mcap_io::ReadLimits;
use crate::session::{
    ContactPart, Contacts, DecodeTopics, GroundTruthPhase, KeptMessages, ObjectState, Session,
    SessionHead, SessionSource, SessionVisitor, KEPT_MESSAGES_BUDGET, MAX_SESSION_OBJECTS,
};

/// Version of the segmentation: what the store records beside every session's skills, so
/// that `icms reprocess` can find the sessions whose skills an older segmentation made and
/// segment them again ([`crate::reprocess`]).
///
/// Bump it with any change that alters the skills stored for a session file already in a data
/// base: what [`segment`] finds (the method, [`SegmentParams`]' defaults, what counts as a
/// grasp, the phases), any parameter it computes or the physics behind one (grasp quality,
/// friction margins, slip, the feature vector and its [`FEATURE_DIMENSIONS`]), the JSON of
/// [`Skill`], how `crate::ingest` maps a skill to the store's columns (grasp type labels, ...),
/// or how a stored file is read into what segmentation sees (decoding, units). Do not bump it
/// for changes that leave every stored skill byte for byte the same (refactors, speed): a
/// bump makes `icms reprocess` read and segment every stored session again; skills that come
/// out the same are kept (ids and replays too), so a needless bump costs time, not data.
///
/// Version 0 stands for "not recorded": the sessions stored before versions were (migration
/// `0003`), which reprocessing checks against the current segmentation.
///
/// History: 1, the segmentation of issue 18 when versions began to be recorded; 2, the
/// approach templates recognition compares (issue 20, `crate::assist`), computed at ingest
/// with the skills (a skill that comes out the same keeps its id and replays and gets its
/// template).
pub const SEGMENTATION_VERSION: u32 = 2;

/// Tuning of [`segment`]. The defaults suit human-speed grasping at any sample rate ≥ 100 Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentParams {
    /// Grid step of the resampled signals (s). Default 0.001.
    pub grid_s: f64,
    /// Half width of the central difference for the speed (s). Default 0.015.
    pub speed_window_s: f64,
    /// Length that turns angular speed into a linear speed (m). Default 0.1.
    pub rotation_radius: f64,
    /// A move starts above this speed (m/s). Default 0.008.
    pub move_enter_speed: f64,
    /// A move ends below this speed (m/s). Default 0.003.
    pub move_exit_speed: f64,
    /// Shortest move (s). Default 0.08.
    pub min_move_s: f64,
    /// Smallest move displacement (m, rotations counted × `rotation_radius`). Default 0.0015.
    pub min_move_m: f64,
    /// A rest between the moves found by speed whose ends are this far apart (m) holds a move
    /// too slow for the speed thresholds. Default 0.005.
    pub slow_move_m: f64,
    /// Shortest contact episode (s). Default 0.1.
    pub min_contact_s: f64,
    /// Contact gaps shorter than this are bridged (s). Default 0.3.
    pub contact_gap_s: f64,
    /// A move with |vertical| / |displacement| above this is a lift or a place. Default 0.6.
    pub vertical_fraction: f64,
    /// Points of the resampled grip-force profile. Default 50.
    pub profile_points: usize,
    /// Key poses of the object's motion every this many seconds (plus phase boundaries).
    /// Default 0.25.
    pub keyframe_s: f64,
    /// A grasp must carry the object at least this far (m) from where the fingers closed on
    /// it, see [`segment`]. Default 0.005.
    pub min_carry_m: f64,
}

impl Default for SegmentParams {
    fn default() -> Self {
        SegmentParams {
            grid_s: 0.001,
            speed_window_s: 0.015,
            rotation_radius: 0.1,
            move_enter_speed: 0.008,
            move_exit_speed: 0.003,
            min_move_s: 0.08,
            min_move_m: 0.0015,
            slow_move_m: 0.005,
            min_contact_s: 0.1,
            contact_gap_s: 0.3,
            vertical_fraction: 0.6,
            profile_points: 50,
            keyframe_s: 0.25,
            min_carry_m: 0.005,
        }
    }
}

/// A phase found by [`segment`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PhaseSpan {
    /// The phase (`approach`, `preshape`, `grasp`, `lift`, `hold`, `transport`, `place`,
    /// `release`, `retreat`).
    pub name: Phase,
    /// Start, ns since the session's start (the log time of its first `/object/state` sample:
    /// 0 in the files `icms simulate` records, later for recorders that log epoch times).
    pub start_ns: u64,
    /// End (exclusive), ns since the session start.
    pub end_ns: u64,
}

/// The result of [`segment`]: one skill per grasp, in time order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segmentation {
    /// The skills.
    pub skills: Vec<Skill>,
}

/// One grasp of a session: its phases and its hand-independent parameters.
///
/// Its JSON is what `icms segment --json` prints in `skills`, what the store keeps as a skill's
/// `params` and what `icms replay --skill FILE` reads. Read back ([`Skill::from_json`]), a skill
/// may leave out what replay does not use (a skill file written by hand): every parameter but
/// `phases`, `contact_model` and `contacts` has a default (empty, zero, or absent), and so
/// have a contact's `finger`, `mean_intensity` and `grip_profile` and the object's `inertia`
/// and `mu_torsion`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skill {
    /// Phases, in time order, never overlapping (nor the phases of other skills), inside the
    /// session; contiguous except where odd data leaves a gap.
    pub phases: Vec<PhaseSpan>,
    /// The skill's parameters (flattened into the skill's JSON).
    #[serde(flatten)]
    pub parameters: SkillParameters,
}

impl Skill {
    /// A skill from its JSON (see [`Skill`]); an error names the path of the field that is
    /// wrong (`object.shape`, `phases[2].name`: serde's flattening loses the path of the
    /// parameters' fields, so they are read on their own).
    pub fn from_json(
        value: &serde_json::Value,
    ) -> Result<Skill, serde_path_to_error::Error<serde_json::Error>> {
        /// The one field of a skill that is not a parameter.
        #[derive(Deserialize)]
        struct Phases {
            phases: Vec<PhaseSpan>,
        }
        let Phases { phases } = serde_path_to_error::deserialize(value)?;
        let parameters = serde_path_to_error::deserialize(value)?;
        Ok(Skill { phases, parameters })
    }
}

/// The object as the session's metadata describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectParams {
    /// Its name in the session's scene, when the session names its objects (a scene of
    /// several: the `objects` of the `session` metadata record; or a named `object`): the
    /// object the skill grasped, the one its contacts pushed. Absent for a session's one
    /// unnamed object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// `sphere`, `box` or `cylinder`.
    pub shape: ShapeKind,
    /// Size (m): `[radius]` (sphere), half extents (box), `[radius, half_height]` (cylinder),
    /// as [`Shape::sizes`] lists them.
    pub size: Vec<f64>,
    /// Mass (kg).
    pub mass: f64,
    /// Principal moments of inertia about B's axes (kg·m²), solid body of uniform density
    /// ([`Shape::principal_inertia`]). Zero when a skill file leaves it out (replay takes the
    /// inertia from the shape and mass).
    #[serde(default)]
    pub inertia: [f64; 3],
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Torsional friction coefficient (m). Default 0.
    #[serde(default)]
    pub mu_torsion: f64,
}

impl ObjectParams {
    /// The shape with its sizes, validated; an error names `object.size` when the list does
    /// not fit the shape, the size (`object.radius`, ...) when one is not a length > 0.
    pub fn to_shape(&self) -> Result<Shape, DfsError> {
        Shape::from_sizes(self.shape, &self.size, "object.size")
    }
}

/// One contact of a skill, in the object frame B.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    /// Fingertip of the recording hand, or its palm or phalanx contact shape (provenance
    /// only; the skill does not depend on it).
    #[serde(default)]
    pub finger: String,
    /// Which part of the hand held the object there: a fingertip (absent: as every skill
    /// before whole-hand contact), the palm or a phalanx.
    #[serde(default, skip_serializing_if = "ContactPart::is_fingertip")]
    pub part: ContactPart,
    /// Mean contact point in B over the held part of the grasp (m).
    pub position_b: [f64; 3],
    /// Mean unit normal in B, pointing into the object.
    pub normal_b: [f64; 3],
    /// Mean intensities `[x, y, normal, torsion]` (N, N·m) per phase, while touching.
    #[serde(default)]
    pub mean_intensity: BTreeMap<Phase, [f64; 4]>,
    /// Normal force (N) resampled to [`SegmentParams::profile_points`] points over the span from
    /// the start of `grasp` to the end of `release` (or of the last phase in contact).
    #[serde(default)]
    pub grip_profile: Vec<f64>,
}

/// A slip of one contact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlipEvent {
    /// Start, s since the start of `grasp`.
    pub time_s: f64,
    /// Fingertip.
    pub finger: String,
    /// Duration (s).
    pub duration_s: f64,
}

/// A key pose of the object relative to its pose at the start of the grasp (frame B₀).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPose {
    /// Time since the start of `grasp` (s).
    pub time_s: f64,
    /// Position of B in B₀ (m).
    pub position: [f64; 3],
    /// Rotation of B relative to B₀ as a rotation vector (rad).
    pub rotation: [f64; 3],
}

/// Grasp quality (GraspIt!): Ferrari-Canny ε and the volume of the grasp wrench space with
/// 8-edge linearised friction cones, on the mean contacts with the object's μ and μ_t and the
/// recording's contact model (soft finger: with point contacts with friction a two-finger pinch
/// is never force closure), torques divided by the object's half diagonal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QualityParamsOut {
    /// Ferrari-Canny ε (0 when not force closure).
    pub epsilon: f64,
    /// Volume of the grasp wrench space.
    pub volume: f64,
    /// The grasp is force closure.
    pub force_closure: bool,
}

/// Grasp type label.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GraspType {
    /// `power` when the palm holds the object (whole-hand contact); otherwise, as for every
    /// fingertip grasp, `precision` with ≤ 3 contacts and `power` with more.
    pub label: String,
    /// Number of virtual fingers: the palm's contacts as one, and the other contacts in groups
    /// of similar normals (within 60°); 2 for a pinch. 0 without contacts.
    pub opposing_virtual_fingers: usize,
}

/// Where a skill comes from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SkillSource {
    /// Scenario (or imported file) name.
    pub scenario: String,
    /// Seed, if simulated.
    pub seed: Option<u64>,
    /// The session's `hand` and `source` metadata.
    pub metadata: BTreeMap<String, String>,
    /// Start of the skill's first phase (ns since the session start).
    pub start_ns: u64,
    /// End of the skill's last phase (ns since the session start).
    pub end_ns: u64,
}

/// The parameters of a skill, in the object frame B and independent of the hand. Read back,
/// every field but `contact_model` and `contacts` may be left out (see [`Skill`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillParameters {
    /// The object (absent when the metadata does not describe it).
    #[serde(default)]
    pub object: Option<ObjectParams>,
    /// Contact model of the recording (`soft_finger`: point contact with friction and torsion).
    pub contact_model: ContactModel,
    /// Number of contacts.
    #[serde(default)]
    pub contact_count: usize,
    /// The contacts.
    pub contacts: Vec<ContactParams>,
    /// Mean sum of the normal forces while the object is held (N).
    #[serde(default)]
    pub internal_force_n: f64,
    /// Smallest `μ c_n − |c_t|` over the held part of the grasp (`lift` to `place`, or the
    /// whole grasp if the object was never lifted), on contacts pushing with more than 0.05 N
    /// (N); negative when a contact left its cone.
    #[serde(default)]
    pub friction_margin_n: f64,
    /// The same as a ratio `(μ c_n − |c_t|) / (μ c_n)` (1 = pure normal force, ≤ 0 = slip).
    #[serde(default)]
    pub friction_margin_ratio: f64,
    /// The object's motion relative to its pose at the start of `grasp`: key poses at every
    /// phase boundary and every [`SegmentParams::keyframe_s`] in between.
    #[serde(default)]
    pub motion: Vec<KeyPose>,
    /// Duration of each phase (s; summed when a phase repeats), by phase name.
    #[serde(default)]
    pub phase_durations: BTreeMap<Phase, f64>,
    /// Slip events: runs of ≥ 2 ms in which a touching contact's requested intensities were
    /// outside its friction cone, merged per finger when less than 20 ms apart.
    #[serde(default)]
    pub slip_events: Vec<SlipEvent>,
    /// Grasp quality on the mean contacts (absent without contacts or μ).
    #[serde(default)]
    pub quality: Option<QualityParamsOut>,
    /// Grasp type.
    #[serde(default)]
    pub grasp_type: GraspType,
    /// Source session and span.
    #[serde(default)]
    pub source: SkillSource,
    /// Feature vector for similarity search, see [`FEATURE_DIMENSIONS`].
    #[serde(default)]
    pub feature: [f32; 16],
}

/// Meaning of each dimension of [`SkillParameters::feature`].
pub const FEATURE_DIMENSIONS: [&str; 16] = [
    "ln(mass / 1 kg)",
    "mu",
    "contact count",
    "Ferrari-Canny epsilon",
    "grasp wrench space volume^(1/6)",
    "internal force / weight",
    "hold duration (s)",
    "lift height of the object (m)",
    "horizontal transport distance of the object (m)",
    "largest rotation of the object (rad)",
    "mean |normal_b.x| of the contacts",
    "mean |normal_b.y| of the contacts",
    "mean |normal_b.z| of the contacts",
    "shape is sphere (0/1)",
    "shape is box (0/1)",
    "shape is cylinder (0/1)",
];

/// Score of a segmentation against ground truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// Absolute boundary errors (ms) of the found truth phases: start and end of each, except
    /// boundaries at the session's start (0) and at the truth's last end.
    pub boundary_errors_ms: Vec<f64>,
    /// Median of `boundary_errors_ms` (0 when empty).
    pub median_boundary_error_ms: f64,
    /// Fraction of truth phases found: a phase of the same name overlaps it by more than 50 %
    /// of its duration (1 when there is no truth).
    pub phases_found_fraction: f64,
}

/// Scores found phases against ground truth (see [`Score`]).
pub fn score(found: &[PhaseSpan], truth: &[GroundTruthPhase]) -> Score {
    let last_end = truth.iter().map(|p| p.end_ns).max().unwrap_or(0);
    let mut errors = Vec::new();
    let mut n_found = 0;
    for t in truth {
        let len = t.end_ns.saturating_sub(t.start_ns).max(1);
        let name = t.name.parse::<Phase>().ok();
        let best = found
            .iter()
            .filter(|f| Some(f.name) == name)
            .map(|f| {
                let ov = f
                    .end_ns
                    .min(t.end_ns)
                    .saturating_sub(f.start_ns.max(t.start_ns));
                (ov, f)
            })
            .max_by_key(|(ov, _)| *ov);
        if let Some((ov, f)) = best {
            if ov * 2 > len {
                n_found += 1;
                if t.start_ns > 0 {
                    errors.push((f.start_ns as f64 - t.start_ns as f64).abs() * 1e-6);
                }
                if t.end_ns < last_end {
                    errors.push((f.end_ns as f64 - t.end_ns as f64).abs() * 1e-6);
                }
            }
        }
    }
    let median = median(&mut errors.clone());
    Score {
        boundary_errors_ms: errors,
        median_boundary_error_ms: median,
        phases_found_fraction: if truth.is_empty() {
            1.0
        } else {
            n_found as f64 / truth.len() as f64
        },
    }
}

/// Median of values (0 when empty); reorders `v`.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A recorded pose as an isometry (a zero quaternion as the identity rotation).
pub(crate) fn iso(p: &Pose) -> Isometry {
    let q = nalgebra::Quaternion::new(
        p.orientation.w,
        p.orientation.x,
        p.orientation.y,
        p.orientation.z,
    );
    let r = if q.norm() > 1e-9 {
        Rotation::from_quaternion(q)
    } else {
        Rotation::identity()
    };
    Isometry::from_parts(
        Vector::new(p.position.x, p.position.y, p.position.z).into(),
        r,
    )
}

/// Signals resampled onto the uniform grid: for an hour at 1 ms, 3.6 million points of 41
/// bytes (the orientation in `f32`: 16 bytes rather than 32, its angles still good to 1e-7
/// rad, see [`Grid::angle`]).
struct Grid {
    t0: u64,
    dt_ns: u64,
    base_p: Vec<Vector>,
    base_r: Vec<[f32; 4]>,
    touching: Vec<bool>,
}

impl Grid {
    fn len(&self) -> usize {
        self.base_p.len()
    }

    /// The hand base's orientation at grid point `i`.
    fn rot(&self, i: usize) -> Rotation {
        let [x, y, z, w] = self.base_r[i].map(f64::from);
        Rotation::new_normalize(nalgebra::Quaternion::new(w, x, y, z))
    }

    /// The angle (rad) between the orientations at grid points `a` and `b`, from the
    /// relative rotation's vector part and scalar (atan2: no loss near 0, unlike the acos of
    /// a dot product, which turns the `f32` storage's 1e-7 into 1e-3 rad).
    fn angle(&self, a: usize, b: usize) -> f64 {
        (self.rot(a).inverse() * self.rot(b)).angle()
    }
}

/// Time after the latest contact sample during which its state holds (ns): over a longer hole
/// in the data the hand is taken as not touching.
const CONTACT_HOLD_NS: u64 = 50_000_000;

/// A run of contact samples with the same "two fingers or more in contact" state and no hole
/// of [`CONTACT_HOLD_NS`] between them: from its first sample's log time to its last's.
#[derive(Debug, Clone, Copy)]
struct ContactRun {
    start: u64,
    end: u64,
    on: bool,
    /// Per object of the scene: how many of the run's samples had most of their transmitting
    /// fingertips on it.
    objects: [u32; MAX_SESSION_OBJECTS],
}

/// The object most of `c`'s transmitting fingertips push (the lowest index of a tie).
fn pushed_object(c: &Contacts) -> usize {
    let mut count = [0u32; MAX_SESSION_OBJECTS];
    for f in c.fingers.iter().filter(|f| f.in_contact) {
        count[(f.object as usize).min(MAX_SESSION_OBJECTS - 1)] += 1;
    }
    argmax(&count)
}

/// The index of the largest count (the lowest of a tie).
fn argmax<T: PartialOrd>(count: &[T]) -> usize {
    let mut best = 0;
    for (i, n) in count.iter().enumerate() {
        if *n > count[best] {
            best = i;
        }
    }
    best
}

/// Pass one of segmentation: the hand base's pose resampled onto the grid as object samples
/// come (in time order), and the contact state as runs. Holds the grid and the last two
/// samples, whatever the session's length.
struct GridBuilder {
    dt_ns: u64,
    /// The last two finite samples: (log time, base pose).
    last: [Option<(u64, Isometry)>; 2],
    /// Log time of the next grid point to fill.
    next: u64,
    t0: Option<u64>,
    base_p: Vec<Vector>,
    base_r: Vec<[f32; 4]>,
    runs: Vec<ContactRun>,
}

impl GridBuilder {
    fn new(params: &SegmentParams) -> Self {
        GridBuilder {
            dt_ns: ((params.grid_s * 1e9) as u64).max(1),
            last: [None, None],
            next: 0,
            t0: None,
            base_p: Vec::new(),
            base_r: Vec::new(),
            runs: Vec::new(),
        }
    }

    /// Fills the grid points before `until` (or up to it, with `inclusive`) from the segment
    /// between the last two samples.
    fn fill(&mut self, until: u64, inclusive: bool) {
        let (Some((ta, a)), Some((tb, b))) = (self.last[0], self.last[1]) else {
            return;
        };
        while self.next < until || (inclusive && self.next == until) {
            let t = self.next;
            let s = if tb > ta {
                // In offsets: epoch-based log times (1.7e18 ns) lose 256 ns as f64.
                (t.saturating_sub(ta) as f64 / (tb - ta) as f64).clamp(0.0, 1.0)
            } else {
                0.0
            };
            self.base_p
                .push(a.translation.vector.lerp(&b.translation.vector, s));
            let q = a.rotation.nlerp(&b.rotation, s);
            self.base_r
                .push([q.i as f32, q.j as f32, q.k as f32, q.w as f32]);
            self.next += self.dt_ns;
        }
    }

    /// An `/object/state` sample: the base pose is `pose ∘ pose_in_hand⁻¹`.
    fn object(&mut self, t: u64, o: &ObjectState) {
        let base = iso(&o.pose) * iso(&o.pose_in_hand).inverse();
        if !base.translation.vector.iter().all(|v| v.is_finite()) {
            return;
        }
        if self.t0.is_none() {
            self.t0 = Some(t);
            self.next = t;
        }
        // The grid points before this sample lie between the last one and it.
        self.last = [self.last[1], Some((t, base))];
        if self.last[0].is_some() {
            self.fill(t, false);
        }
    }

    /// A `/dfs/contacts` sample: two fingers or more in contact, or not.
    fn contacts(&mut self, t: u64, c: &Contacts) {
        let on = c.fingers.iter().filter(|f| f.in_contact).count() >= 2;
        match self.runs.last_mut() {
            Some(r) if r.on == on && t.saturating_sub(r.end) < CONTACT_HOLD_NS => r.end = t,
            _ => self.runs.push(ContactRun {
                start: t,
                end: t,
                on,
                objects: [0; MAX_SESSION_OBJECTS],
            }),
        }
        if on {
            if let Some(r) = self.runs.last_mut() {
                r.objects[pushed_object(c)] += 1;
            }
        }
    }

    /// The grid, `None` with fewer than two object samples. Each grid point touches if the
    /// latest contact sample at or before it (or the first one, if it comes within a grid
    /// step) says so and is less than [`CONTACT_HOLD_NS`] old.
    fn finish(mut self) -> Option<Grid> {
        let t0 = self.t0?;
        let (t1, _) = self.last[1]?;
        self.last[0]?;
        self.fill(t1, true);
        let n = self.base_p.len();
        let mut touching = vec![false; n];
        let mut r = 0usize;
        for (i, tv) in touching.iter_mut().enumerate() {
            let t = t0 + i as u64 * self.dt_ns;
            while r + 1 < self.runs.len() && self.runs[r + 1].start <= t {
                r += 1;
            }
            let Some(run) = self.runs.get(r) else {
                break;
            };
            *tv = if run.start > t {
                run.start <= t + self.dt_ns && run.on
            } else {
                run.on && (t <= run.end || t - run.end < CONTACT_HOLD_NS)
            };
        }
        Some(Grid {
            t0,
            dt_ns: self.dt_ns,
            base_p: self.base_p,
            base_r: self.base_r,
            touching,
        })
    }
}

/// The object the contacts of `runs` from `start` to `end` (log times) pushed most: the one a
/// skill of that span grasped (0 in a session of one object).
fn grasped_object(runs: &[ContactRun], start: u64, end: u64) -> usize {
    let mut count = [0u64; MAX_SESSION_OBJECTS];
    for r in runs
        .iter()
        .filter(|r| r.on && r.end >= start && r.start <= end)
    {
        for (c, &n) in count.iter_mut().zip(&r.objects) {
            *c += u64::from(n);
        }
    }
    argmax(&count)
}

/// A move of the hand's base: grid indices of its refined start and end, and its displacement.
#[derive(Debug, Clone, Copy)]
struct Move {
    start: f64,
    end: f64,
    dp: Vector,
    angle: f64,
}

fn speed_profile(g: &Grid, params: &SegmentParams, window_s: f64) -> Vec<f64> {
    let n = g.len();
    let w = ((window_s / params.grid_s).round() as usize).max(1);
    let dt = g.dt_ns as f64 * 1e-9;
    (0..n)
        .map(|i| {
            let a = i.saturating_sub(w);
            let b = (i + w).min(n - 1);
            if b <= a {
                return 0.0;
            }
            let span = (b - a) as f64 * dt;
            let lin = (g.base_p[b] - g.base_p[a]).norm();
            let ang = g.angle(a, b);
            (lin + params.rotation_radius * ang) / span
        })
        .collect()
}

/// Runs of `speed` above `enter` (extended back and forward to where it is below `exit`)
/// inside `[from, to)`.
fn hysteresis(speed: &[f64], enter: f64, exit: f64, from: usize, to: usize) -> Vec<(usize, usize)> {
    let mut raw = Vec::new();
    let mut start: Option<usize> = None;
    for i in from..to {
        let v = speed[i];
        match start {
            None if v > enter => {
                let mut s = i;
                while s > from && speed[s - 1] > exit {
                    s -= 1;
                }
                start = Some(s);
            }
            Some(s) if v < exit => {
                raw.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        raw.push((s, to.saturating_sub(1)));
    }
    raw
}

/// A minimum-jerk fit of the hand's motion over the grid window `[a, b]`: the times (grid
/// indices) at which it covered 10 %, 50 % and 90 % of the window's displacement give the
/// move's start and end. Also the displacement and rotation vector over the window.
struct Fit {
    start: f64,
    end: f64,
    dp: Vector,
    rv: Vector,
}

fn fit_min_jerk(g: &Grid, params: &SegmentParams, a: usize, b: usize, tau10: f64) -> Fit {
    let dp = g.base_p[b] - g.base_p[a];
    let ra = g.rot(a).inverse();
    let rv = (ra * g.rot(b)).scaled_axis();
    let d2 = (dp.norm_squared() + (params.rotation_radius * rv.norm()).powi(2)).max(1e-30);
    // Progress along the window's displacement (translation and rotation together). A
    // rotation under 1 % of the displacement is left out: it changes the progress by less than
    // 1e-4, and its rotations cost most of the time on a long window.
    let turns = (params.rotation_radius * rv.norm()).powi(2) > 1e-4 * d2;
    let progress = |i: usize| -> f64 {
        let p = g.base_p[i] - g.base_p[a];
        let r = if turns {
            params.rotation_radius.powi(2) * (ra * g.rot(i)).scaled_axis().dot(&rv)
        } else {
            0.0
        };
        (p.dot(&dp) + r) / d2
    };
    // First crossings of 10 %, 50 % and 90 %, in one pass.
    let levels = [0.1, 0.5, 0.9];
    let mut at = [b as f64; 3];
    let mut k = 0;
    let mut prev = progress(a);
    for i in a + 1..=b {
        let cur = progress(i);
        while k < 3 && cur >= levels[k] {
            let f = if cur > prev {
                (levels[k] - prev) / (cur - prev)
            } else {
                1.0
            };
            at[k] = (i - 1) as f64 + f.clamp(0.0, 1.0);
            k += 1;
        }
        if k == 3 {
            break;
        }
        prev = cur;
    }
    let [t10, t50, t90] = at;
    let dur = (t90 - t10) / (1.0 - 2.0 * tau10);
    Fit {
        start: t50 - 0.5 * dur,
        end: t50 + 0.5 * dur,
        dp,
        rv,
    }
}

fn find_moves(g: &Grid, params: &SegmentParams) -> Vec<Move> {
    let n = g.len();
    let dt = g.dt_ns as f64 * 1e-9;
    let speed = speed_profile(g, params, params.speed_window_s);
    let mut raw = hysteresis(
        &speed,
        params.move_enter_speed,
        params.move_exit_speed,
        0,
        n,
    );
    // A wider window (less noise) for slow motion, with a quarter of the thresholds.
    let slow = speed_profile(g, params, 3.0 * params.speed_window_s);
    let slow_exit = 0.25 * params.move_exit_speed;
    // A long, gentle move (a retreat stretched over many seconds by `--duration`) spends its
    // first and last seconds below the fast exit speed: extend each fast run outward while the
    // hand is still moving at the slow exit speed, up to its neighbours. Otherwise the slow pass
    // below finds its slow start and end as moves of their own (a 2 mm "retreat" ahead of the
    // real one, which then started 0.7 s late).
    for i in 0..raw.len() {
        let lo = if i > 0 { raw[i - 1].1 } else { 0 };
        let hi = raw.get(i + 1).map_or(n.saturating_sub(1), |r| r.0);
        let (mut a, mut b) = raw[i];
        while a > lo && slow[a - 1] > slow_exit {
            a -= 1;
        }
        while b < hi && slow[b + 1] > slow_exit {
            b += 1;
        }
        raw[i] = (a, b);
    }
    // Second pass for slow, small moves in the rests between the fast ones.
    let margin = (3.0 * params.speed_window_s / params.grid_s) as usize;
    let mut gaps = Vec::new();
    let mut prev = 0usize;
    for &(a, b) in &raw {
        gaps.push((prev, a.saturating_sub(margin)));
        prev = (b + margin).min(n);
    }
    gaps.push((prev, n));
    for (a, b) in gaps {
        if b > a {
            raw.extend(hysteresis(
                &slow,
                0.25 * params.move_enter_speed,
                slow_exit,
                a,
                b,
            ));
        }
    }
    raw.sort_unstable();
    // Last, moves too slow for either threshold (a 0.1 m retreat stretched over two minutes
    // peaks at 1.6 mm/s): a rest between the runs at whose ends the hand is
    // [`SegmentParams::slow_move_m`] apart held a move; the fit below finds it in the rest.
    let mut prev = 0usize;
    let mut slow_moves = Vec::new();
    for &(a, b) in raw.iter().chain(std::iter::once(&(n - 1, n - 1))) {
        if a > prev && (g.base_p[a] - g.base_p[prev]).norm() >= params.slow_move_m {
            slow_moves.push((prev, a));
        }
        prev = prev.max(b);
    }
    if !slow_moves.is_empty() {
        raw.extend(slow_moves);
        raw.sort_unstable();
    }
    let tau10 = dfs_core::min_jerk::time_at_progress(0.1);
    let mut moves = Vec::new();
    for (i, &(a, b)) in raw.iter().enumerate() {
        if (b - a) as f64 * dt < params.min_move_s {
            continue;
        }
        let mut fit = fit_min_jerk(g, params, a, b, tau10);
        let d2 = fit.dp.norm_squared() + (params.rotation_radius * fit.rv.norm()).powi(2);
        if d2.sqrt() < params.min_move_m {
            continue;
        }
        // The thresholds cut off the move's slow start and end, which for a long move can be a
        // large part of it: widen the window to the fit's start and end (plus a quarter of its
        // duration) within the rests around it, and fit again, until it holds the whole move.
        // Rests add nothing to the displacement, so the fit then sees the complete profile.
        let lo = if i > 0 { raw[i - 1].1.min(a) } else { 0 };
        let hi = raw.get(i + 1).map_or(n - 1, |r| r.0.max(b));
        let (mut wa, mut wb) = (a, b);
        for _ in 0..6 {
            let pad = 0.25 * (fit.end - fit.start).max(0.0);
            let na = (fit.start - pad).floor().max(lo as f64) as usize;
            let nb = ((fit.end + pad).ceil().min(hi as f64) as usize).max(na);
            if na >= wa && nb <= wb {
                break;
            }
            (wa, wb) = (wa.min(na), wb.max(nb));
            fit = fit_min_jerk(g, params, wa, wb, tau10);
        }
        let (mut s, mut e) = (fit.start, fit.end);
        // The fit should not move a boundary far outside what the threshold saw.
        let slack = 0.3 * (b - a) as f64;
        s = s.clamp(a as f64 - slack, a as f64 + slack).max(0.0);
        e = e
            .clamp(b as f64 - slack, b as f64 + slack)
            .min((n - 1) as f64);
        moves.push(Move {
            start: s,
            end: e,
            dp: fit.dp,
            angle: fit.rv.norm(),
        });
    }
    // Neighbouring moves must not overlap after refinement.
    for i in 1..moves.len() {
        if moves[i].start < moves[i - 1].end {
            let m = 0.5 * (moves[i].start + moves[i - 1].end);
            moves[i].start = m;
            moves[i - 1].end = m;
        }
    }
    moves
}

fn find_episodes(g: &Grid, params: &SegmentParams) -> Vec<(usize, usize)> {
    let mut eps: Vec<(usize, usize)> = Vec::new();
    let mut start = None;
    for i in 0..=g.len() {
        let on = i < g.len() && g.touching[i];
        match (start, on) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                eps.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    let gap = (params.contact_gap_s / params.grid_s) as usize;
    let mut merged: Vec<(usize, usize)> = Vec::new();
    for e in eps {
        match merged.last_mut() {
            Some(last) if e.0 - last.1 <= gap => last.1 = e.1,
            _ => merged.push(e),
        }
    }
    let min = (params.min_contact_s / params.grid_s) as usize;
    merged.retain(|(a, b)| b - a >= min);
    merged
}

/// The candidate skills of a session whose grid is `g`: each one's phases (log times), well
/// formed ([`well_formed`]), before the checks that need the samples again (carried, a grasp).
fn plan(g: &Grid, params: &SegmentParams) -> Vec<Vec<PhaseSpan>> {
    let moves = find_moves(g, params);
    let episodes = find_episodes(g, params);
    let n = g.len();
    let last = (n - 1) as f64;
    let tol = 0.05 / params.grid_s;
    let mut skills_spans: Vec<Vec<(Phase, f64, f64)>> = Vec::new();
    let mut prev_end = 0.0f64;
    let mut mi = 0usize; // first move not yet used
    for (k, &(c0, c1)) in episodes.iter().enumerate() {
        let (c0, c1) = (c0 as f64, c1 as f64);
        let mut spans: Vec<(Phase, f64, f64)> = Vec::new();
        // Moves before the first touch.
        let pre: Vec<Move> = moves[mi..]
            .iter()
            .take_while(|m| m.end <= c0 + tol)
            .copied()
            .collect();
        mi += pre.len();
        let grasp_start = pre.last().map_or(c0, |m| m.end.min(c0));
        if pre.len() >= 2 {
            let p = pre[pre.len() - 1];
            spans.push((Phase::Approach, prev_end, p.start));
            spans.push((Phase::Preshape, p.start, p.end.min(grasp_start)));
        } else {
            spans.push((Phase::Approach, prev_end, grasp_start));
        }
        // Moves after the grasp: in contact, or after a lost contact until the retreat (the
        // first upward move after the contact ended or after a place).
        let next_c0 = episodes.get(k + 1).map(|e| e.0 as f64);
        let mut cursor = grasp_start;
        let mut name_rest = Phase::Grasp;
        let mut last_label = None;
        let mut retreat = None;
        while let Some(m) = moves.get(mi).copied() {
            if next_c0.is_some_and(|c| m.end > c + tol) {
                break;
            }
            let h = m.dp.norm();
            let label = if h < params.rotation_radius * m.angle * 0.5 {
                Phase::Transport
            } else if m.dp.z > params.vertical_fraction * h {
                Phase::Lift
            } else if m.dp.z < -params.vertical_fraction * h {
                Phase::Place
            } else {
                Phase::Transport
            };
            mi += 1;
            if label == Phase::Lift && (m.start > c1 + tol || last_label == Some(Phase::Place)) {
                retreat = Some(m);
                break;
            }
            if m.start - cursor > 0.15 / params.grid_s || name_rest == Phase::Grasp {
                spans.push((name_rest, cursor, m.start));
            } else if let Some(prev) = spans.last_mut() {
                prev.2 = m.start;
            }
            spans.push((label, m.start, m.end));
            cursor = m.end;
            last_label = Some(label);
            name_rest = Phase::Hold;
        }
        if last_label == Some(Phase::Place) {
            name_rest = Phase::Release;
        }
        match retreat {
            Some(r) => {
                spans.push((name_rest, cursor, r.start));
                let end = if next_c0.is_some() { r.end } else { last };
                spans.push((Phase::Retreat, r.start, end));
                prev_end = end;
            }
            None => {
                let end = next_c0.map_or(last, |c| c1.max(cursor).min(c));
                spans.push((name_rest, cursor, end.max(cursor)));
                prev_end = end;
            }
        }
        skills_spans.push(spans);
    }
    well_formed(skills_spans, g, last)
}

/// Segments a session held in memory into skills, one per grasp (see the module's "What
/// counts as a grasp"; a session without one has no skill). Pure: no I/O. The same as
/// [`segment_source`] on the file the session came from.
pub fn segment(session: &Session, params: &SegmentParams) -> Segmentation {
    // Each topic in time order, as a file read gives them.
    let mut object: Vec<&(u64, ObjectState)> = session.object.iter().collect();
    object.sort_by_key(|(t, _)| *t);
    let mut contacts: Vec<&(u64, Contacts)> = session.contacts.iter().collect();
    contacts.sort_by_key(|(t, _)| *t);
    // Interleaved by time, contacts first at a tick, as the recorder writes them.
    let feed = |v: &mut dyn SessionVisitor| -> Result<(), RecordingError> {
        let (mut i, mut j) = (0, 0);
        loop {
            match (object.get(i), contacts.get(j)) {
                (Some((to, o)), Some((tc, _))) if to < tc => {
                    v.object(*to, o)?;
                    i += 1;
                }
                (_, Some((tc, c))) => {
                    v.contacts(*tc, c)?;
                    j += 1;
                }
                (Some((to, o)), None) => {
                    v.object(*to, o)?;
                    i += 1;
                }
                (None, None) => return Ok(()),
            }
        }
    };
    let mut one = PassOne::new(params);
    // Neither pass fails: they only collect.
    let _ = feed(&mut one);
    let mut two = one.finish(&session.metadata, params);
    let _ = feed(&mut two);
    two.finish()
}

/// Segments the session `source` in two streamed passes ([`crate::session::stream_session_file`]):
/// the first checks the file and resamples the hand's base onto the grid (about 41 bytes per
/// millisecond of session), the second computes the parameters of each grasp found, keeping
/// per grasp only its accumulators. The second pass reads the contacts and object states the
/// first kept ([`KeptMessages`], up to [`KEPT_MESSAGES_BUDGET`]: about two minutes of session)
/// and decodes only what the accumulators read; a longer session is read again. Memory is
/// bounded by the grid, that budget and a few chunks, not the file: a 60 s session in 34 MB,
/// an hour in 218 MB (peak resident of `icms segment`). A file that writes
/// its object states well ahead of its contacts (valid MCAP: each topic in time order) also
/// holds each grasp's object positions until its contacts come, 56 bytes a sample of the
/// grasp at most. A replay recording is refused
/// ([`crate::session::SessionHead::ensure_grasp_session`]) after the first pass.
pub fn segment_source(
    source: &SessionSource<'_>,
    limits: &ReadLimits,
    params: &SegmentParams,
) -> Result<(SessionHead, Segmentation), RecordingError> {
    // The contacts and object states of a session of a minute or two are kept from the first
    // pass for the second (no second decompression); a longer one is read again.
    let mut kept = KeptMessages::new(KEPT_MESSAGES_BUDGET);
    segment_source_keeping(source, limits, params, &mut kept)
}

/// [`segment_source`] keeping the first pass's messages in `kept` (the topics segmentation
/// reads and those `kept` is asked to keep [as well](KeptMessages::also)) for a reader after
/// it: ingest's approach templates read them without a third pass over the file.
pub fn segment_source_keeping(
    source: &SessionSource<'_>,
    limits: &ReadLimits,
    params: &SegmentParams,
    kept: &mut KeptMessages,
) -> Result<(SessionHead, Segmentation), RecordingError> {
    let mut one = PassOne::new(params);
    let head = source.stream_keeping(limits, &mut one, kept)?;
    head.ensure_grasp_session(&source.name())?;
    let mut two = one.finish(&head.metadata, params);
    source.stream_again_kept(limits, &mut two, kept)?;
    Ok((head, two.finish()))
}

/// Pass one: the grid, then the candidate skills.
struct PassOne {
    grid: GridBuilder,
}

impl PassOne {
    fn new(params: &SegmentParams) -> Self {
        PassOne {
            grid: GridBuilder::new(params),
        }
    }

    /// The second pass, for the candidate skills the grid holds.
    fn finish(self, metadata: &BTreeMap<String, String>, params: &SegmentParams) -> PassTwo {
        let runs = self.grid.runs.clone();
        let (t0, skills) = match self.grid.finish() {
            None => (0, Vec::new()),
            Some(g) => {
                let skills = plan(&g, params)
                    .into_iter()
                    .map(|phases| {
                        let start = phases.first().map_or(0, |p| p.start_ns);
                        let end = phases.last().map_or(0, |p| p.end_ns);
                        let index = grasped_object(&runs, start, end);
                        let object = object_params(metadata, index);
                        let mut acc = SkillAcc::new(phases, object, metadata, params);
                        acc.object_index = index as u32;
                        acc
                    })
                    .collect();
                (g.t0, skills)
            }
        };
        PassTwo {
            t0,
            skills,
            first_open: 0,
            last_contact: 0,
            last_object: 0,
            before: None,
        }
    }
}

impl SessionVisitor for PassOne {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics::SEGMENTATION
    }
    fn contacts(&mut self, t: u64, m: &Contacts) -> Result<(), RecordingError> {
        self.grid.contacts(t, m);
        Ok(())
    }
    fn object(&mut self, t: u64, m: &ObjectState) -> Result<(), RecordingError> {
        self.grid.object(t, m);
        Ok(())
    }
}

/// Pass two: each candidate skill's accumulators, fed the samples of its time span.
struct PassTwo {
    /// Log time of the grid's first point: session time 0.
    t0: u64,
    skills: Vec<SkillAcc>,
    /// Skills before this one have seen every sample they need.
    first_open: usize,
    /// Log times of the latest contact and object samples.
    last_contact: u64,
    last_object: u64,
    /// The latest object sample.
    before: Option<(u64, ObjectState)>,
}

impl PassTwo {
    fn finish(self) -> Segmentation {
        let t0 = self.t0;
        let skills = self
            .skills
            .into_iter()
            .filter_map(SkillAcc::finish)
            .filter(|s| is_grasp(&s.parameters))
            .map(|mut s| {
                // Log times to session time: recorders need not start their clocks at 0 (ROS
                // bags and most MCAP writers log epoch times).
                for p in &mut s.phases {
                    p.start_ns -= t0;
                    p.end_ns -= t0;
                }
                s.parameters.source.start_ns -= t0;
                s.parameters.source.end_ns -= t0;
                s
            })
            .collect();
        Segmentation { skills }
    }
}

impl PassTwo {
    /// Skips the skills that samples from here on cannot change.
    fn close(&mut self) {
        let t = self.last_contact.min(self.last_object);
        while self.skills.get(self.first_open).is_some_and(|s| s.done(t)) {
            self.first_open += 1;
        }
    }
}

impl SessionVisitor for PassTwo {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics::SEGMENTATION
    }
    fn contacts(&mut self, t: u64, m: &Contacts) -> Result<(), RecordingError> {
        self.last_contact = t;
        // Skills are in time order: those not started yet take nothing.
        for s in &mut self.skills[self.first_open..] {
            if t < s.start {
                break;
            }
            s.contacts(t, &contacts_on(m, s.object_index));
        }
        self.close();
        Ok(())
    }
    fn object(&mut self, t: u64, m: &ObjectState) -> Result<(), RecordingError> {
        self.last_object = t;
        for s in &mut self.skills[self.first_open..] {
            if t < s.start {
                break;
            }
            let index = s.object_index;
            if !s.seeded {
                s.seeded = true;
                if let Some((tp, p)) = &self.before {
                    s.object(*tp, &object_view(p, index));
                }
            }
            s.object(t, &object_view(m, index));
        }
        self.before = Some((t, m.clone()));
        self.close();
        Ok(())
    }
    fn done(&self) -> bool {
        self.first_open == self.skills.len()
    }
    fn segmentation_fields_only(&self) -> bool {
        true
    }
}

/// `c` as a skill of object `index` sees it: the fingertips touching another object of the
/// scene are not touching (its object). Borrowed when none does (always with one object).
fn contacts_on(c: &Contacts, index: u32) -> std::borrow::Cow<'_, Contacts> {
    if c.fingers.iter().all(|f| !f.touching || f.object == index) {
        return std::borrow::Cow::Borrowed(c);
    }
    let mut own = c.clone();
    for f in own
        .fingers
        .iter_mut()
        .filter(|f| f.touching && f.object != index)
    {
        *f = crate::session::FingerContact {
            name: std::mem::take(&mut f.name),
            part: f.part,
            link: std::mem::take(&mut f.link),
            ..Default::default()
        };
    }
    own.n_contacts = own.fingers.iter().filter(|f| f.in_contact).count() as u32;
    std::borrow::Cow::Owned(own)
}

/// Object `index`'s state from an `/object/state` sample: the sample itself when its main
/// fields are that object's (always with one object), else its entry in `objects` with its
/// pose in the hand (the hand's base from the main fields); wrenches are not recorded for it.
/// An index the sample does not list gives the sample.
fn object_view(m: &ObjectState, index: u32) -> std::borrow::Cow<'_, ObjectState> {
    let Some(o) = m.objects.get(index as usize).filter(|_| m.index != index) else {
        return std::borrow::Cow::Borrowed(m);
    };
    let base = iso(&m.pose) * iso(&m.pose_in_hand).inverse();
    let pose = iso(&o.pose);
    std::borrow::Cow::Owned(ObjectState {
        pose: o.pose,
        linear_velocity: o.linear_velocity,
        angular_velocity_b: o.angular_velocity_b,
        pose_in_hand: pose_of(&(base.inverse() * pose)),
        index,
        ..ObjectState::default()
    })
}

fn pose_of(i: &Isometry) -> Pose {
    let q = i.rotation.quaternion();
    Pose {
        position: crate::foxglove::Vector3::new(
            i.translation.vector.x,
            i.translation.vector.y,
            i.translation.vector.z,
        ),
        orientation: crate::foxglove::Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// Whether the hand carried the object during a skill, decided as the samples come: at some
/// contact sample from the start of `grasp` to the skill's end with at least two fingertips
/// transmitting force, the object (its last sample at or before that time) is
/// [`SegmentParams::min_carry_m`] or more from where it was when two fingertips first
/// transmitted force, and it moved with the hand: its displacement relative to the hand's base
/// is less than half its displacement in the world. An object the fingers squeeze but cannot
/// lift (too heavy, too small to hold, frictionless), one pushed or knocked away, or one that
/// only rocks in the fingers is not carried.
///
/// Contacts and object samples come interleaved tick by tick in our files (a handful wait
/// here); a file that writes one topic well ahead of the other makes the one ahead wait, up to
/// the skill's length.
struct CarryState {
    from: u64,
    to: u64,
    min_carry_m: f64,
    /// Contact samples (log times) waiting for the object's sample at or before them.
    pending: std::collections::VecDeque<u64>,
    /// Object samples that a contact sample to come may need: (log time, position in the
    /// world, position in the hand), from the latest one at or before the later of `from` and
    /// the last contact sample.
    track: std::collections::VecDeque<(u64, Vector, Vector)>,
    /// Log time of the latest contact sample.
    last_contact: u64,
    reference: Option<(Vector, Vector)>,
    carried: bool,
}

impl CarryState {
    fn new(phases: &[PhaseSpan], params: &SegmentParams) -> Self {
        let first = phases.first().map_or(0, |p| p.start_ns);
        CarryState {
            from: phases
                .iter()
                .find(|p| p.name == Phase::Grasp)
                .map_or(first, |p| p.start_ns),
            to: phases.last().map_or(0, |p| p.end_ns),
            min_carry_m: params.min_carry_m,
            pending: std::collections::VecDeque::new(),
            track: std::collections::VecDeque::new(),
            last_contact: 0,
            reference: None,
            carried: false,
        }
    }

    fn contacts(&mut self, t: u64, c: &Contacts) {
        self.last_contact = t;
        if !self.carried
            && t >= self.from
            && t < self.to
            && c.fingers.iter().filter(|f| f.in_contact).count() >= 2
        {
            self.pending.push_back(t);
        }
        self.resolve(false);
    }

    fn object(&mut self, t: u64, o: &ObjectState) {
        let (p, h) = (v3(&o.pose.position), v3(&o.pose_in_hand.position));
        // Past the skill's end one sample is enough (it says the ones before are final): the
        // track holds at most the skill's samples, whatever the order of the file's topics.
        let past_end = self.track.back().is_some_and(|s| s.0 >= self.to);
        if self.carried || past_end || !p.iter().chain(h.iter()).all(|v| v.is_finite()) {
            return;
        }
        self.track.push_back((t, p, h));
        self.resolve(false);
    }

    /// Decides the waiting contact samples that an object sample after them (or, at the
    /// `end`, the last one) has made decidable, then forgets the object samples no contact
    /// sample to come can need.
    fn resolve(&mut self, end: bool) {
        while let Some(&tc) = self.pending.front() {
            if self.carried {
                self.pending.clear();
                break;
            }
            if !end && self.track.back().is_none_or(|s| s.0 <= tc) {
                break;
            }
            while self.track.len() >= 2 && self.track[1].0 <= tc {
                self.track.pop_front();
            }
            let Some(&(_, p, h)) = self.track.front() else {
                break;
            };
            self.pending.pop_front();
            match self.reference {
                None => self.reference = Some((p, h)),
                Some((p0, h0)) => {
                    let moved = (p - p0).norm();
                    if moved >= self.min_carry_m && (h - h0).norm() < 0.5 * moved {
                        self.carried = true;
                    }
                }
            }
        }
        if self.pending.is_empty() {
            let keep_from = self.last_contact.max(self.from);
            while self.track.len() >= 2 && self.track[1].0 <= keep_from {
                self.track.pop_front();
            }
        }
        if self.carried {
            self.track.clear();
        }
    }

    /// Whether nothing more can change the verdict once both topics reached `t`.
    fn done(&self, t: u64) -> bool {
        self.carried || (t >= self.to && self.pending.is_empty())
    }

    fn finish(mut self) -> bool {
        self.resolve(true);
        self.carried
    }
}

/// A skill is a grasp only if contacts carried the object ([`CarryTrack::carried`]) and it has
/// at least two contacts (fingertips touching for 30 % of the held part) of which two oppose
/// each other (mean normals more than 90° apart). Checked on the parameters, so that no skill
/// is ever stored with fewer than two contacts.
fn is_grasp(p: &SkillParameters) -> bool {
    p.contacts.iter().enumerate().any(|(i, a)| {
        p.contacts[i + 1..]
            .iter()
            .any(|b| Vector::from(a.normal_b).dot(&Vector::from(b.normal_b)) < 0.0)
    })
}

/// The skills' spans (grid indices) as phases in ns, well formed whatever the data: every
/// phase non-empty, in time order across all skills, never overlapping, inside the session
/// (`0` to the grid's `last` index); a skill left without a phase is dropped.
///
/// The grammar in [`segment`] can produce disordered spans on odd recordings: a move that starts
/// before the first touch and ends after it (the approach runs to the touch, the move from its
/// own start), contacts that flicker or come back after the object was dropped, a retreat that
/// runs past the next grasp's start. Each span is clipped to start where the previous phase
/// ended; one left empty goes.
fn well_formed(
    skills_spans: Vec<Vec<(Phase, f64, f64)>>,
    g: &Grid,
    last: f64,
) -> Vec<Vec<PhaseSpan>> {
    let grid_ns = |x: f64| g.t0 + (x.max(0.0) * g.dt_ns as f64).round() as u64;
    // End of the previous phase, as a grid index and in ns.
    let mut floor = 0.0f64;
    let mut floor_ns = g.t0;
    let mut skills = Vec::with_capacity(skills_spans.len());
    for spans in skills_spans {
        let mut phases = Vec::with_capacity(spans.len());
        for (name, a, b) in spans {
            let (a, b) = (a.max(floor), b.min(last));
            if b.partial_cmp(&a) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            // The first phase of a session starts at the session's start, the grid's first
            // sample (log times need not start at 0: real recorders log epoch times).
            let start_ns = grid_ns(a).max(floor_ns);
            let end_ns = grid_ns(b);
            if end_ns <= start_ns {
                continue;
            }
            floor = b;
            floor_ns = end_ns;
            phases.push(PhaseSpan {
                name,
                start_ns,
                end_ns,
            });
        }
        if !phases.is_empty() {
            skills.push(phases);
        }
    }
    skills
}

/// The object of index `index` in the session's scene as its metadata describes it: entry
/// `index` of `objects` (a scene of several), else `object`.
fn object_params(metadata: &BTreeMap<String, String>, index: usize) -> Option<ObjectParams> {
    let listed = metadata.get("objects").and_then(|text| {
        let list: Vec<ScenarioObject> = serde_json::from_str(text).ok()?;
        list.into_iter().nth(index)
    });
    let o: ScenarioObject = match listed {
        Some(o) => o,
        None => serde_json::from_str(metadata.get("object")?).ok()?,
    };
    let shape = o.to_shape().ok()?;
    Some(ObjectParams {
        name: o.name.clone(),
        shape: o.shape,
        size: shape.sizes(),
        mass: o.mass,
        inertia: shape.principal_inertia(o.mass),
        mu: o.mu,
        mu_torsion: o.mu_torsion,
    })
}

fn v3(v: &crate::foxglove::Vector3) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

fn arr(v: &Vector) -> [f64; 3] {
    [v.x, v.y, v.z]
}

const HELD: [Phase; 4] = [Phase::Lift, Phase::Hold, Phase::Transport, Phase::Place];

/// The grasp type of a skill's `contacts` ([`GraspType`]): virtual fingers are the palm's
/// contacts as one and greedy groups of the others' normals within 60° of the group's first; a
/// grasp the palm takes part in is a power grasp (Cutkosky's taxonomy: the object pressed into
/// the palm by the fingers), any other `precision` with ≤ 3 contacts and `power` with more.
pub fn grasp_type(contacts: &[ContactParams]) -> GraspType {
    let palm = contacts.iter().any(|c| c.part == ContactPart::Palm);
    let mut groups: Vec<Vector> = Vec::new();
    for c in contacts.iter().filter(|c| c.part != ContactPart::Palm) {
        let nv = Vector::from(c.normal_b);
        if !groups.iter().any(|g| g.dot(&nv) > 0.5) {
            groups.push(nv);
        }
    }
    GraspType {
        label: if palm || contacts.len() > 3 {
            "power"
        } else {
            "precision"
        }
        .into(),
        opposing_virtual_fingers: groups.len() + usize::from(palm),
    }
}

/// A finger's accumulators over a skill.
struct FingerAcc {
    name: String,
    /// The part of the hand (a fingertip, or a palm or phalanx contact shape).
    part: ContactPart,
    steady_n: usize,
    pos: Vector,
    nrm: Vector,
    /// Per phase index of the skill's phases: sums of the intensities and samples.
    per_phase: Vec<([f64; 4], usize)>,
    /// The grip profile at [`SegmentParams::profile_points`] evenly spaced times of the
    /// grasp: each the normal force of the last sample at or before it (the first sample's
    /// for times before it), filled as samples pass those times.
    profile: Vec<f64>,
    /// Profile points filled so far.
    profile_next: usize,
    /// The normal force of the latest sample.
    latest_normal: Option<f64>,
    slip: Option<u64>,
}

/// Pass two for one candidate skill: its parameters accumulated sample by sample, holding
/// per finger its sums and grip profile, whatever the skill's length.
struct SkillAcc {
    phases: Vec<PhaseSpan>,
    /// Log time of the first phase's start: the skill takes samples from there (and the
    /// object sample before it, for the first contact's object position).
    start: u64,
    /// Whether it was handed the object sample before its start.
    seeded: bool,
    grasp_start: u64,
    grasp_end: u64,
    held_span: (u64, u64),
    object: Option<ObjectParams>,
    mu: Option<f64>,
    source: SkillSource,
    profile_times: Vec<f64>,
    fingers: Vec<FingerAcc>,
    steady_samples: usize,
    internal: (f64, usize),
    margin_n: f64,
    margin_ratio: f64,
    slips: Vec<SlipEvent>,
    last_t: u64,
    /// Index of the current phase.
    pi: usize,
    carry: CarryState,
    /// The times of the object's key poses (sorted), and for each the first object sample at
    /// or after it, filled as samples pass them; a time after the last sample takes the last.
    key_times: Vec<u64>,
    key_poses: Vec<Option<Isometry>>,
    key_next: usize,
    /// The first object sample at or after the grasp's start: the reference of the motion.
    start_pose: Option<Isometry>,
    last_object: Option<Isometry>,
    /// Which object of the session's scene the skill grasps (0 with one object).
    object_index: u32,
}

impl SkillAcc {
    fn new(
        phases: Vec<PhaseSpan>,
        object: Option<ObjectParams>,
        metadata: &BTreeMap<String, String>,
        params: &SegmentParams,
    ) -> Self {
        let mu = object.as_ref().map(|o| o.mu);
        let start_ns = phases.first().map_or(0, |p| p.start_ns);
        let end_ns = phases.last().map_or(0, |p| p.end_ns);
        let grasp_start = phases
            .iter()
            .find(|p| p.name == Phase::Grasp)
            .map_or(start_ns, |p| p.start_ns);
        let grasp_end = phases
            .iter()
            .rev()
            .find(|p| matches!(p.name, Phase::Release | Phase::Grasp) || HELD.contains(&p.name))
            .map_or(end_ns, |p| p.end_ns);
        let held_span = {
            let h: Vec<&PhaseSpan> = phases.iter().filter(|p| HELD.contains(&p.name)).collect();
            match (h.first(), h.last()) {
                (Some(a), Some(b)) => (a.start_ns, b.end_ns),
                _ => (grasp_start, grasp_end),
            }
        };
        // Offsets of the grip profile's points from the grasp's start.
        let span = (grasp_end.saturating_sub(grasp_start)).max(1) as f64;
        let npts = params.profile_points.max(2);
        let profile_times = (0..npts)
            .map(|k| span * k as f64 / (npts - 1) as f64)
            .collect();
        // The object's key poses: phase boundaries and every `keyframe_s` of the grasp.
        let mut key_times: Vec<u64> = phases
            .iter()
            .flat_map(|p| [p.start_ns, p.end_ns])
            .filter(|t| *t >= grasp_start && *t <= grasp_end)
            .collect();
        let step = (params.keyframe_s * 1e9).max(1e6) as u64;
        let mut t = grasp_start;
        while t < grasp_end {
            key_times.push(t);
            t += step;
        }
        key_times.sort_unstable();
        key_times.dedup();
        let source = SkillSource {
            scenario: metadata.get("scenario").cloned().unwrap_or_default(),
            seed: metadata.get("seed").and_then(|s| s.parse().ok()),
            metadata: metadata
                .iter()
                .filter(|(k, _)| matches!(k.as_str(), "hand" | "source" | "started_at"))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect(),
            start_ns,
            end_ns,
        };
        SkillAcc {
            start: start_ns,
            seeded: false,
            grasp_start,
            grasp_end,
            held_span,
            mu,
            object,
            source,
            profile_times,
            fingers: Vec::new(),
            steady_samples: 0,
            internal: (0.0, 0),
            margin_n: f64::INFINITY,
            margin_ratio: f64::INFINITY,
            slips: Vec::new(),
            last_t: grasp_start,
            pi: 0,
            carry: CarryState::new(&phases, params),
            key_poses: vec![None; key_times.len()],
            key_times,
            key_next: 0,
            start_pose: None,
            last_object: None,
            object_index: 0,
            phases,
        }
    }

    /// Whether samples from `t` on can change nothing: the grasp's contact samples are in,
    /// the key poses found, and whether the object was carried decided (which, for a grasp
    /// that carried it, is early: the second pass then stops reading there).
    fn done(&self, t: u64) -> bool {
        t >= self.grasp_end
            && self.carry.done(t)
            && self.key_next == self.key_times.len()
            && self.start_pose.is_some()
    }

    fn object(&mut self, t: u64, o: &ObjectState) {
        self.carry.object(t, o);
        let b = iso(&o.pose);
        if self.start_pose.is_none() && t >= self.grasp_start {
            self.start_pose = Some(b);
        }
        while self.key_next < self.key_times.len() && self.key_times[self.key_next] <= t {
            self.key_poses[self.key_next] = Some(b);
            self.key_next += 1;
        }
        self.last_object = Some(b);
    }

    fn contacts(&mut self, t: u64, c: &Contacts) {
        self.carry.contacts(t, c);
        if t < self.grasp_start || t >= self.grasp_end {
            return;
        }
        self.last_t = t;
        let steady = t >= self.held_span.0 && t < self.held_span.1;
        if steady {
            self.steady_samples += 1;
        }
        // Phases are in time order: advance the current one.
        while self.pi + 1 < self.phases.len() && t >= self.phases[self.pi].end_ns {
            self.pi += 1;
        }
        let pi = self.pi;
        let phase = self.phases.get(pi).map(|p| p.name);
        let offset = t.saturating_sub(self.grasp_start) as f64;
        let mut sum_n = 0.0;
        for (fi, f) in c.fingers.iter().enumerate() {
            // Fingers come in the same order every tick; look the name up only if not.
            let found = match self.fingers.get(fi) {
                Some(a) if a.name == f.name => Some(fi),
                _ => self.fingers.iter().position(|a| a.name == f.name),
            };
            let a = match found {
                Some(i) => &mut self.fingers[i],
                None => {
                    self.fingers.push(FingerAcc {
                        name: f.name.clone(),
                        part: f.part,
                        steady_n: 0,
                        pos: Vector::zeros(),
                        nrm: Vector::zeros(),
                        per_phase: vec![([0.0; 4], 0); self.phases.len()],
                        profile: vec![0.0; self.profile_times.len()],
                        profile_next: 0,
                        latest_normal: None,
                        slip: None,
                    });
                    self.fingers.last_mut().expect("pushed")
                }
            };
            let i = &f.intensity;
            let normal = if f.in_contact { i.z.max(0.0) } else { 0.0 };
            while a.profile_next < self.profile_times.len()
                && self.profile_times[a.profile_next] < offset
            {
                a.profile[a.profile_next] = a.latest_normal.unwrap_or(normal);
                a.profile_next += 1;
            }
            a.latest_normal = Some(normal);
            if f.slip && f.touching {
                a.slip.get_or_insert(t);
            } else if let Some(s) = a.slip.take() {
                if t - s >= 2_000_000 {
                    self.slips.push(SlipEvent {
                        time_s: (s - self.grasp_start) as f64 * 1e-9,
                        finger: f.name.clone(),
                        duration_s: (t - s) as f64 * 1e-9,
                    });
                }
            }
            if !f.touching {
                continue;
            }
            sum_n += normal;
            let Some(e) = a.per_phase.get_mut(pi) else {
                continue;
            };
            for (k, v) in [i.x, i.y, i.z, i.torsion].into_iter().enumerate() {
                e.0[k] += v;
            }
            e.1 += 1;
            if steady {
                a.steady_n += 1;
                a.pos += v3(&f.point_b);
                a.nrm += v3(&f.normal_b);
            }
            // The friction margin over the held part (closing and opening are excluded: there
            // the normal force is near zero by intent).
            if let (Some(mu), true) = (self.mu, steady && f.in_contact && i.z > 0.05) {
                let ct = i.x.hypot(i.y);
                let m = mu * i.z - ct;
                self.margin_n = self.margin_n.min(m);
                if mu * i.z > 1e-6 {
                    self.margin_ratio = self.margin_ratio.min(m / (mu * i.z));
                }
            }
        }
        if steady && phase.is_some_and(|p| HELD.contains(&p)) {
            self.internal.0 += sum_n;
            self.internal.1 += 1;
        }
    }

    /// The skill, if the hand carried the object.
    fn finish(mut self) -> Option<Skill> {
        let carried = std::mem::replace(
            &mut self.carry,
            CarryState::new(&[], &SegmentParams::default()),
        )
        .finish();
        if !carried {
            return None;
        }
        let parameters = self.parameters();
        Some(Skill {
            phases: self.phases,
            parameters,
        })
    }

    fn parameters(&mut self) -> SkillParameters {
        let (phases, object, mu) = (&self.phases, self.object.clone(), self.mu);
        let grasp_start = self.grasp_start;
        let last_t = self.last_t;
        let mut slips = std::mem::take(&mut self.slips);
        for a in &mut self.fingers {
            if let Some(s) = a.slip.take() {
                slips.push(SlipEvent {
                    time_s: (s - grasp_start) as f64 * 1e-9,
                    finger: a.name.clone(),
                    duration_s: (last_t - s) as f64 * 1e-9,
                });
            }
            // Profile points after the last sample: its value.
            for k in a.profile_next..a.profile.len() {
                a.profile[k] = a.latest_normal.unwrap_or(0.0);
            }
        }
        let accs = &self.fingers;
        let steady_samples = self.steady_samples;
        let internal = self.internal;
        let (margin_n, margin_ratio) = (self.margin_n, self.margin_ratio);
        // One event per finger for slips closer than 20 ms.
        slips.sort_by(|a, b| a.finger.cmp(&b.finger).then(a.time_s.total_cmp(&b.time_s)));
        let mut merged: Vec<SlipEvent> = Vec::new();
        for e in slips {
            match merged.last_mut() {
                Some(m) if m.finger == e.finger && e.time_s - (m.time_s + m.duration_s) < 0.02 => {
                    m.duration_s = (e.time_s + e.duration_s - m.time_s).max(m.duration_s);
                }
                _ => merged.push(e),
            }
        }
        let mut slips = merged;
        slips.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
        // Contacts: fingers touching for at least 30 % of the steady part.
        let min_n = (steady_samples as f64 * 0.3).max(1.0) as usize;
        let contacts: Vec<ContactParams> = accs
            .iter()
            .filter(|a| a.steady_n >= min_n && a.nrm.norm() > 0.0)
            .map(|a| {
                let pos = a.pos / a.steady_n as f64;
                let nrm = a.nrm.normalize();
                let grip_profile = a.profile.clone();
                ContactParams {
                    finger: a.name.clone(),
                    part: a.part,
                    position_b: arr(&pos),
                    normal_b: arr(&nrm),
                    mean_intensity: {
                        let mut m: BTreeMap<Phase, ([f64; 4], usize)> = BTreeMap::new();
                        for (p, (s, c)) in phases.iter().zip(&a.per_phase) {
                            let e = m.entry(p.name).or_insert(([0.0; 4], 0));
                            for k in 0..4 {
                                e.0[k] += s[k];
                            }
                            e.1 += c;
                        }
                        m.into_iter()
                            .filter(|(_, (_, c))| *c > 0)
                            .map(|(k, (s, c))| (k, s.map(|v| v / c as f64)))
                            .collect()
                    },
                    grip_profile,
                }
            })
            .collect();
        // Quality on the mean contacts.
        let quality = match (&object, contacts.len()) {
            (Some(o), n) if n > 0 => {
                let frames: Vec<ContactFrame> = contacts
                    .iter()
                    .map(|c| ContactFrame::from_normal(c.position_b.into(), c.normal_b.into()))
                    .collect();
                let qp = QualityParams {
                    torque_scale: Some(o.size.iter().map(|v| v * v).sum::<f64>().sqrt()),
                    ..QualityParams::default()
                };
                let fr = Friction {
                    mu: o.mu,
                    mu_torsion: o.mu_torsion,
                };
                grasp_quality(&frames, ContactModel::SoftFinger, &fr, &qp)
                    .ok()
                    .map(|q| QualityParamsOut {
                        epsilon: q.epsilon,
                        volume: q.volume,
                        force_closure: q.force_closure,
                    })
            }
            _ => None,
        };
        let grasp_type = grasp_type(&contacts);
        // Object motion relative to B at grasp start: the first object sample at or after each
        // key time (the last sample for a key time after it).
        let last_object = self.last_object;
        let obj_at = |k: usize| self.key_poses[k].or(last_object);
        let mut motion = Vec::new();
        let (mut lift_h, mut horiz, mut max_rot) = (0.0f64, 0.0f64, 0.0f64);
        if let Some(b0) = self.start_pose.or(last_object) {
            for (k, &t) in self.key_times.iter().enumerate() {
                if let Some(b) = obj_at(k) {
                    let rel = b0.inverse() * b;
                    let d = b.translation.vector - b0.translation.vector;
                    lift_h = lift_h.max(d.z);
                    horiz = horiz.max(d.x.hypot(d.y));
                    max_rot = max_rot.max(rel.rotation.angle());
                    motion.push(KeyPose {
                        time_s: (t - grasp_start) as f64 * 1e-9,
                        position: arr(&rel.translation.vector),
                        rotation: arr(&rel.rotation.scaled_axis()),
                    });
                }
            }
        }
        let mut phase_durations = BTreeMap::new();
        for p in phases {
            *phase_durations.entry(p.name).or_insert(0.0) += (p.end_ns - p.start_ns) as f64 * 1e-9;
        }
        let internal_force_n = if internal.1 > 0 {
            internal.0 / internal.1 as f64
        } else {
            0.0
        };
        let fin = |v: f64| if v.is_finite() { v } else { 0.0 };
        let (friction_margin_n, friction_margin_ratio) = (fin(margin_n), fin(margin_ratio));
        let mean_abs_n = {
            let mut s = Vector::zeros();
            for c in &contacts {
                s += Vector::from(c.normal_b).abs();
            }
            if contacts.is_empty() {
                s
            } else {
                s / contacts.len() as f64
            }
        };
        let shape = object.as_ref().map(|o| o.shape);
        let weight = object.as_ref().map_or(1.0, |o| o.mass * 9.81);
        let q = quality.as_ref();
        let raw = [
            object.as_ref().map_or(0.0, |o| o.mass.ln()),
            mu.unwrap_or(0.0),
            contacts.len() as f64,
            q.map_or(0.0, |q| q.epsilon),
            q.map_or(0.0, |q| q.volume.max(0.0).powf(1.0 / 6.0)),
            internal_force_n / weight,
            phase_durations.get(&Phase::Hold).copied().unwrap_or(0.0),
            lift_h,
            horiz,
            max_rot,
            mean_abs_n.x,
            mean_abs_n.y,
            mean_abs_n.z,
            (shape == Some(ShapeKind::Sphere)) as u8 as f64,
            (shape == Some(ShapeKind::Box)) as u8 as f64,
            (shape == Some(ShapeKind::Cylinder)) as u8 as f64,
        ];
        let feature = raw.map(|v| fin(v) as f32);
        let source = self.source.clone();
        SkillParameters {
            object,
            contact_model: ContactModel::SoftFinger,
            contact_count: contacts.len(),
            contacts,
            internal_force_n,
            friction_margin_n,
            friction_margin_ratio,
            motion,
            phase_durations,
            slip_events: slips,
            quality,
            grasp_type,
            source,
            feature,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phase_found_exactly_scores_zero_error_and_full_recall() {
        let truth = vec![
            GroundTruthPhase {
                name: "approach".into(),
                start_ns: 0,
                end_ns: 100,
            },
            GroundTruthPhase {
                name: "grasp".into(),
                start_ns: 100,
                end_ns: 300,
            },
        ];
        let found: Vec<PhaseSpan> = truth
            .iter()
            .map(|p| PhaseSpan {
                name: p.name.parse().unwrap(),
                start_ns: p.start_ns,
                end_ns: p.end_ns,
            })
            .collect();
        let s = score(&found, &truth);
        assert_eq!(s.phases_found_fraction, 1.0);
        assert_eq!(s.median_boundary_error_ms, 0.0);
        assert_eq!(s.boundary_errors_ms.len(), 2);
    }
}
