//! Exporting a session's glove samples as a glove CSV file (`icms export-glove`), in exactly the
//! format [`super::import`] reads: `time_s`, each DOF's angle, `tau_<DOF>` and the wrist pose
//! (`wrist_x` … `wrist_qw`), one line per tick.
//!
//! - `time_s`: the tick's log time less the first `/glove/joint_states` message's, in seconds
//!   written exactly to the nanosecond (`0.001000000`).
//! - angles and torques: `/glove/joint_states` (`positions`, `efforts`), the sample the DFS
//!   stepped on, at the file's resolution, each written as the shortest decimal that reads
//!   back as the same number.
//! - the wrist pose: the hand base's pose of the tick, `pose ∘ pose_in_hand⁻¹` of the
//!   `/object/state` message of the same log time (the session records the object's pose in
//!   the world and relative to the hand base).
//!
//! Importing the file with the session's hand and object (`session` metadata `hand` and
//! `object`; the export ends with a comment line naming both, and [`ExportSummary`] holds
//! them) replays the same samples through the DFS.
//!
//! The session is streamed ([`stream_session_file`]): it is checked as any session read is,
//! and the rows are written as the samples come, with only the samples of a tick whose other
//! topic has not come yet held in memory (none, in files written tick by tick). The CSV is
//! written to `F.csv.part` and renamed into place once the whole session has been read and
//! checked; on any error the partial file is removed.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use dfs_core::math::Isometry;

use super::import::WRIST_COLUMNS;
use super::messages::{GloveJointStates, ObjectState};
use super::{
    stream_session_file, DecodeTopics, SessionVisitor, TOPIC_GLOVE_JOINT_STATES, TOPIC_OBJECT_STATE,
};
use crate::error::{RecordingError, Result};
use crate::mcap_io::ReadLimits;
use crate::segmentation::iso;

/// What [`export_glove_csv`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportSummary {
    /// Sample lines written (one per tick).
    pub rows: u64,
    /// The DOF names, in column order.
    pub dofs: Vec<String>,
    /// Time of the last line (s).
    pub duration_s: f64,
    /// Size of the CSV file (bytes).
    pub file_bytes: u64,
    /// The session's hand (`session` metadata `hand`), if recorded.
    pub hand: Option<String>,
    /// The session's object as JSON (`session` metadata `object`), if recorded.
    pub object_json: Option<String>,
    /// Whether the session's DFS let the whole hand touch the object (`session` metadata
    /// `contacts` = `whole_hand`): import it with `--whole-hand` to get the same skills.
    pub whole_hand: bool,
}

/// The hand base's pose of a tick: `pose ∘ pose_in_hand⁻¹`.
fn base_of(o: &ObjectState) -> Isometry {
    iso(&o.pose) * iso(&o.pose_in_hand).inverse()
}

/// The visitor: pairs each `/glove/joint_states` sample with the `/object/state` sample of the
/// same log time and writes the line.
struct Export<W: Write> {
    out: W,
    path: PathBuf,
    names: Vec<String>,
    /// First glove sample's log time: the CSV's time origin.
    t0: Option<u64>,
    /// Glove samples waiting for their object state: log time, `q` then `τ`.
    glove: VecDeque<(u64, Vec<f64>)>,
    /// Object states waiting for their glove sample: log time, base pose.
    base: VecDeque<(u64, Isometry)>,
    /// Emptied buffers of `glove`, for reuse.
    spare: Vec<Vec<f64>>,
    line: String,
    rows: u64,
    last_t: u64,
}

impl<W: Write> Export<W> {
    fn io(&self, e: std::io::Error) -> RecordingError {
        RecordingError::io(format!("writing {}", self.path.display()), e)
    }

    fn header(&mut self) -> Result<()> {
        self.line.clear();
        self.line.push_str("time_s");
        for n in &self.names {
            let _ = write!(self.line, ",{n}");
        }
        for n in &self.names {
            let _ = write!(self.line, ",tau_{n}");
        }
        for w in WRIST_COLUMNS {
            let _ = write!(self.line, ",{w}");
        }
        self.line.push('\n');
        let line = std::mem::take(&mut self.line);
        let r = self.out.write_all(line.as_bytes()).map_err(|e| self.io(e));
        self.line = line;
        r
    }

    /// Writes the lines of every tick both topics have given.
    fn drain(&mut self) -> Result<()> {
        while let (Some(&(tg, _)), Some(&(tb, base))) = (self.glove.front(), self.base.front()) {
            if tg != tb {
                let (topic, t) = if tg < tb {
                    (TOPIC_OBJECT_STATE, tg)
                } else {
                    (TOPIC_GLOVE_JOINT_STATES, tb)
                };
                return Err(RecordingError::InvalidInput {
                    location: self.path.display().to_string(),
                    detail: format!(
                        "no {topic} message at log time {t} ns: a glove sample is exported \
                         with the hand base of its tick"
                    ),
                });
            }
            let Some((_, values)) = self.glove.pop_front() else {
                break;
            };
            self.base.pop_front();
            let d = tg - self.t0.unwrap_or(tg);
            self.line.clear();
            let _ = write!(self.line, "{}.{:09}", d / 1_000_000_000, d % 1_000_000_000);
            for v in &values {
                let _ = write!(self.line, ",{v}");
            }
            let (p, r) = (base.translation.vector, base.rotation);
            for v in [p.x, p.y, p.z, r.i, r.j, r.k, r.w] {
                let _ = write!(self.line, ",{v}");
            }
            self.line.push('\n');
            let line = std::mem::take(&mut self.line);
            let written = self.out.write_all(line.as_bytes()).map_err(|e| self.io(e));
            self.line = line;
            written?;
            self.spare.push(values);
            self.rows += 1;
            self.last_t = d;
        }
        Ok(())
    }
}

