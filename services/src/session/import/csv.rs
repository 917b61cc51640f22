//! The glove CSV format (see the parent module's docs): header, angles, optional torques and
//! wrist pose.

use std::collections::HashMap;
use std::path::Path;

use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Rotation, Vector};
use nalgebra::Quaternion;

use super::{invalid, GloveRecording, WristTrack, MAX_RECORDING_NS};
use crate::error::{RecordingError, Result};

/// The wrist pose columns, in the order `icms export-glove` writes them: position (m), then
/// the orientation quaternion `x, y, z, w`.
pub const WRIST_COLUMNS: [&str; 7] = [
    "wrist_x", "wrist_y", "wrist_z", "wrist_qx", "wrist_qy", "wrist_qz", "wrist_qw",
];

/// Reads a glove CSV file (format in the module docs) for `hand`.
pub fn read_glove_csv(path: &Path, hand: &HandModel) -> Result<GloveRecording> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| RecordingError::io(format!("reading {}", path.display()), e))?;
    parse_glove_csv(&text, &path.display().to_string(), hand)
}

/// What a column after `time_s` holds.
#[derive(Debug, Clone, Copy)]
enum Column {
    Angle(usize),
    Torque(usize),
    Wrist(usize),
}

/// Parses glove CSV text; `name` (e.g. the file name) prefixes error locations.
pub fn parse_glove_csv(text: &str, name: &str, hand: &HandModel) -> Result<GloveRecording> {
    let n = hand.dof();
    // Spreadsheets export UTF-8 with a byte order mark; it is not part of the first column.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((header_line, header)) = lines.next() else {
        return Err(invalid(name, "empty file: expected a header line"));
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    if columns[0] != "time_s" {
        return Err(invalid(
            format!("{name} line {header_line}, column 1"),
            format!("the first column must be time_s, found {:?}", columns[0]),
        ));
    }
    let dof_index: HashMap<&str, usize> = hand
        .dof_names
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    let mut mapping = Vec::with_capacity(columns.len() - 1);
    let mut seen_angle = vec![false; n];
    let mut seen_torque = vec![false; n];
    let mut seen_wrist = [false; 7];
    for (c, col) in columns.iter().enumerate().skip(1) {
        // A DOF's own name first (a DOF may be called `tau_x` or `wrist_x`).
        let column = if let Some(&d) = dof_index.get(col) {
            Column::Angle(d)
        } else if let Some(&d) = col.strip_prefix("tau_").and_then(|j| dof_index.get(j)) {
            Column::Torque(d)
        } else if let Some(w) = WRIST_COLUMNS.iter().position(|w| w == col) {
            Column::Wrist(w)
        } else {
            return Err(invalid(
                format!("{name} line {header_line}, column {}", c + 1),
                format!(
                    "unknown column name {col:?}; expected time_s, then the DOFs of {} ({}), \
                     tau_<DOF> for each (or none) and the wrist pose {} (or none)",
                    hand.name,
                    hand.dof_names.join(", "),
                    WRIST_COLUMNS.join(",")
                ),
            ));
        };
        let seen = match column {
            Column::Angle(d) => &mut seen_angle[d],
            Column::Torque(d) => &mut seen_torque[d],
            Column::Wrist(w) => &mut seen_wrist[w],
        };
        if std::mem::replace(seen, true) {
            return Err(invalid(
                format!("{name} line {header_line}, column {}", c + 1),
                format!("column {col:?} appears twice"),
            ));
        }
        mapping.push(column);
    }
    if let Some(d) = seen_angle.iter().position(|s| !s) {
        return Err(invalid(
            format!("{name} line {header_line}"),
            format!("missing column {}", hand.dof_names[d]),
        ));
    }
    let torques = seen_torque.iter().any(|&s| s);
    if let (true, Some(d)) = (torques, seen_torque.iter().position(|s| !s)) {
        return Err(invalid(
            format!("{name} line {header_line}"),
            format!(
                "missing column tau_{}: give tau_<DOF> for every DOF, or for none (a glove \
                 that measures positions only)",
                hand.dof_names[d]
            ),
        ));
    }
    let wrist = seen_wrist.iter().any(|&s| s);
    if let (true, Some(w)) = (wrist, seen_wrist.iter().position(|s| !s)) {
        return Err(invalid(
            format!("{name} line {header_line}"),
            format!(
                "missing column {}: the wrist pose needs all of {}, or none",
                WRIST_COLUMNS[w],
                WRIST_COLUMNS.join(",")
            ),
        ));
    }
    let mut rec = GloveRecording {
        names: hand.dof_names.clone(),
        times_ns: Vec::new(),
        q: Vec::new(),
        tau: torques.then(Vec::new),
        wrist: wrist.then(|| WristTrack {
            source: "csv".to_owned(),
            times_ns: Vec::new(),
            poses: Vec::new(),
        }),
    };
    let mut t0: Option<f64> = None;
    let mut row_q = vec![0.0; n];
    let mut row_tau = vec![0.0; n];
    let mut row_wrist = [0.0; 7];
    for (line_no, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != columns.len() {
            return Err(invalid(
                format!("{name} line {line_no}"),
                format!("{} columns, the header has {}", fields.len(), columns.len()),
            ));
        }
        let number = |c: usize| -> Result<f64> {
            let v: f64 = fields[c].parse().map_err(|_| {
                invalid(
                    format!("{name} line {line_no}, column {}", columns[c]),
                    format!("not a number: {:?}", fields[c]),
                )
            })?;
            if !v.is_finite() {
                return Err(invalid(
                    format!("{name} line {line_no}, column {}", columns[c]),
                    format!("{v} is not a finite number"),
                ));
            }
            Ok(v)
        };
        let t = number(0)?;
        let start = *t0.get_or_insert(t);
        let t_ns = ((t - start) * 1e9).round();
        if !(0.0..=MAX_RECORDING_NS as f64).contains(&t_ns) {
            return Err(invalid(
                format!("{name} line {line_no}, column time_s"),
                "time must not go back before the first sample, nor exceed one hour after it",
            ));
        }
        let t_ns = t_ns as u64;
        if let Some(&prev) = rec.times_ns.last() {
            if t_ns <= prev {
                return Err(invalid(
                    format!("{name} line {line_no}, column time_s"),
                    format!("time {t} s is not after the previous sample"),
                ));
            }
        }
        for (c, column) in mapping.iter().enumerate() {
            let v = number(c + 1)?;
            match *column {
                Column::Angle(d) => row_q[d] = v,
                Column::Torque(d) => row_tau[d] = v,
                Column::Wrist(w) => row_wrist[w] = v,
            }
        }
        rec.times_ns.push(t_ns);
        rec.q.extend_from_slice(&row_q);
        if let Some(tau) = &mut rec.tau {
            tau.extend_from_slice(&row_tau);
        }
        if let Some(track) = &mut rec.wrist {
            let [x, y, z, qx, qy, qz, qw] = row_wrist;
            let rotation = unit_quaternion(qx, qy, qz, qw).ok_or_else(|| {
                invalid(
                    format!(
                        "{name} line {line_no}, columns {}",
                        WRIST_COLUMNS[3..].join(",")
                    ),
                    format!(
                        "the wrist quaternion ({qx}, {qy}, {qz}, {qw}) has no direction: \
                         not a rotation"
                    ),
                )
            })?;
            track.times_ns.push(t_ns as i64);
            track
                .poses
                .push(Isometry::from_parts(Vector::new(x, y, z).into(), rotation));
        }
    }
    if rec.is_empty() {
        return Err(invalid(name, "no samples after the header"));
    }
    Ok(rec)
}

/// The quaternion `(x, y, z, w)` normalised, `None` if it is not finite or (nearly) zero.
pub(crate) fn unit_quaternion(x: f64, y: f64, z: f64, w: f64) -> Option<Rotation> {
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    (norm.is_finite() && norm > 1e-9).then(|| Rotation::from_quaternion(q))
}
