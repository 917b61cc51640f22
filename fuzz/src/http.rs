//! The HTTP target: request bodies to the API's router in-process (`api::http::app` over a
//! store in a scratch directory, with the job workers that run its simulations and replays, as
//! `icms serve` builds it), one request per input through
//! `tower::ServiceExt::oneshot` on a current-thread runtime. A panic is a finding (the driver
//! catches it), and so is any 5xx answer.
//!
//! An input is `[endpoint, flags, body...]`: endpoint 0 `POST /api/v1/simulations`, 1 `POST
//! /api/v1/hands`, 2 `POST /api/v1/skills/{id}/replays`, 3 `POST /api/v1/sessions`. Flags
//! choose the skill id of a replay (flags 0: the stored skill, for 1 input in 32: a replay is
//! long work)
//! and, rarely, a wrong content type. Simulation bodies that parse get a short `duration`
//! (at most 60 ms of simulated time, the shortest accepted being 50 ms, or a refused one
//! just under it) so that an input stays short; the validation of
//! durations is fuzzed by the bodies that do not parse as an object, and the scenario
//! target covers scenario validation.

use axum::body::Body;
use axum::http::{header, Method, Request};
use axum::Router;
use http_body_util::BodyExt;
use serde_json::{json, Value};
use tower::ServiceExt;

use crate::mcap::McapFile;
use crate::rng::Rng;
use crate::seeds::{self, SeedError};
use crate::targets::{generate_mcap, rounds, Setup, Target};
use crate::{json, xml};

const ENDPOINTS: usize = 4;

