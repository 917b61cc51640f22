//! The OpenAPI document: valid OpenAPI 3.1 (checked by Python's openapi-spec-validator, which
//! `.ci/run` installs), and its (method, path) pairs are exactly the routes the server answers.

use crate::interpreter;

use std::collections::BTreeSet;
use std::io::Write;
use std::process::{Command, Stdio};

use reqwest::Method;
use serde_json::Value;
use tests::TestApp;

/// Every endpoint the issue asks for.
const ENDPOINTS: &[(&str, &str)] = &[
    ("get", "/api/v1/openapi.json"),
    ("get", "/api/v1/sessions"),
    ("post", "/api/v1/sessions"),
    ("get", "/api/v1/sessions/{id}"),
    ("delete", "/api/v1/sessions/{id}"),
    ("get", "/api/v1/sessions/{id}/mcap"),
    ("post", "/api/v1/simulations"),
    ("get", "/api/v1/skills"),
    ("get", "/api/v1/skills/{id}"),
    ("delete", "/api/v1/skills/{id}"),
    ("get", "/api/v1/skills/{id}/similar"),
    ("get", "/api/v1/skills/summaries"),
    ("get", "/api/v1/skills/{id}/forces"),
    ("get", "/api/v1/hands/{id}/geometry"),
    ("get", "/api/v1/replays/{id}/frames"),
    ("get", "/api/v1/skills/{id}/replays"),
    ("post", "/api/v1/skills/{id}/replays"),
    ("get", "/api/v1/hands"),
    ("post", "/api/v1/hands"),
    ("get", "/api/v1/hands/{id}"),
    ("get", "/api/v1/hands/{id}/urdf"),
    ("get", "/api/v1/replays/{id}"),
    ("get", "/api/v1/replays/{id}/mcap"),
    ("get", "/api/v1/jobs"),
    ("get", "/api/v1/jobs/{id}"),
    ("delete", "/api/v1/jobs/{id}"),
    ("get", "/api/v1/live"),
    ("get", "/api/v1/live/schema"),
    ("get", "/healthz"),
];

const METHODS: &[&str] = &["get", "post", "put", "patch", "delete"];

fn documented(doc: &Value) -> BTreeSet<(String, String)> {
    let mut out = BTreeSet::new();
    for (path, item) in doc["paths"].as_object().expect("paths") {
        for m in METHODS {
            if item.get(*m).is_some() {
                out.insert((m.to_string(), path.clone()));
            }
        }
    }
    out
}

