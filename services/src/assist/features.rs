//! What the assistant sees of a tick, and the *approach template* of a grasp.
//!
//! # The approach template
//!
//! A person reaching for an object shapes the hand for it well before touching it (Jeannerod's
//! reach-to-grasp: the aperture opens to a maximum scaled to the object, then closes on it as
//! the hand decelerates). The template records that, indexed by *distance* rather than time, so
//! that a slower, faster, curved or paused reach of the same grasp gives the same template:
//!
//! - the object: shape (one-hot), ln(mass / 1 kg), μ and its bounding radius (m);
//! - at each of [`CHECKPOINTS_M`] (the grasp centre's distance to the object's surface, first
//!   reached on the way in): the hand's aperture (mean distance of the fingertips from the
//!   thumb's, m), its spread (mean distance of the fingertips from their centroid, m), the
//!   elevation of the grasp centre seen from the object's centre (z of the unit direction:
//!   1 from above, 0 from the side) and the direction the hand points (z of the unit direction
//!   from the wrist to the grasp centre: −1 pointing down);
//! - the contact onset: fingertips touching the object [`ONSET_WINDOW_NS`] after the first did;
//! - the grip: the normal force of the whole hand on the object per its weight [`GRIP_AT_NS`]
//!   after the first touch (what the grasp stage estimates the held force from);
//! - the number of objects in the scene (the grasp's context).
//!
//! The grasp centre is the centroid of the fingertips. A value not seen (a reach that began
//! inside a checkpoint, a session without contact) is NaN and left out of comparisons.
//! Every quantity is in the world or the object's frame, not the hand's: the template of a
//! grasp made with one hand model compares with one made with another.

use dfs_core::contact::ContactFrame;
use dfs_core::dfs::{BodyContact, TickOutput, MAX_OBJECTS};
use dfs_core::hand::{MAX_CONTACT_SHAPES, MAX_TIPS};
use dfs_core::math::{Isometry, Point, Vector};
use dfs_core::object::{Shape, ShapeKind};

/// Distances of the grasp centre to the object's surface (m) at which the template records
/// the hand, farthest first.
pub const CHECKPOINTS_M: [f64; 5] = [0.20, 0.12, 0.08, 0.05, 0.03];

/// Values recorded at each checkpoint: aperture, spread, elevation, pointing.
pub const CHECKPOINT_DIMS: usize = 4;

/// Values describing the object: sphere, box, cylinder (one-hot), ln(mass), μ, bounding radius.
pub const OBJECT_DIMS: usize = 6;

/// Index of the contact-onset value in a template.
pub const ONSET_DIM: usize = OBJECT_DIMS + CHECKPOINTS_M.len() * CHECKPOINT_DIMS;

/// Index of the grip value in a template: the normal force of the whole hand on the object
/// per its weight, [`GRIP_AT_NS`] after the first fingertip touched it.
pub const GRIP_DIM: usize = ONSET_DIM + 1;

/// Index of the scene value in a template: how many objects the scene has (the grasp's
/// context: what a grasp does next, how long it holds and where it carries, goes with the
/// scene it is done in).
pub const SCENE_DIM: usize = GRIP_DIM + 1;

/// Length of an approach template.
pub const TEMPLATE_DIM: usize = SCENE_DIM + 1;

/// Length of the templates stored before the grip and the scene were added (segmentation
/// version 2): read back with both not seen (NaN), [`template_of`].
pub const TEMPLATE_DIM_V2: usize = GRIP_DIM;

/// How long after the first fingertip touched the object the grip is taken (ns): 800 ms,
/// when the recogniser's grasp stage decides ([`super::recognise::RecogniserParams`]'s
/// default `grasp_stage_ns`), so that a stored skill's grip and a live grasp's are the same
/// measurement.
pub const GRIP_AT_NS: u64 = 800_000_000;

/// Standard gravity (m/s²), for the weight the grip is divided by.
const GRAVITY: f64 = 9.81;

/// How long after the first fingertip touched the object the onset counts touching fingertips
/// (ns): 100 ms.
pub const ONSET_WINDOW_NS: u64 = 100_000_000;