/// The server's error log (`tracing` ERROR events), kept to explain a 5xx.
#[derive(Clone, Default)]
struct ErrorLog(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

impl std::io::Write for ErrorLog {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Ok(mut b) = self.0.lock() {
            // Bounded: only the latest request's errors matter.
            if b.len() < 1 << 16 {
                b.extend_from_slice(buf);
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for ErrorLog {
    type Writer = ErrorLog;

    fn make_writer(&'a self) -> Self::Writer {
        self.clone()
    }
}

impl ErrorLog {
    fn take(&self) -> String {
        self.0
            .lock()
            .map(|mut b| String::from_utf8_lossy(&std::mem::take(&mut *b)).into_owned())
            .unwrap_or_default()
    }
}

/// The HTTP target.
pub struct HttpTarget {
    rt: tokio::runtime::Runtime,
    app: Router,
    skill_id: i64,
    seeds: Vec<Vec<u8>>,
    json_seeds: [Vec<Value>; 3],
    mcap_raw: Vec<Vec<u8>>,
    mcap_parsed: Vec<McapFile>,
    hands: Vec<seeds::HandSeed>,
    log: ErrorLog,
    /// Stops the job workers when the target is dropped.
    _workers: WorkerGuard,
    _data: tempfile::TempDir,
}

/// The job workers of the target's server (`api::jobs::spawn_workers`, as `icms serve` starts
/// them): without them a simulation or replay request waits out the server's job wait (30 s)
/// for a job nobody runs, and answers 202.
struct WorkerGuard {
    stop: tokio_util::sync::CancellationToken,
    _set: tokio::task::JoinSet<()>,
}

impl Drop for WorkerGuard {
    fn drop(&mut self) {
        self.stop.cancel();
    }
}

fn err(what: &str, e: impl std::fmt::Display) -> SeedError {
    SeedError(format!("{what}: {e}"))
}

fn encode(endpoint: u8, flags: u8, body: &[u8]) -> Vec<u8> {
    let mut v = vec![endpoint, flags];
    v.extend_from_slice(body);
    v
}

impl HttpTarget {
    /// Opens a store in a scratch directory, stores one simulated session with its skills
    /// (for replays) and builds the router.
    pub fn new(setup: &Setup) -> Result<Self, SeedError> {
        let log = ErrorLog::default();
        let _ = tracing_subscriber::fmt()
            .with_max_level(tracing_subscriber::filter::LevelFilter::ERROR)
            .with_ansi(false)
            .without_time()
            .with_writer(log.clone())
            .try_init();
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| err("starting a runtime", e))?;
        let data = tempfile::Builder::new()
            .prefix("http-store-")
            .tempdir_in(&setup.scratch)
            .map_err(|e| err("making a data directory", e))?;
        let args = api::config::ServeArgs {
            store: api::config::StoreArgs::in_dir(data.path().to_path_buf()),
            no_demo: true,
            ..api::config::ServeArgs::default()
        };
        let config = args
            .into_config()
            .map_err(|e| err("server configuration", e))?;
        let full = seeds::full_session(&setup.scratch)?;
        let (app, skill_id, workers) = rt.block_on(async {
            let store = services::store::Store::open(&config.data)
                .await
                .map_err(|e| err("opening the store", e))?;
            let (meta, skills) = services::ingest::analyse(&full, "seed.mcap")
                .map_err(|e| err("analysing the seed session", e))?;
            let out = store
                .ingest(&full, meta, skills)
                .await
                .map_err(|e| err("storing the seed session", e))?;
            let skill_id = *out
                .skill_ids
                .first()
                .ok_or_else(|| err("storing the seed session", "no skills"))?;
            let state = api::http::AppState::new(store, &config.state)
                .map_err(|e| err("starting the live stepping threads", e))?;
            let stop = tokio_util::sync::CancellationToken::new();
            let set = api::jobs::spawn_workers(state.store(), &config.workers, state.jobs(), &stop);
            let workers = WorkerGuard { stop, _set: set };
            Ok::<_, SeedError>((api::http::app(state, &config.layers), skill_id, workers))
        })?;

        let hands = seeds::hands(&setup.hands_dir)?;
        let mut sims = vec![
            json!({"scenario": "sphere-lift", "seed": 7, "duration": 0.05}),
            json!({"scenario": "two-grasps", "duration": 0.06}),
        ];
        if let Some(s) = seeds::scenarios().into_iter().nth(1) {
            sims.push(json!({"scenario": s, "seed": 3, "duration": 0.05}));
        }
        let uploads: Vec<Value> = hands
            .iter()
            .map(|h| {
                let mut spec = h.spec.clone();
                spec["name"] = json!(format!("fuzz-{}", h.name));
                if let Some(o) = spec.as_object_mut() {
                    o.remove("urdf");
                }
                json!({"spec": spec, "urdf": h.urdf})
            })
            .collect();
        let replays = vec![
            json!({"hand": "gripper"}),
            json!({"hand": "allegro"}),
            json!({"hand": "glove10"}),
            json!({"hand": "fuzz-gripper"}),
        ];
        let mcap_raw = seeds::sessions(&setup.scratch)?;
        let mcap_parsed = mcap_raw.iter().filter_map(|b| McapFile::parse(b)).collect();
        let mut seeds_out = Vec::new();
        for (e, group) in [&sims, &uploads, &replays].into_iter().enumerate() {
            for v in group {
                seeds_out.push(encode(
                    e as u8,
                    1,
                    &serde_json::to_vec(v).unwrap_or_default(),
                ));
            }
        }
        // The stored skill replayed once, on the smallest hand.
        seeds_out.push(encode(2, 0, br#"{"hand": "gripper"}"#));
        for m in &mcap_raw {
            seeds_out.push(encode(3, 1, m));
        }
        Ok(HttpTarget {
            rt,
            app,
            skill_id,
            seeds: seeds_out,
            json_seeds: [sims, uploads, replays],
            mcap_raw,
            mcap_parsed,
            hands,
            log,
            _workers: workers,
            _data: data,
        })
    }

    fn request(&self, input: &[u8]) -> Request<Body> {
        let endpoint = input.first().copied().unwrap_or(0) as usize % ENDPOINTS;
        let flags = input.get(1).copied().unwrap_or(1);
        let body = input.get(2..).unwrap_or_default().to_vec();
        let path = match endpoint {
            0 => "/api/v1/simulations".to_owned(),
            1 => "/api/v1/hands".to_owned(),
            2 => {
                let id = match flags {
                    0 => self.skill_id.to_string(),
                    1..=200 => "999999".to_owned(),
                    201..=210 => "0".to_owned(),
                    211..=220 => "-1".to_owned(),
                    221..=230 => "99999999999999999999".to_owned(),
                    231..=240 => "abc".to_owned(),
                    _ => "1%00".to_owned(),
                };
                format!("/api/v1/skills/{id}/replays")
            }
            _ => "/api/v1/sessions".to_owned(),
        };
        let right = if endpoint == 3 {
            "application/x-mcap"
        } else {
            "application/json"
        };
        let content_type = match flags % 64 {
            63 => "text/plain",
            62 => "application/json; charset=utf-16",
            61 => "",
            _ => right,
        };
        let mut b = Request::builder().method(Method::POST).uri(path);
        if !content_type.is_empty() {
            b = b.header(header::CONTENT_TYPE, content_type);
        }
        b.body(Body::from(body)).unwrap_or_default()
    }

    /// A simulation body that parses gets a short duration.
    fn bound_simulation(rng: &mut Rng, body: Vec<u8>) -> Vec<u8> {
        let Ok(Value::Object(mut m)) = serde_json::from_slice::<Value>(&body) else {
            return body;
        };
        let long = match m.get("duration") {
            None | Some(Value::Null) => true,
            Some(v) => v.as_f64().is_some_and(|d| d > 0.06 && d <= 120.0),
        };
        if long {
            let d = *rng.pick(&[0.05, 0.05, 0.055, 0.06, 0.049, 0.001]);
            m.insert("duration".into(), json!(d));
        }
        serde_json::to_vec(&Value::Object(m)).unwrap_or(body)
    }
}

impl Target for HttpTarget {
    fn generate(&self, seed: u64, index: u64) -> Vec<u8> {
        if let Some(s) = self.seeds.get(index as usize) {
            return s.clone();
        }
        let mut rng = Rng::for_input("http", seed, index);
        let base = rng.pick(&self.seeds).clone();
        let mut endpoint = base[0];
        if rng.one_in(64) {
            endpoint = rng.below(ENDPOINTS) as u8;
        }
        // Flags 0 (the stored skill) only rarely: a replay is long work.
        let flags = match rng.byte() {
            _ if rng.one_in(32) => 0,
            0 => 1,
            f => f,
        };
        let body = &base[2..];
        let n = rounds(&mut rng);
        let out = match endpoint {
            3 => generate_mcap(&mut rng, &self.mcap_raw, &self.mcap_parsed),
            1 if rng.one_in(2) => {
                // The URDF or spec inside the upload, as the urdf target mutates them.
                let mut v: Value = serde_json::from_slice(body).unwrap_or(Value::Null);
                let urdfs: Vec<&str> = self.hands.iter().map(|h| h.urdf.as_str()).collect();
                if let Some(u) = v.get("urdf").and_then(Value::as_str) {
                    let mut u = u.to_owned();
                    for _ in 0..n {
                        xml::mutate(&mut rng, &mut u, &urdfs);
                    }
                    v["urdf"] = json!(u);
                }
                if rng.one_in(2) {
                    if let Some(spec) = v.get("spec").cloned() {
                        let t = json::mutate_value_text(&mut rng, &spec, &[], 1);
                        let s = String::from_utf8_lossy(&t).into_owned();
                        let text = serde_json::to_string(&v).unwrap_or_default();
                        let spec_text = serde_json::to_string(&spec).unwrap_or_default();
                        return encode(
                            endpoint,
                            flags,
                            text.replacen(&spec_text, &s, 1).as_bytes(),
                        );
                    }
                }
                serde_json::to_vec(&v).unwrap_or_default()
            }
            e => {
                let group = &self.json_seeds[(e as usize).min(2)];
                json::mutate_text(&mut rng, body, group, n)
            }
        };
        let out = if endpoint == 0 {
            Self::bound_simulation(&mut rng, out)
        } else {
            out
        };
        encode(endpoint, flags, &out)
    }

    fn run(&mut self, input: &[u8]) -> Result<(), String> {
        let req = self.request(input);
        let app = self.app.clone();
        let _ = self.log.take();
        let (status, body) = self.rt.block_on(async move {
            let resp = match app.oneshot(req).await {
                Ok(r) => r,
                Err(never) => match never {},
            };
            let status = resp.status();
            let body = resp
                .into_body()
                .collect()
                .await
                .map(|b| b.to_bytes().to_vec())
                .unwrap_or_default();
            (status, body)
        });
        if std::env::var_os("ICMS_FUZZ_VERBOSE").is_some() {
            let text: String = String::from_utf8_lossy(&body).chars().take(300).collect();
            eprintln!("HTTP {status}: {text}");
        }
        if status.is_server_error() {
            // The problem body hides an internal error's cause; the server's log has it.
            let logged = self.log.take();
            let cause = logged
                .lines()
                .find(|l| l.contains("ERROR"))
                .unwrap_or("")
                .trim();
            let text: String = String::from_utf8_lossy(&body).chars().take(200).collect();
            let cause: String = cause.chars().take(400).collect();
            return Err(format!("HTTP {status}: {cause} (body: {text})"));
        }
        Ok(())
    }

    fn seeds(&self) -> usize {
        self.seeds.len()
    }
}
