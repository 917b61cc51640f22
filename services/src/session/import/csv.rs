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
    let header = parse_header(header, header_line, name, hand)?;
    let mut rec = GloveRecording {
        names: hand.dof_names.clone(),
        times_ns: Vec::new(),
        q: Vec::new(),
        tau: header.torques.then(Vec::new),
        wrist: header.wrist.then(|| WristTrack {
            source: "csv".to_owned(),
            times_ns: Vec::new(),
            poses: Vec::new(),
        }),
    };
    let mut rows = Rows {
        name,
        header: &header,
        t0: None,
        q: vec![0.0; hand.dof()],
        tau: vec![0.0; hand.dof()],
        wrist: [0.0; 7],
    };
    for (line_no, line) in lines {
        rows.push(line_no, line, &mut rec)?;
    }
    if rec.is_empty() {
        return Err(invalid(name, "no samples after the header"));
    }
    Ok(rec)
}

/// A CSV file's header line, checked against the hand.
struct Header<'a> {
    /// The column names, `time_s` first.
    columns: Vec<&'a str>,
    /// What each column after `time_s` holds.
    mapping: Vec<Column>,
    /// The file has a torque column for every DOF (else for none).
    torques: bool,
    /// The file has the wrist pose columns (else none of them).
    wrist: bool,
}

/// Parses the `header` line (line `header_line` of the file `name`): `time_s` first, then each
/// column a DOF of `hand`, its torque or a wrist pose column, none twice and none missing.
fn parse_header<'a>(
    header: &'a str,
    header_line: usize,
    name: &str,
    hand: &HandModel,
) -> Result<Header<'a>> {
    let n = hand.dof();
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    if columns[0] != "time_s" {
        return Err(invalid(
            format!("{name} line {header_line}, column 1"),
            format!("the first column must be time_s, found {:?}", columns[0]),
        ));
    }
    let dof_index = dof_index(hand);
    let mut mapping = Vec::with_capacity(columns.len() - 1);
    let mut seen = Seen {
        angle: vec![false; n],
        torque: vec![false; n],
        wrist: [false; 7],
    };
    for (c, col) in columns.iter().enumerate().skip(1) {
        let Some(column) = column_of(col, &dof_index) else {
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
        let flag = match column {
            Column::Angle(d) => &mut seen.angle[d],
            Column::Torque(d) => &mut seen.torque[d],
            Column::Wrist(w) => &mut seen.wrist[w],
        };
        if std::mem::replace(flag, true) {
            return Err(invalid(
                format!("{name} line {header_line}, column {}", c + 1),
                format!("column {col:?} appears twice"),
            ));
        }
        mapping.push(column);
    }
    seen.check_complete(&format!("{name} line {header_line}"), hand)?;
    Ok(Header {
        columns,
        mapping,
        torques: seen.torque.iter().any(|&s| s),
        wrist: seen.wrist.iter().any(|&s| s),
    })
}

/// What the column named `col` holds, by the DOFs' indices by name; `None` for an unknown
/// name. A DOF's own name first (a DOF may be called `tau_x` or `wrist_x`).
/// The index of each of `hand`'s DOFs by its name: how an imported file's joint columns or
/// names are matched with the hand's.
pub(super) fn dof_index(hand: &HandModel) -> HashMap<&str, usize> {
    hand.dof_names
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect()
}

fn column_of(col: &str, dof_index: &HashMap<&str, usize>) -> Option<Column> {
    if let Some(&d) = dof_index.get(col) {
        Some(Column::Angle(d))
    } else if let Some(&d) = col.strip_prefix("tau_").and_then(|j| dof_index.get(j)) {
        Some(Column::Torque(d))
    } else {
        WRIST_COLUMNS
            .iter()
            .position(|w| *w == col)
            .map(Column::Wrist)
    }
}

/// The columns a header names, by kind.
struct Seen {
    /// Per DOF, its angle column.
    angle: Vec<bool>,
    /// Per DOF, its torque column.
    torque: Vec<bool>,
    /// Per [`WRIST_COLUMNS`] entry.
    wrist: [bool; 7],
}

