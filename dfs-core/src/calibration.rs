//! Per-operator glove calibration: a joint offset and scale per DOF, mapping the glove's raw
//! angles onto the hand model's, `q_dfs = scale · q_raw + offset`.
//!
//! A data glove's bend sensors read each wearer's joints with a gain and a zero of their own
//! (hand size, how the glove sits); a short calibration (flat hand, fist) gives both. The
//! operator's [`Calibration`] is JSON keyed by DOF name, so it reads the same whatever the
//! order of the glove's channels, and a DOF left out is not changed (offset 0, scale 1):
//!
//! ```json
//! { "offsets": { "index_mcp": 0.05, "thumb_cmc": -0.1 },
//!   "scales":  { "index_pip": 1.1 } }
//! ```
//!
//! Offsets in rad (m for a prismatic DOF), scales without unit. [`Calibration::validate`]
//! checks it against a hand (every name one of its DOFs, every number finite, no scale 0) and
//! gives the per-DOF [`DofCalibration`] whose [`apply`](DofCalibration::apply) maps a sample
//! in place without allocating. Angles only: operator torques are measured by their own
//! sensors and are not changed.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::{DfsError, Result};
use crate::hand::{HandModel, MAX_DOF};
use crate::math::Real;

/// A per-operator calibration as written in JSON (`import-glove --calibration FILE.json`, a
/// live session's `start` message): offsets and scales keyed by DOF name. Unknown fields are
/// refused, and so is anything but a JSON object.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a calibration {\"offsets\": {DOF: rad, ...}, \"scales\": {DOF: factor, ...}}"
)]
pub struct Calibration {
    /// Offset per DOF name (rad; m for a prismatic DOF), added after the scale. Default: none.
    #[serde(default)]
    pub offsets: BTreeMap<String, Real>,
    /// Scale per DOF name (non-zero, finite). Default: none (1).
    #[serde(default)]
    pub scales: BTreeMap<String, Real>,
}

crate::object_only!(
    Calibration,
    "a calibration {\"offsets\": {DOF: rad, ...}, \"scales\": {DOF: factor, ...}}",
    serialize
);

impl Calibration {
    /// Whether it changes nothing (no entries).
    pub fn is_empty(&self) -> bool {
        self.offsets.is_empty() && self.scales.is_empty()
    }

    /// Checks the calibration against `hand` and resolves it per DOF: every name must be one
    /// of the hand's DOFs, every offset finite, every scale finite and non-zero. The error
    /// names the entry (`offsets.pinky_twist: unknown DOF of glove10 (wrist_roll, ...)`).
    pub fn validate(&self, hand: &HandModel) -> Result<DofCalibration> {
        let n = hand.dof();
        if n > MAX_DOF {
            return Err(DfsError::invalid(
                "hand",
                format!("{n} DOFs, at most {MAX_DOF}"),
            ));
        }
        let mut out = DofCalibration::identity(n);
        for (field, map) in [("offsets", &self.offsets), ("scales", &self.scales)] {
            for (name, &v) in map {
                let Some(d) = hand.dof_names.iter().position(|s| s == name) else {
                    return Err(DfsError::invalid(
                        format!("calibration {field}.{name}"),
                        format!(
                            "unknown DOF of {} (its DOFs: {})",
                            hand.name,
                            hand.dof_names.join(", ")
                        ),
                    ));
                };
                if !v.is_finite() {
                    return Err(DfsError::invalid(
                        format!("calibration {field}.{name}"),
                        format!("must be a finite number, got {v}"),
                    ));
                }
                if field == "scales" {
                    if v == 0.0 {
                        return Err(DfsError::invalid(
                            format!("calibration {field}.{name}"),
                            "a scale of 0 would erase the joint's motion",
                        ));
                    }
                    out.scale[d] = v;
                } else {
                    out.offset[d] = v;
                }
            }
        }
        Ok(out)
    }
}

/// A [`Calibration`] resolved for one hand: scale and offset per DOF in the hand's order.
/// Fixed capacity, `Copy`: applying it allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DofCalibration {
    scale: [Real; MAX_DOF],
    offset: [Real; MAX_DOF],
    dof: usize,
}