/// The scale of each template value in comparisons: a difference of one scale counts 1.
/// Shapes differ by 2 / 0.2² = 50, so a grasp is matched with grasps of its object's shape.
pub const TEMPLATE_SCALE: [f32; TEMPLATE_DIM] = {
    let mut s = [0.0f32; TEMPLATE_DIM];
    s[0] = 0.2;
    s[1] = 0.2;
    s[2] = 0.2;
    s[3] = 0.3; // ln mass: ±35 %
    s[4] = 0.15; // μ
    s[5] = 0.01; // bounding radius (m)
    let mut k = 0;
    while k < CHECKPOINTS_M.len() {
        let b = OBJECT_DIMS + k * CHECKPOINT_DIMS;
        s[b] = 0.012; // aperture (m)
        s[b + 1] = 0.01; // spread (m)
        s[b + 2] = 0.25; // elevation
        s[b + 3] = 0.25; // pointing
        k += 1;
    }
    s[ONSET_DIM] = 0.75; // fingertips at onset
    s[GRIP_DIM] = 1.5; // grip per weight
    s[SCENE_DIM] = 2.0; // objects in the scene
    s
};

/// A template from its stored values: [`TEMPLATE_DIM`] of them, or [`TEMPLATE_DIM_V2`] (a
/// template stored before the grip and the scene were added: both not seen); `None` for any
/// other length.
pub fn template_of(values: &[f32]) -> Option<[f32; TEMPLATE_DIM]> {
    let mut t = [f32::NAN; TEMPLATE_DIM];
    match values.len() {
        TEMPLATE_DIM | TEMPLATE_DIM_V2 => {
            t[..values.len()].copy_from_slice(values);
            Some(t)
        }
        _ => None,
    }
}

/// Names of the template's values, for documents and `--json` output.
pub fn template_dimensions() -> Vec<String> {
    let mut v: Vec<String> = [
        "shape is sphere (0/1)",
        "shape is box (0/1)",
        "shape is cylinder (0/1)",
        "ln(mass / 1 kg)",
        "mu",
        "bounding radius (m)",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for d in CHECKPOINTS_M {
        let cm = d * 100.0;
        v.push(format!("aperture at {cm} cm (m)"));
        v.push(format!("spread at {cm} cm (m)"));
        v.push(format!("elevation at {cm} cm"));
        v.push(format!("pointing at {cm} cm"));
    }
    v.push("fingertips touching at onset".to_owned());
    v.push(format!(
        "grip: normal force of the hand on the object per its weight, {} s after the first touch",
        GRIP_AT_NS as f64 * 1e-9
    ));
    v.push("objects in the scene".to_owned());
    v
}

/// An object as the assistant knows it: from a live session's scene, a session file's
/// metadata, or a stored skill.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectInfo {
    /// Its name in the scene (`object` for a session's one unnamed object).
    pub name: String,
    /// Shape and size.
    pub shape: Shape,
    /// Mass (kg).
    pub mass: f64,
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Torsional friction coefficient (m).
    pub mu_torsion: f64,
}

impl ObjectInfo {
    /// The objects of a scene, in its order.
    pub fn of_scene(scene: &dfs_core::scenario::Scene) -> Vec<ObjectInfo> {
        scene
            .objects
            .iter()
            .map(|o| ObjectInfo {
                name: o.name.clone(),
                shape: o.object.shape,
                mass: o.object.mass,
                mu: o.friction.mu,
                mu_torsion: o.friction.mu_torsion,
            })
            .collect()
    }

    /// The object's part of a template.
    pub fn descriptor(&self) -> [f32; OBJECT_DIMS] {
        let kind = self.shape.kind();
        [
            (kind == ShapeKind::Sphere) as u8 as f32,
            (kind == ShapeKind::Box) as u8 as f32,
            (kind == ShapeKind::Cylinder) as u8 as f32,
            finite_or_nan(self.mass.max(1e-9).ln()),
            finite_or_nan(self.mu),
            finite_or_nan(self.shape.bounding_radius()),
        ]
    }
}

fn finite_or_nan(v: f64) -> f32 {
    if v.is_finite() {
        v as f32
    } else {
        f32::NAN
    }
}

/// A fingertip, or a whole-hand contact shape (the palm, a phalanx), touching an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipTouch {
    /// The object (index in the scene).
    pub object: usize,
    /// The contact point in the object's frame B (m).
    pub p_b: Vector,
    /// The contact normal in B, pointing into the object.
    pub normal_b: Vector,
    /// Touching and pushing: the contact transmits force.
    pub in_contact: bool,
    /// Normal force the contact transmits (N; 0 when touching without pushing).
    pub normal_force: f64,
}