impl Seen {
    /// Refuses a header (at `location`) without every DOF's angle, or with the torques or the
    /// wrist pose of some but not all.
    fn check_complete(&self, location: &str, hand: &HandModel) -> Result<()> {
        if let Some(d) = self.angle.iter().position(|s| !s) {
            return Err(invalid(
                location,
                format!("missing column {}", hand.dof_names[d]),
            ));
        }
        let torques = self.torque.iter().any(|&s| s);
        if let (true, Some(d)) = (torques, self.torque.iter().position(|s| !s)) {
            return Err(invalid(
                location,
                format!(
                    "missing column tau_{}: give tau_<DOF> for every DOF, or for none (a glove \
                     that measures positions only)",
                    hand.dof_names[d]
                ),
            ));
        }
        let wrist = self.wrist.iter().any(|&s| s);
        if let (true, Some(w)) = (wrist, self.wrist.iter().position(|s| !s)) {
            return Err(invalid(
                location,
                format!(
                    "missing column {}: the wrist pose needs all of {}, or none",
                    WRIST_COLUMNS[w],
                    WRIST_COLUMNS.join(",")
                ),
            ));
        }
        Ok(())
    }
}

/// The sample lines of a CSV file, read one by one into a recording.
struct Rows<'a> {
    /// The file's name, for error locations.
    name: &'a str,
    /// Its header.
    header: &'a Header<'a>,
    /// The first sample's time (s).
    t0: Option<f64>,
    /// The row's angles, by DOF.
    q: Vec<f64>,
    /// The row's torques, by DOF.
    tau: Vec<f64>,
    /// The row's wrist pose, as [`WRIST_COLUMNS`].
    wrist: [f64; 7],
}

impl Rows<'_> {
    /// Parses line `line_no`, `line`, and appends its sample to `rec`: every field a finite
    /// number, the time after the previous sample's and within an hour of the first.
    fn push(&mut self, line_no: usize, line: &str, rec: &mut GloveRecording) -> Result<()> {
        let (name, header) = (self.name, self.header);
        let columns = &header.columns;
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
        let t_ns = self.time_ns(t, line_no, rec.times_ns.last().copied())?;
        for (c, column) in header.mapping.iter().enumerate() {
            let v = number(c + 1)?;
            match *column {
                Column::Angle(d) => self.q[d] = v,
                Column::Torque(d) => self.tau[d] = v,
                Column::Wrist(w) => self.wrist[w] = v,
            }
        }
        rec.times_ns.push(t_ns);
        rec.q.extend_from_slice(&self.q);
        if let Some(tau) = &mut rec.tau {
            tau.extend_from_slice(&self.tau);
        }
        if let Some(track) = &mut rec.wrist {
            let pose = wrist_pose(name, line_no, self.wrist)?;
            track.times_ns.push(t_ns as i64);
            track.poses.push(pose);
        }
        Ok(())
    }

    /// The time `t` (s) of line `line_no` as ns since the first sample: not before it, at most
    /// an hour after it, and after the `previous` sample's.
    fn time_ns(&mut self, t: f64, line_no: usize, previous: Option<u64>) -> Result<u64> {
        let name = self.name;
        let start = *self.t0.get_or_insert(t);
        let t_ns = ((t - start) * 1e9).round();
        if !(0.0..=MAX_RECORDING_NS as f64).contains(&t_ns) {
            return Err(invalid(
                format!("{name} line {line_no}, column time_s"),
                "time must not go back before the first sample, nor exceed one hour after it",
            ));
        }
        let t_ns = t_ns as u64;
        if let Some(prev) = previous {
            if t_ns <= prev {
                return Err(invalid(
                    format!("{name} line {line_no}, column time_s"),
                    format!("time {t} s is not after the previous sample"),
                ));
            }
        }
        Ok(t_ns)
    }
}

/// The wrist pose of line `line_no` of the file `name` from its [`WRIST_COLUMNS`] values; a
/// quaternion with no direction is refused.
fn wrist_pose(name: &str, line_no: usize, values: [f64; 7]) -> Result<Isometry> {
    let [x, y, z, qx, qy, qz, qw] = values;
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
    Ok(Isometry::from_parts(Vector::new(x, y, z).into(), rotation))
}

/// The quaternion `(x, y, z, w)` normalised, `None` if it is not finite or (nearly) zero.
pub(crate) fn unit_quaternion(x: f64, y: f64, z: f64, w: f64) -> Option<Rotation> {
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    (norm.is_finite() && norm > 1e-9).then(|| Rotation::from_quaternion(q))
}