impl DofCalibration {
    /// The calibration that changes nothing, for `dof` DOFs (at most [`MAX_DOF`]).
    pub fn identity(dof: usize) -> Self {
        DofCalibration {
            scale: [1.0; MAX_DOF],
            offset: [0.0; MAX_DOF],
            dof: dof.min(MAX_DOF),
        }
    }

    /// Number of DOFs.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Scale per DOF.
    pub fn scales(&self) -> &[Real] {
        &self.scale[..self.dof]
    }

    /// Offset per DOF (rad or m).
    pub fn offsets(&self) -> &[Real] {
        &self.offset[..self.dof]
    }

    /// Whether it changes nothing.
    pub fn is_identity(&self) -> bool {
        self.scales().iter().all(|&s| s == 1.0) && self.offsets().iter().all(|&o| o == 0.0)
    }

    /// Maps raw joint angles in place: `q[d] = scale[d] · q[d] + offset[d]` for the first
    /// [`dof`](Self::dof) entries (a sample in the hand's DOF order; entries beyond are left
    /// alone, missing ones skipped). Allocation-free, never panics.
    pub fn apply(&self, q: &mut [Real]) {
        for ((v, &s), &o) in q.iter_mut().zip(self.scales()).zip(self.offsets()) {
            *v = s * *v + o;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> std::result::Result<Calibration, String> {
        serde_json::from_str(text).map_err(|e| e.to_string())
    }

    #[test]
    fn a_calibration_maps_each_named_dof_and_leaves_the_others() {
        let hand = HandModel::glove10();
        let c = parse(
            r#"{"offsets": {"index_mcp": 0.1}, "scales": {"index_mcp": 2, "thumb_cmc": 0.5}}"#,
        )
        .unwrap();
        let cal = c.validate(&hand).unwrap();
        let n = hand.dof();
        let mcp = hand
            .dof_names
            .iter()
            .position(|s| s == "index_mcp")
            .unwrap();
        let cmc = hand
            .dof_names
            .iter()
            .position(|s| s == "thumb_cmc")
            .unwrap();
        let mut q = vec![0.3; n];
        cal.apply(&mut q);
        for (d, &v) in q.iter().enumerate() {
            let expected = match d {
                _ if d == mcp => 0.7,
                _ if d == cmc => 0.15,
                _ => 0.3,
            };
            assert!((v - expected).abs() < 1e-12, "DOF {d}: {v}");
        }
        assert!(!cal.is_identity());
        assert!(Calibration::default()
            .validate(&hand)
            .unwrap()
            .is_identity());
        // A short slice is mapped as far as it goes; nothing panics.
        let mut short = [1.0; 2];
        cal.apply(&mut short);
    }

    #[test]
    fn bad_calibrations_are_refused_naming_the_entry() {
        let hand = HandModel::glove10();
        let e = parse(r#"{"offsets": {"pinky_twist": 0.1}}"#)
            .unwrap()
            .validate(&hand)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("offsets.pinky_twist") && e.contains("unknown DOF of glove10"),
            "{e}"
        );
        let e = parse(r#"{"scales": {"index_pip": 0}}"#)
            .unwrap()
            .validate(&hand)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scales.index_pip"), "{e}");
        let c = Calibration {
            offsets: BTreeMap::from([("index_pip".to_owned(), Real::NAN)]),
            ..Calibration::default()
        };
        let e = c.validate(&hand).unwrap_err().to_string();
        assert!(
            e.contains("offsets.index_pip") && e.contains("finite"),
            "{e}"
        );
        let e = parse(r#"{"offset": {}}"#).unwrap_err();
        assert!(e.contains("unknown field `offset`"), "{e}");
        let e = parse(r#"[{}, {}]"#).unwrap_err();
        assert!(e.contains("expected a calibration"), "{e}");
        let e = parse(r#"{"scales": {"index_pip": "x"}}"#).unwrap_err();
        assert!(e.contains("invalid type"), "{e}");
    }
}