impl TipTouch {
    /// The touch of a contact that is `touching` object `object` at `frame` (in B), pushing
    /// (`in_contact`) with normal intensity `normal` (N); `None` when it does not touch.
    pub fn of(
        touching: bool,
        frame: Option<&ContactFrame>,
        object: usize,
        in_contact: bool,
        normal: f64,
    ) -> Option<TipTouch> {
        let frame = frame.filter(|_| touching)?;
        Some(TipTouch {
            object,
            p_b: frame.p_b,
            normal_b: frame.normal_b(),
            in_contact,
            normal_force: if in_contact { normal.max(0.0) } else { 0.0 },
        })
    }
}

/// What the assistant sees of one tick. Fixed capacity, `Copy`: it crosses a bounded channel
/// to the assistant's thread without allocating.
#[derive(Debug, Clone, Copy)]
pub struct Observation {
    /// Session time (ns).
    pub t_ns: u64,
    /// The hand's base (wrist) in the world.
    pub base: Isometry,
    /// Fingertips of the hand.
    pub n_tips: usize,
    /// Index of the thumb's fingertip.
    pub thumb: usize,
    /// Fingertip centres in the world (m).
    pub tips: [Point; MAX_TIPS],
    /// Per fingertip: what it touches.
    pub touch: [Option<TipTouch>; MAX_TIPS],
    /// Whole-hand contact shapes (palm, phalanges) of the stream: `body[..n_body]`.
    pub n_body: usize,
    /// Per whole-hand contact shape, what it touches; a shape keeps its slot over the stream.
    /// A skill's contacts (and so the features it is compared by) count these as they count
    /// fingertips: a power grasp's palm is one of its contacts.
    pub body: [Option<TipTouch>; MAX_CONTACT_SHAPES],
    /// Objects of the scene.
    pub n_objects: usize,
    /// Their poses in the world.
    pub objects: [Isometry; MAX_OBJECTS],
}

impl Observation {
    /// An observation of nothing at time 0 (to fill).
    pub fn empty() -> Observation {
        Observation {
            t_ns: 0,
            base: Isometry::identity(),
            n_tips: 0,
            thumb: 0,
            tips: [Point::origin(); MAX_TIPS],
            touch: [None; MAX_TIPS],
            n_body: 0,
            body: [None; MAX_CONTACT_SHAPES],
            n_objects: 0,
            objects: [Isometry::identity(); MAX_OBJECTS],
        }
    }

    /// The observation of a DFS tick at session time `t_ns` with the hand's base at `base`,
    /// with its whole-hand contacts `body` ([`Dfs::body_contacts`](dfs_core::dfs::Dfs::body_contacts):
    /// empty without whole-hand contact).
    pub fn of_tick(
        t_ns: u64,
        base: &Isometry,
        thumb: usize,
        out: &TickOutput,
        body: &[BodyContact],
    ) -> Observation {
        let mut o = Observation::empty();
        o.t_ns = t_ns;
        o.base = *base;
        o.n_tips = out.n_tips.min(MAX_TIPS);
        o.thumb = thumb.min(o.n_tips.saturating_sub(1));
        o.tips[..o.n_tips].copy_from_slice(&out.tip_centres[..o.n_tips]);
        for (slot, tip) in o.touch.iter_mut().zip(&out.tips[..o.n_tips]) {
            *slot = TipTouch::of(
                tip.touching,
                tip.frame.as_ref(),
                tip.object,
                tip.in_contact,
                tip.transmitted[2],
            );
        }
        o.n_body = body.len().min(MAX_CONTACT_SHAPES);
        for (slot, c) in o.body.iter_mut().zip(&body[..o.n_body]) {
            *slot = TipTouch::of(
                c.touching,
                c.frame.as_ref(),
                c.object,
                c.in_contact,
                c.transmitted[2],
            );
        }
        o.n_objects = out.n_objects.min(MAX_OBJECTS);
        for i in 0..o.n_objects {
            o.objects[i] = out.objects[i].state.pose;
        }
        o
    }

    /// Fingertips in contact (pushing) on any object.
    pub fn in_contact(&self) -> usize {
        self.touch[..self.n_tips]
            .iter()
            .filter(|t| t.is_some_and(|t| t.in_contact))
            .count()
    }

    /// Fingertips touching object `i`.
    pub fn touching(&self, i: usize) -> usize {
        self.touch[..self.n_tips]
            .iter()
            .filter(|t| t.is_some_and(|t| t.object == i))
            .count()
    }