/// Validates with openapi-spec-validator; panics with its message if invalid.
fn validate_with_python(doc: &Value) {
    let script = "import json, sys\n\
                  from openapi_spec_validator import validate\n\
                  validate(json.load(sys.stdin))\n\
                  print('valid')\n";
    let Some(python) = interpreter::python_with(&["openapi_spec_validator"]) else {
        return;
    };
    let mut child = Command::new(python)
        .args(["-c", script])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("running the OpenAPI validator");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(doc.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success() && out.stdout.starts_with(b"valid"),
        "the OpenAPI document is invalid (or openapi-spec-validator is missing: \
         pip install openapi-spec-validator):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[tokio::test]
async fn the_openapi_document_is_valid_and_lists_every_endpoint() {
    let app = TestApp::spawn().await;
    let r = app.client.get("/api/v1/openapi.json").await;
    assert_eq!(r.status, 200);
    assert_eq!(r.content_type(), "application/json");
    let doc = r.json();
    assert!(
        doc["openapi"].as_str().unwrap().starts_with("3.1"),
        "{}",
        doc["openapi"]
    );
    validate_with_python(&doc);

    let expected: BTreeSet<(String, String)> = ENDPOINTS
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    assert_eq!(documented(&doc), expected);

    // Every filter of the store is a documented query parameter of GET /skills.
    let params: BTreeSet<&str> = doc["paths"]["/api/v1/skills"]["get"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    for name in [
        "shape",
        "mass_min",
        "mass_max",
        "mu_min",
        "mu_max",
        "contacts",
        "contact_model",
        "grasp_type",
        "min_quality",
        "phase",
        "phase_min_s",
        "phase_max_s",
        "sort",
        "limit",
        "cursor",
    ] {
        assert!(params.contains(name), "GET /skills documents {name}");
    }
    // Without a token configured, writes carry no security requirement.
    let upload = &doc["paths"]["/api/v1/sessions"]["post"];
    assert!(upload.get("security").is_none(), "{upload}");
    assert_eq!(
        upload["requestBody"]["content"]
            .as_object()
            .unwrap()
            .keys()
            .collect::<Vec<_>>(),
        ["application/x-mcap"]
    );
    // The schemas' bounds are the code's: a hand spec takes up to MAX_TIPS fingertips (the
    // document said 5 while uploads of 6 were accepted), a replay's peak torque ratio is of
    // the clamped torque.
    let schemas = &doc["components"]["schemas"];
    assert_eq!(
        schemas["HandSpec"]["properties"]["fingertips"]["maxItems"],
        dfs_core::hand::MAX_TIPS,
        "{}",
        schemas["HandSpec"]
    );
    assert_eq!(
        schemas["ReplayReport"]["properties"]["peak_torque_ratio"]["maximum"], 1.0,
        "{}",
        schemas["ReplayReport"]
    );
    // The scenario's schemas are dfs-core's own types: the object's shape is dfs-core's shape
    // kind, with its names, and a task's phase is dfs-core's phase.
    use dfs_core::names::Named;
    assert_eq!(
        schemas["ScenarioObject"]["properties"]["shape"]["$ref"],
        "#/components/schemas/ShapeKind"
    );
    assert_eq!(
        schemas["ShapeKind"]["enum"],
        serde_json::json!(dfs_core::object::ShapeKind::names())
    );
    assert_eq!(
        schemas["Phase"]["enum"],
        serde_json::json!(dfs_core::scenario::Phase::names())
    );
    app.stop().await;
}

#[tokio::test]
async fn the_router_answers_exactly_the_documented_methods_and_paths() {
    let app = TestApp::spawn().await;
    let doc = app.client.get("/api/v1/openapi.json").await.json();
    let documented = documented(&doc);
    let paths: BTreeSet<&String> = documented.iter().map(|(_, p)| p).collect();
    for path in paths {
        let url = path.replace("{id}", "999");
        for m in METHODS {
            let method = Method::from_bytes(m.to_uppercase().as_bytes()).unwrap();
            let r = app.client.send(method, &url, None, None).await;
            let is_route = r.status != 405
                && !(r.status == 404
                    && r.json()["detail"]
                        .as_str()
                        .unwrap()
                        .contains("no such route"));
            assert_eq!(
                is_route,
                documented.contains(&(m.to_string(), path.clone())),
                "{m} {url} answered {}: {}",
                r.status,
                String::from_utf8_lossy(&r.body)
            );
            assert_ne!(r.status, 500, "{m} {url}");
        }
    }
    app.stop().await;
}

#[tokio::test]
async fn with_a_token_configured_the_document_requires_it_on_writes_only() {
    let app = TestApp::spawn_with(|a| a.token = Some("tok".into())).await;
    let doc = app.client.get("/api/v1/openapi.json").await.json();
    validate_with_python(&doc);
    assert_eq!(
        doc["components"]["securitySchemes"]["bearer"]["scheme"],
        "bearer"
    );
    for (m, p) in documented(&doc) {
        let op = &doc["paths"][&p][&m];
        // Opening a live session (a WebSocket upgrade, a GET) stores a session: it writes.
        let writes = m != "get" || p == "/api/v1/live";
        let secured = op["security"] == serde_json::json!([{"bearer": []}]);
        assert_eq!(secured, writes, "{m} {p}: {}", op["security"]);
        assert_eq!(op["responses"].get("401").is_some(), writes, "{m} {p}");
        // The responses every operation with a body shares: declared once, on every one.
        let responses = &op["responses"];
        assert_eq!(
            responses.get("413").is_some(),
            op.get("requestBody").is_some(),
            "{m} {p}"
        );
        if let Some(body) = op.get("requestBody") {
            let types: Vec<&String> = body["content"].as_object().unwrap().keys().collect();
            let d415 = responses["415"]["description"].as_str().unwrap();
            assert!(
                types.iter().all(|t| d415.contains(t.as_str())),
                "{m} {p}: {d415}"
            );
        }
        for status in ["401", "413", "415", "503"] {
            if let Some(r) = responses.get(status) {
                assert!(
                    r["content"].get("application/problem+json").is_some(),
                    "{m} {p} {status}: {r}"
                );
            }
        }
    }
    app.stop().await;
}

/// Sends `request` over a fresh connection; returns the status and the body of the answer.
async fn raw(app: &TestApp, request: &[u8]) -> (u16, Value) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(app.addr).await.unwrap();
    stream.write_all(request).await.unwrap();
    let mut answer = Vec::new();
    // Every request here ends with `Connection: close`.
    stream.read_to_end(&mut answer).await.unwrap();
    let answer = String::from_utf8(answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").expect("a whole answer");
    let status = head[9..12].parse().unwrap();
    assert!(
        head.to_ascii_lowercase()
            .contains("content-type: application/problem+json"),
        "{head}"
    );
    (status, serde_json::from_str(body).expect("a JSON problem"))
}

/// Requests the well-behaved clients of the other tests never send (a body that is not valid
/// chunked encoding, a path that is not UTF-8) are answered with statuses the document lists
/// for their operation; and every operation lists 503, which the time limit (and a server
/// that is stopping) gives on any route.
#[tokio::test]
async fn odd_requests_get_statuses_the_document_lists_for_their_operation() {
    let app = TestApp::spawn().await;
    let doc = app.client.get("/api/v1/openapi.json").await.json();
    let cases: &[(&str, &str, &str)] = &[
        (
            "post",
            "/api/v1/sessions",
            "POST /api/v1/sessions HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\
             Content-Type: application/x-mcap\r\nTransfer-Encoding: chunked\r\n\r\n\
             ZZ\r\nhello\r\n0\r\n\r\n",
        ),
        (
            "post",
            "/api/v1/simulations",
            "POST /api/v1/simulations HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\
             Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n\
             ZZ\r\nhello\r\n0\r\n\r\n",
        ),
        (
            "get",
            "/api/v1/hands/{id}",
            "GET /api/v1/hands/%ff%fe HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
        ),
        (
            "get",
            "/api/v1/hands/{id}/urdf",
            "GET /api/v1/hands/%ff%fe/urdf HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
        ),
    ];
    for (method, path, request) in cases {
        let (status, problem) = raw(&app, request.as_bytes()).await;
        assert_eq!(status, 400, "{method} {path}: {problem}");
        assert!(
            doc["paths"][path][method]["responses"]
                .get(status.to_string())
                .is_some(),
            "{method} {path} answers {status} ({problem}) but the document does not list it"
        );
    }
    for (m, p) in documented(&doc) {
        let r = &doc["paths"][&p][&m]["responses"]["503"];
        assert!(
            r["content"]["application/problem+json"].is_object(),
            "{m} {p} does not list 503: {r}"
        );
    }
    assert_eq!(
        app.client.get("/api/v1/sessions").await.json()["items"],
        serde_json::json!([])
    );
    app.stop().await;
}
