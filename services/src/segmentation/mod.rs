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
//!
//! # Files
//!
//! One job each:
//!
//! - `skill.rs`: the result: [`Skill`], its phases and parameters, [`FEATURE_DIMENSIONS`].
//! - `grid.rs`: pass one's data: the hand's base resampled onto the grid, contact runs.
//! - `moves.rs`: the moves of the hand's base and the contact episodes on the grid.
//! - `grammar.rs`: the phases of each candidate skill from its moves and episode.
//! - `stream.rs`: the two streamed passes over a session's samples.
//! - `carry.rs`: whether the hand carried the object, decided as samples come.
//! - `accumulate.rs`: pass two's accumulators of one skill, fed sample by sample.
//! - `params.rs`: the parameters computed from what was accumulated (quality, grasp type,
//!   feature vector, ...) and whether a skill is a grasp.
//! - `score.rs`: [`score()`] against ground truth, and [`median`].
//! - `pose.rs`: conversions between recorded poses and the math types.

mod accumulate;
mod carry;
mod grammar;
mod grid;
mod moves;
mod params;
mod pose;
mod score;
mod skill;
mod stream;

pub use params::grasp_type;
pub(crate) use pose::iso;
pub use score::{median, score, Score};
pub use skill::{
    ContactParams, GraspType, KeyPose, ObjectParams, PhaseSpan, QualityParamsOut, Segmentation,
    Skill, SkillParameters, SkillSource, SlipEvent, FEATURE_DIMENSIONS,
};

use crate::error::RecordingError;
use crate::mcap_io::ReadLimits;
use crate::session::{
    Contacts, KeptMessages, ObjectState, Session, SessionHead, SessionSource, SessionVisitor,
    KEPT_MESSAGES_BUDGET,
};
use stream::PassOne;

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
/// template); 3, the templates take the grip 0.8 s after the first touch (the grasp stage's
/// held-force estimate) and the scene's number of objects (templates of version 2 are read
/// without them until reprocessed).
pub const SEGMENTATION_VERSION: u32 = 3;

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