    /// Fingertips and whole-hand contact shapes touching object `i`.
    pub fn hand_touching(&self, i: usize) -> usize {
        self.touching(i)
            + self.body[..self.n_body]
                .iter()
                .filter(|t| t.is_some_and(|t| t.object == i))
                .count()
    }

    /// The hand's shape in this observation.
    pub fn hand(&self) -> HandView {
        HandView::of(self)
    }
}

/// The hand's shape in an observation, independent of the hand model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandView {
    /// Centroid of the fingertips (world, m).
    pub centre: Point,
    /// Mean distance of the other fingertips from the thumb's (m).
    pub aperture: f64,
    /// Mean distance of the fingertips from their centroid (m).
    pub spread: f64,
    /// z of the unit direction from the wrist to the grasp centre (−1: pointing down).
    pub pointing: f64,
}

impl HandView {
    /// The view of `obs` (NaN values for a hand without fingertips).
    pub fn of(obs: &Observation) -> HandView {
        let tips = &obs.tips[..obs.n_tips];
        if tips.is_empty() {
            return HandView {
                centre: obs.base.translation.vector.into(),
                aperture: f64::NAN,
                spread: f64::NAN,
                pointing: f64::NAN,
            };
        }
        let mut c = Vector::zeros();
        for p in tips {
            c += p.coords;
        }
        c /= tips.len() as f64;
        let spread = tips.iter().map(|p| (p.coords - c).norm()).sum::<f64>() / tips.len() as f64;
        let thumb = tips[obs.thumb.min(tips.len() - 1)];
        let others = tips.len().saturating_sub(1).max(1) as f64;
        let aperture = tips.iter().map(|p| (p - thumb).norm()).sum::<f64>() / others;
        let pointing = (c - obs.base.translation.vector)
            .try_normalize(1e-9)
            .map_or(f64::NAN, |u| u.z);
        HandView {
            centre: c.into(),
            aperture,
            spread,
            pointing,
        }
    }

    /// Signed distance (m) of the grasp centre to the surface of `shape` at `pose` (negative
    /// inside), and the elevation of the centre seen from the object's centre.
    pub fn relative_to(&self, shape: &Shape, pose: &Isometry) -> (f64, f64) {
        let p_b = pose.inverse_transform_point(&self.centre).coords;
        let d = shape.closest(&p_b).distance;
        let elevation = (self.centre.coords - pose.translation.vector)
            .try_normalize(1e-9)
            .map_or(f64::NAN, |u| u.z);
        (d, elevation)
    }
}

/// How far (m) the grasp centre must go back out past a checkpoint before crossing it inward
/// again counts anew (hysteresis against tremor at the checkpoint).
pub const REARM_M: f64 = 0.005;

/// Builds the approach template of a reach for one object, an observation at a time (see the
/// module docs). A checkpoint records the hand when the grasp centre crosses it inward, and
/// again at the next inward crossing after going back out past it by [`REARM_M`] before the
/// first touch; a checkpoint the first observation is already inside of records nothing until
/// then. Checkpoints are recorded up to the contact onset, the grip after it. Allocation-free.
#[derive(Debug, Clone, Copy)]
pub struct TemplateBuilder {
    object: usize,
    values: [f32; TEMPLATE_DIM],
    /// Per checkpoint: the hand is outside it, so an inward crossing records.
    armed: [bool; CHECKPOINTS_M.len()],
    /// An observation with a finite distance has been seen.
    seen: bool,
    /// Distance of the grasp centre to the surface at the last observation (m).
    distance_m: f64,
    first_touch_ns: Option<u64>,
    onset_done: bool,
    /// The object's weight (N; NaN when its mass is not known).
    weight: f64,
    grip_done: bool,
}

/// What one observation did to a [`TemplateBuilder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// Nothing new.
    None,
    /// The hand crossed checkpoint `k` (index into [`CHECKPOINTS_M`]; the innermost one
    /// crossed, when it crossed several).
    Checkpoint(usize),
    /// The contact onset was recorded.
    Onset,
}

