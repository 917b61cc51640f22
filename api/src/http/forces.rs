//! `GET /api/v1/skills/{id}/forces`: a skill's contact forces over time, read from its source
//! session's `/dfs/contacts` and decimated to a bounded number of points, for plotting (the
//! web page's force plot) without downloading the session.

use axum::extract::State;
use serde::{Deserialize, Serialize};
use services::mcap_io::ReadLimits;
use services::session::{stream_session_file, Contacts, DecodeTopics, ObjectState, SessionVisitor};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::{Id, Query};
use super::state::AppState;

/// Default number of points of a series.
pub const DEFAULT_POINTS: u32 = 400;
/// Most points a series may ask for.
pub const MAX_POINTS: u32 = 5000;

/// Parameters of `GET /skills/{id}/forces`.
#[derive(Debug, Clone, Default, Deserialize, IntoParams)]
#[serde(default, deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ForcesParams {
    /// Points per series, 10 to 5000 (default 400): the skill's span is cut into this many
    /// equal bins and each bin gives the mean of its 1 kHz samples.
    #[param(minimum = 10, maximum = 5000)]
    pub points: Option<u32>,
}

/// One fingertip's forces on the object over the skill.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct FingerForces {
    /// Fingertip name (the recording hand's).
    pub finger: String,
    /// Normal force transmitted to the object, N (mean over each bin), one per `time_s`.
    pub normal_n: Vec<f64>,
    /// Magnitude of the tangential force transmitted to the object, N (mean over each bin).
    pub tangential_n: Vec<f64>,
}

/// A skill's contact forces over time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SkillForces {
    /// The skill.
    pub skill_id: i64,
    /// Its source session.
    pub session_id: i64,
    /// Centre of each bin, s since the session's start (the skill's `start_ns` / `end_ns`
    /// are on the same clock); bins without a sample are left out.
    pub time_s: Vec<f64>,
    /// Per fingertip, in the hand's fingertip order.
    pub fingers: Vec<FingerForces>,
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(skill_forces))
}

/// The normal and tangential contact force of each fingertip over the skill, from its source
/// session, decimated to at most `points` points.
#[utoipa::path(get, path = "/skills/{id}/forces", tag = "skills",
    params(("id" = i64, Path, description = "Skill id"), ForcesParams),
    responses(
        (status = 200, description = "The skill's contact forces over time", body = SkillForces),
        (status = 400, description = "The id is not an integer, points is out of range, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id, or its session's file is missing", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn skill_forces(
    State(st): State<AppState>,
    Id(id): Id,
    Query(p): Query<ForcesParams>,
) -> Result<axum::Json<SkillForces>, Problem> {
    let points = p.points.unwrap_or(DEFAULT_POINTS);
    if !(10..=MAX_POINTS).contains(&points) {
        return Err(Problem::bad_request(format!(
            "points {points} is outside 10..={MAX_POINTS}"
        )));
    }
    let skill = st.store().get_skill(id).await?;
    let path = st.store().session_blob_path(skill.session_id).await?;
    // Reading a session is the work of an upload's first pass: take an upload's turn.
    let _turn = st.ingest_turn().await?;
    let (start, end) = (skill.start_ns.max(0) as u64, skill.end_ns.max(0) as u64);
    let series = tokio::task::spawn_blocking(move || {
        let mut bins = Bins::new(start, end.max(start + 1), points as usize);
        stream_session_file(&path, &ReadLimits::default(), &mut bins).map(|_| bins)
    })
    .await
    .map_err(|e| Problem::internal(&e))?;
    let bins = series
        .map_err(|e| Problem::stored_recording(&format!("session {}", skill.session_id), e))?;
    Ok(axum::Json(bins.into_forces(id, skill.session_id)))
}

/// Per-bin sums of each fingertip's forces, filled as the session streams by.
struct Bins {
    start_ns: u64,
    end_ns: u64,
    /// The session's clock origin: the first `/object/state` log time.
    origin_ns: Option<u64>,
    names: Vec<String>,
    /// `[bin][finger]` sums of (normal, tangential).
    sums: Vec<Vec<(f64, f64)>>,
    counts: Vec<u32>,
}

impl Bins {
    fn new(start_ns: u64, end_ns: u64, n: usize) -> Self {
        Bins {
            start_ns,
            end_ns,
            origin_ns: None,
            names: Vec::new(),
            sums: vec![Vec::new(); n],
            counts: vec![0; n],
        }
    }

    fn into_forces(self, skill_id: i64, session_id: i64) -> SkillForces {
        let n = self.counts.len();
        let span = (self.end_ns - self.start_ns) as f64;
        let mut time_s = Vec::with_capacity(n);
        let mut fingers: Vec<FingerForces> = self
            .names
            .iter()
            .map(|name| FingerForces {
                finger: name.clone(),
                normal_n: Vec::with_capacity(n),
                tangential_n: Vec::with_capacity(n),
            })
            .collect();
        for (b, (&count, sums)) in self.counts.iter().zip(&self.sums).enumerate() {
            if count == 0 {
                continue;
            }
            let centre = self.start_ns as f64 + span * (b as f64 + 0.5) / n as f64;
            time_s.push(round3(centre * 1e-9));
            for (f, out) in fingers.iter_mut().enumerate() {
                let (normal, tangential) = sums.get(f).copied().unwrap_or_default();
                out.normal_n.push(round3(normal / f64::from(count)));
                out.tangential_n.push(round3(tangential / f64::from(count)));
            }
        }
        SkillForces {
            skill_id,
            session_id,
            time_s,
            fingers,
        }
    }
}

/// `x` to 1e-3 (a millinewton, a millisecond): the sensors' resolution is coarser, and the
/// JSON a third of the size.
fn round3(x: f64) -> f64 {
    (x * 1e3).round() / 1e3
}

impl SessionVisitor for Bins {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics {
            joint_states: false,
            feedback: false,
            contacts: true,
            object: true,
        }
    }

    fn object(&mut self, log_time_ns: u64, _m: &ObjectState) -> services::error::Result<()> {
        self.origin_ns.get_or_insert(log_time_ns);
        Ok(())
    }

    fn contacts(&mut self, log_time_ns: u64, m: &Contacts) -> services::error::Result<()> {
        // The raw topics start together, tick by tick; a contact sample logged before the
        // first object state is before any skill.
        let Some(origin) = self.origin_ns else {
            return Ok(());
        };
        let t = log_time_ns.saturating_sub(origin);
        if t < self.start_ns || t > self.end_ns {
            return Ok(());
        }
        if self.names.is_empty() {
            self.names = m.fingers.iter().map(|f| f.name.clone()).collect();
        }
        let n = self.counts.len();
        let span = self.end_ns - self.start_ns;
        let b = (((t - self.start_ns) as u128 * n as u128 / span as u128) as usize).min(n - 1);
        let sums = &mut self.sums[b];
        if sums.len() < self.names.len() {
            sums.resize(self.names.len(), (0.0, 0.0));
        }
        for (s, f) in sums.iter_mut().zip(&m.fingers) {
            let tr = &f.transmitted;
            s.0 += tr.z;
            s.1 += tr.x.hypot(tr.y);
        }
        self.counts[b] += 1;
        Ok(())
    }
}
