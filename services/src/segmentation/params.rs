//! A skill's parameters as functions of what pass two accumulated or the session describes:
//! the object from the metadata, slip events merged, grasp quality, grasp type, the feature
//! vector; and whether the contacts make a grasp.

use std::collections::BTreeMap;

use dfs_core::contact::{ContactFrame, ContactModel, Friction};
use dfs_core::grasp::quality::{grasp_quality, QualityParams};
use dfs_core::math::Vector;
use dfs_core::object::ShapeKind;
use dfs_core::scenario::{Phase, ScenarioObject};

use super::{
    ContactParams, GraspType, ObjectParams, PhaseSpan, QualityParamsOut, SkillParameters, SlipEvent,
};
use crate::session::ContactPart;

/// A skill is a grasp only if contacts carried the object ([`CarryState`]) and it has at least
/// two contacts (fingertips touching for 30 % of the held part) of which two oppose each other
/// (mean normals more than 90° apart). Checked on the parameters, so that no skill is ever
/// stored with fewer than two contacts.
///
/// [`CarryState`]: super::carry::CarryState
pub(super) fn is_grasp(p: &SkillParameters) -> bool {
    p.contacts.iter().enumerate().any(|(i, a)| {
        p.contacts[i + 1..]
            .iter()
            .any(|b| Vector::from(a.normal_b).dot(&Vector::from(b.normal_b)) < 0.0)
    })
}

/// The object of index `index` in the session's scene as its metadata describes it: entry
/// `index` of `objects` (a scene of several), else `object`.
pub(super) fn object_params(
    metadata: &BTreeMap<String, String>,
    index: usize,
) -> Option<ObjectParams> {
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

/// Slip events merged: one event per finger for slips closer than 20 ms; in time order.
pub(super) fn merge_slips(mut slips: Vec<SlipEvent>) -> Vec<SlipEvent> {
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
    slips
}

/// A contact's mean intensities per phase name ([`ContactParams::mean_intensity`]) from its
/// sums and sample counts per phase of `phases` (`per_phase`, by index); a phase without a
/// sample is left out.
pub(super) fn mean_intensity(
    phases: &[PhaseSpan],
    per_phase: &[([f64; 4], usize)],
) -> BTreeMap<Phase, [f64; 4]> {
    let mut m: BTreeMap<Phase, ([f64; 4], usize)> = BTreeMap::new();
    for (p, (s, c)) in phases.iter().zip(per_phase) {
        let e = m.entry(p.phase).or_insert(([0.0; 4], 0));
        for k in 0..4 {
            e.0[k] += s[k];
        }
        e.1 += c;
    }
    m.into_iter()
        .filter(|(_, (_, c))| *c > 0)
        .map(|(k, (s, c))| (k, s.map(|v| v / c as f64)))
        .collect()
}

/// Grasp quality on the mean `contacts` ([`QualityParamsOut`]), with the object's μ and μ_t;
/// absent without the object, without contacts, or when it cannot be computed.
pub(super) fn quality(
    object: Option<&ObjectParams>,
    contacts: &[ContactParams],
) -> Option<QualityParamsOut> {
    match (object, contacts.len()) {
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
    }
}

/// How far the object went during a grasp, from its pose at the grasp's start (over the key
/// poses of its motion).
#[derive(Debug, Clone, Copy)]
pub(super) struct ObjectExtent {
    /// Highest lift (m).
    pub(super) lift_m: f64,
    /// Farthest horizontal distance (m).
    pub(super) horizontal_m: f64,
    /// Largest rotation (rad).
    pub(super) rotation_rad: f64,
}

/// `v`, or 0 when it is not finite.
pub(super) fn finite_or_zero(v: f64) -> f64 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// The feature vector of a skill ([`FEATURE_DIMENSIONS`](super::FEATURE_DIMENSIONS)), a value
/// that is not finite as 0. `hold_s` is the duration of its `hold` phases.
pub(super) fn feature(
    object: Option<&ObjectParams>,
    mu: Option<f64>,
    contacts: &[ContactParams],
    quality: Option<&QualityParamsOut>,
    internal_force_n: f64,
    hold_s: f64,
    extent: ObjectExtent,
) -> [f32; 16] {
    let mean_abs_n = {
        let mut s = Vector::zeros();
        for c in contacts {
            s += Vector::from(c.normal_b).abs();
        }
        if contacts.is_empty() {
            s
        } else {
            s / contacts.len() as f64
        }
    };
    let shape = object.map(|o| o.shape);
    let weight = object.map_or(1.0, |o| o.mass * 9.81);
    let q = quality;
    let raw = [
        object.map_or(0.0, |o| o.mass.ln()),
        mu.unwrap_or(0.0),
        contacts.len() as f64,
        q.map_or(0.0, |q| q.epsilon),
        q.map_or(0.0, |q| q.volume.max(0.0).powf(1.0 / 6.0)),
        internal_force_n / weight,
        hold_s,
        extent.lift_m,
        extent.horizontal_m,
        extent.rotation_rad,
        mean_abs_n.x,
        mean_abs_n.y,
        mean_abs_n.z,
        (shape == Some(ShapeKind::Sphere)) as u8 as f64,
        (shape == Some(ShapeKind::Box)) as u8 as f64,
        (shape == Some(ShapeKind::Cylinder)) as u8 as f64,
    ];
    raw.map(|v| finite_or_zero(v) as f32)
}