impl TemplateBuilder {
    /// A template for object `object` (index in the scene) described by `info`, in a scene
    /// of `scene_objects` objects, nothing seen.
    pub fn new(object: usize, info: &ObjectInfo, scene_objects: usize) -> TemplateBuilder {
        let mut values = [f32::NAN; TEMPLATE_DIM];
        values[..OBJECT_DIMS].copy_from_slice(&info.descriptor());
        values[SCENE_DIM] = scene_objects as f32;
        TemplateBuilder {
            object,
            values,
            armed: [false; CHECKPOINTS_M.len()],
            seen: false,
            distance_m: f64::INFINITY,
            first_touch_ns: None,
            onset_done: false,
            weight: info.mass * GRAVITY,
            grip_done: false,
        }
    }

    /// The object (index in the scene).
    pub fn object(&self) -> usize {
        self.object
    }

    /// Takes an observation: `hand` its [`HandView`], `shape` the object's shape.
    pub fn observe(&mut self, obs: &Observation, hand: &HandView, shape: &Shape) -> Progress {
        if self.object >= obs.n_objects {
            return Progress::None;
        }
        let (d, elevation) = hand.relative_to(shape, &obs.objects[self.object]);
        let mut progress = Progress::None;
        if d.is_finite() {
            self.distance_m = d;
        }
        // The reach ends at the contact onset (a checkpoint still crossed then records, as it
        // always did); what the hand does after (closing, lifting, a regrasp) records none,
        // although the grip is taken later, and nothing re-arms after the first touch.
        if d.is_finite() && !self.onset_done {
            if !self.seen {
                self.seen = true;
                for (armed, cp) in self.armed.iter_mut().zip(CHECKPOINTS_M) {
                    *armed = d > cp;
                }
            }
            for (k, cp) in CHECKPOINTS_M.iter().enumerate() {
                if self.armed[k] && d <= *cp {
                    let b = OBJECT_DIMS + k * CHECKPOINT_DIMS;
                    self.values[b] = finite_or_nan(hand.aperture);
                    self.values[b + 1] = finite_or_nan(hand.spread);
                    self.values[b + 2] = finite_or_nan(elevation);
                    self.values[b + 3] = finite_or_nan(hand.pointing);
                    self.armed[k] = false;
                    progress = Progress::Checkpoint(k);
                } else if !self.armed[k] && d > cp + REARM_M && self.first_touch_ns.is_none() {
                    self.armed[k] = true;
                }
            }
        }
        let touching = obs.touching(self.object);
        let Some(t0) = self.first_touch_ns else {
            if touching > 0 {
                self.first_touch_ns = Some(obs.t_ns);
            }
            return progress;
        };
        if !self.onset_done && obs.t_ns >= t0 + ONSET_WINDOW_NS {
            self.values[ONSET_DIM] = touching as f32;
            self.onset_done = true;
            progress = Progress::Onset;
        }
        if !self.grip_done && obs.t_ns >= t0 + GRIP_AT_NS {
            let normal: f64 = obs.touch[..obs.n_tips]
                .iter()
                .chain(&obs.body[..obs.n_body])
                .flatten()
                .filter(|t| t.object == self.object)
                .map(|t| t.normal_force)
                .sum();
            self.values[GRIP_DIM] = if self.weight > 0.0 {
                finite_or_nan(normal / self.weight)
            } else {
                f32::NAN
            };
            self.grip_done = true;
        }
        progress
    }

    /// Distance of the grasp centre to the object's surface at the last observation (m;
    /// infinite before one).
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// When a fingertip first touched the object (session ns).
    pub fn first_touch_ns(&self) -> Option<u64> {
        self.first_touch_ns
    }

    /// The contact onset has been recorded.
    pub fn onset_done(&self) -> bool {
        self.onset_done
    }

    /// The contact onset and the grip have been recorded: the template is complete.
    pub fn done(&self) -> bool {
        self.onset_done && self.grip_done
    }