impl<W: Write> SessionVisitor for Export<W> {
    fn joint_states(&mut self, log_time_ns: u64, m: &GloveJointStates) -> Result<()> {
        if self.t0.is_none() {
            self.t0 = Some(log_time_ns);
            self.names.clone_from(&m.names);
            self.header()?;
        }
        let mut values = self.spare.pop().unwrap_or_default();
        values.clear();
        values.extend_from_slice(&m.positions);
        values.extend_from_slice(&m.efforts);
        self.glove.push_back((log_time_ns, values));
        self.drain()
    }

    fn object(&mut self, log_time_ns: u64, m: &ObjectState) -> Result<()> {
        self.base.push_back((log_time_ns, base_of(m)));
        self.drain()
    }

    fn wants(&self) -> DecodeTopics {
        DecodeTopics {
            joint_states: true,
            object: true,
            ..DecodeTopics::NONE
        }
    }
}

/// Writes the glove samples of the session file `session` into the CSV file `out` (see the
/// module docs). A session that does not read (the reader's errors, naming the topic and
/// message) or whose glove samples and object states do not pair up tick by tick is an error,
/// and `out` is left as it was.
pub fn export_glove_csv(session: &Path, out: &Path) -> Result<ExportSummary> {
    let part = {
        let mut name = out.file_name().unwrap_or_default().to_os_string();
        name.push(".part");
        out.with_file_name(name)
    };
    let file = std::fs::File::create(&part)
        .map_err(|e| RecordingError::io(format!("creating {}", part.display()), e))?;
    let mut export = Export {
        out: std::io::BufWriter::with_capacity(1 << 16, file),
        path: out.to_path_buf(),
        names: Vec::new(),
        t0: None,
        glove: VecDeque::new(),
        base: VecDeque::new(),
        spare: Vec::new(),
        line: String::new(),
        rows: 0,
        last_t: 0,
    };
    let result =
        stream_session_file(session, &ReadLimits::streaming(), &mut export).and_then(|head| {
            if let Some(&(t, _)) = export.glove.front() {
                return Err(RecordingError::InvalidInput {
                    location: session.display().to_string(),
                    detail: format!("no {TOPIC_OBJECT_STATE} message at log time {t} ns"),
                });
            }
            if let Some(&(t, _)) = export.base.front() {
                return Err(RecordingError::InvalidInput {
                    location: session.display().to_string(),
                    detail: format!("no {TOPIC_GLOVE_JOINT_STATES} message at log time {t} ns"),
                });
            }
            let hand = head.metadata.get("hand").filter(|h| !h.is_empty()).cloned();
            let object_json = head
                .metadata
                .get("object")
                .filter(|o| !o.trim().is_empty())
                .cloned();
            let whole_hand = head
                .metadata
                .get("contacts")
                .is_some_and(|c| c == "whole_hand");
            // A comment (ignored by the importer) on what to import it with.
            let mut trailer = format!(
                "# exported by icms export-glove from {}",
                session.file_name().map_or_else(
                    || session.display().to_string(),
                    |n| n.to_string_lossy().into()
                )
            );
            if let Some(h) = &hand {
                let _ = write!(trailer, "; hand {h}");
            }
            if let Some(o) = &object_json {
                let _ = write!(trailer, "; object {}", o.replace(['\n', '\r'], " "));
            }
            if whole_hand {
                let _ = write!(trailer, "; contacts whole_hand");
            }
            trailer.push('\n');
            export
                .out
                .write_all(trailer.as_bytes())
                .and_then(|()| export.out.flush())
                .map_err(|e| export.io(e))?;
            Ok((hand, object_json, whole_hand))
        });
    let finished = result.and_then(|(hand, object_json, whole_hand)| {
        let file = export.out.into_inner().map_err(|e| {
            RecordingError::io(format!("writing {}", out.display()), e.into_error())
        })?;
        file.sync_all()
            .map_err(|e| RecordingError::io(format!("writing {}", out.display()), e))?;
        drop(file);
        std::fs::rename(&part, out).map_err(|e| {
            RecordingError::io(format!("renaming {} into place", part.display()), e)
        })?;
        let file_bytes = std::fs::metadata(out).map_or(0, |m| m.len());
        Ok(ExportSummary {
            rows: export.rows,
            dofs: export.names,
            duration_s: export.last_t as f64 * 1e-9,
            file_bytes,
            hand,
            object_json,
            whole_hand,
        })
    });
    if finished.is_err() {
        let _ = std::fs::remove_file(&part);
    }
    finished
}