    /// The template so far (NaN where nothing was seen yet).
    pub fn template(&self) -> &[f32; TEMPLATE_DIM] {
        &self.values
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dfs_core::math::Rotation;

    fn obs_at(centre: Vector, aperture: f64, objects: &[Isometry]) -> Observation {
        let mut o = Observation::empty();
        o.n_tips = 2;
        o.thumb = 0;
        o.tips[0] = (centre - Vector::x() * aperture / 2.0).into();
        o.tips[1] = (centre + Vector::x() * aperture / 2.0).into();
        o.base = Isometry::from_parts((centre + Vector::z() * 0.1).into(), Rotation::identity());
        o.n_objects = objects.len();
        o.objects[..objects.len()].copy_from_slice(objects);
        o
    }

    /// A fingertip pushing 1 N on the side of [`ball`].
    fn pad_on_the_ball() -> TipTouch {
        TipTouch {
            object: 0,
            p_b: Vector::x() * 0.04,
            normal_b: -Vector::x(),
            in_contact: true,
            normal_force: 1.0,
        }
    }

    /// The built-in scenarios' 4 cm ball.
    fn ball() -> ObjectInfo {
        ObjectInfo {
            name: "object".into(),
            shape: Shape::Sphere { radius: 0.04 },
            mass: 0.3,
            mu: 0.8,
            mu_torsion: 0.0,
        }
    }

    #[test]
    fn checkpoints_are_filled_once_in_order_as_the_hand_comes_in() {
        let info = ball();
        let pose = Isometry::translation(0.0, 0.0, 0.04);
        let mut b = TemplateBuilder::new(0, &info, 1);
        assert!(b.template()[OBJECT_DIMS..SCENE_DIM]
            .iter()
            .all(|v| v.is_nan()));
        assert_eq!(b.template()[SCENE_DIM], 1.0);
        // From 0.25 m above the surface down to it, the aperture opening with distance.
        let mut reached = Vec::new();
        for i in 0..=250 {
            let d = 0.25 - i as f64 * 0.001;
            let c = Vector::new(0.0, 0.0, 0.08 + d);
            let o = obs_at(c, 0.05 + d * 0.1, &[pose]);
            let h = o.hand();
            if let Progress::Checkpoint(k) = b.observe(&o, &h, &info.shape) {
                reached.push((k, d));
            }
        }
        assert_eq!(reached.len(), CHECKPOINTS_M.len());
        for (k, (crossed, d)) in reached.iter().enumerate() {
            assert_eq!(*crossed, k);
            assert!((d - CHECKPOINTS_M[k]).abs() < 0.0011, "{d}");
            let ap = b.template()[OBJECT_DIMS + k * CHECKPOINT_DIMS];
            assert!((ap as f64 - (0.05 + CHECKPOINTS_M[k] * 0.1)).abs() < 2e-4);
            // Straight above: elevation 1, pointing down.
            assert!((b.template()[OBJECT_DIMS + k * CHECKPOINT_DIMS + 2] - 1.0).abs() < 1e-6);
            assert!((b.template()[OBJECT_DIMS + k * CHECKPOINT_DIMS + 3] + 1.0).abs() < 1e-6);
        }
        assert!(b.template()[ONSET_DIM].is_nan());
    }

    #[test]
    fn a_jump_past_several_checkpoints_fills_them_with_what_is_seen() {
        let info = ObjectInfo {
            name: "box".into(),
            shape: Shape::Box {
                half_extents: [0.02, 0.02, 0.04],
            },
            mass: 0.2,
            mu: 0.8,
            mu_torsion: 0.0,
        };
        let pose = Isometry::translation(0.3, 0.0, 0.04);
        let mut b = TemplateBuilder::new(0, &info, 1);
        let far = obs_at(Vector::new(0.3, 0.3, 0.1), 0.08, &[pose]);
        assert_eq!(b.observe(&far, &far.hand(), &info.shape), Progress::None);
        let near = obs_at(Vector::new(0.3, 0.045, 0.06), 0.07, &[pose]);
        assert_eq!(
            b.observe(&near, &near.hand(), &info.shape),
            Progress::Checkpoint(4)
        );
        for k in 0..5 {
            assert!((b.template()[OBJECT_DIMS + k * CHECKPOINT_DIMS] - 0.07).abs() < 1e-6);
        }
        assert!(b.template()[ONSET_DIM].is_nan());
    }

    #[test]
    fn the_onset_counts_fingertips_touching_after_the_window() {
        let info = ball();
        let pose = Isometry::translation(0.0, 0.0, 0.04);
        let mut b = TemplateBuilder::new(0, &info, 1);
        let touch = pad_on_the_ball();
        for (t_ms, n) in [(0u64, 0usize), (10, 1), (60, 2), (110, 2), (120, 2)] {
            let mut o = obs_at(Vector::new(0.0, 0.0, 0.04), 0.08, &[pose]);
            o.t_ns = t_ms * 1_000_000;
            for k in 0..n {
                o.touch[k] = Some(touch);
            }
            let p = b.observe(&o, &o.hand(), &info.shape);
            assert_eq!(p == Progress::Onset, t_ms == 110, "{t_ms}");
        }
        assert_eq!(b.first_touch_ns(), Some(10_000_000));
        assert_eq!(b.template()[ONSET_DIM], 2.0);
    }

    #[test]
    fn the_grip_is_the_hands_normal_force_on_the_object_per_weight_after_its_delay() {
        let info = ball();
        let pose = Isometry::translation(0.0, 0.0, 0.04);
        let mut b = TemplateBuilder::new(0, &info, 1);
        let touch = |object, normal_force| TipTouch {
            object,
            p_b: Vector::x() * 0.04,
            normal_b: -Vector::x(),
            in_contact: true,
            normal_force,
        };
        let t0 = 50_000_000;
        for t in (0..100).map(|k| t0 + k * 10_000_000) {
            let mut o = obs_at(Vector::new(0.0, 0.0, 0.04), 0.08, &[pose]);
            o.t_ns = t;
            // Two fingertips and the palm on the ball, a third fingertip on another object:
            // only the ball's count, and they change with time (the grip taken is the one at
            // the delay, not before).
            let f = (t - t0) as f64 * 1e-9;
            o.touch[0] = Some(touch(0, 1.0 + f));
            o.touch[1] = Some(touch(0, 2.0 + f));
            o.touch[2] = Some(touch(1, 100.0));
            o.n_tips = 3;
            o.n_body = 1;
            o.body[0] = Some(touch(0, 0.5));
            b.observe(&o, &o.hand(), &info.shape);
            assert_eq!(b.done(), t >= t0 + GRIP_AT_NS, "{t}");
            if t < t0 + GRIP_AT_NS {
                assert!(b.template()[GRIP_DIM].is_nan());
            }
        }
        // At the first observation 0.8 s after the touch: 1.8 + 2.8 + 0.5 N on 0.3 kg.
        let expected = (1.8 + 2.8 + 0.5) / (0.3 * GRAVITY);
        assert!((f64::from(b.template()[GRIP_DIM]) - expected).abs() < 1e-5);
    }

    #[test]
    fn checkpoints_record_up_to_the_onset_and_none_after() {
        let info = ball();
        let pose = Isometry::translation(0.0, 0.0, 0.04);
        let mut b = TemplateBuilder::new(0, &info, 1);
        let touch = pad_on_the_ball();
        // (ms, distance of the grasp centre to the surface, aperture, touching): a fingertip
        // brushes the ball at 4 cm, the centre crosses 3 cm within the onset window, then the
        // hand backs off to 10 cm and comes in again after the onset.
        let path = [
            (0u64, 0.25, 0.10, false),
            (100, 0.04, 0.09, true),
            (150, 0.025, 0.08, true),
            (300, 0.10, 0.12, true),
            (400, 0.02, 0.05, true),
        ];
        let mut crossed = Vec::new();
        for (t_ms, d, aperture, touching) in path {
            let mut o = obs_at(Vector::new(0.0, 0.0, 0.08 + d), aperture, &[pose]);
            o.t_ns = t_ms * 1_000_000;
            if touching {
                o.touch[0] = Some(touch);
            }
            if let Progress::Checkpoint(k) = b.observe(&o, &o.hand(), &info.shape) {
                crossed.push((t_ms, k));
            }
        }
        // 20 to 5 cm at the first touch, 3 cm in the window; nothing after the onset.
        assert_eq!(crossed, [(100, 3), (150, 4)]);
        let at = |k: usize| b.template()[OBJECT_DIMS + k * CHECKPOINT_DIMS];
        assert!((at(3) - 0.09).abs() < 1e-6 && (at(4) - 0.08).abs() < 1e-6);
    }

    #[test]
    fn a_template_stored_without_the_grip_and_the_scene_reads_back_with_them_not_seen() {
        let old: Vec<f32> = (0..TEMPLATE_DIM_V2).map(|k| k as f32).collect();
        let t = template_of(&old).unwrap();
        assert_eq!(&t[..GRIP_DIM], old.as_slice());
        assert!(t[GRIP_DIM].is_nan() && t[SCENE_DIM].is_nan());
        let new: Vec<f32> = (0..TEMPLATE_DIM).map(|k| k as f32).collect();
        assert_eq!(template_of(&new).unwrap().as_slice(), new.as_slice());
        assert!(template_of(&new[..5]).is_none());
        assert!(template_of(&[0.0; TEMPLATE_DIM + 1]).is_none());
    }
}
