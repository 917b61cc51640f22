//! Issue 22 over plain HTTP (the browser test is `web_page.rs`): the page's routes and files,
//! HTML not-found pages outside the API and problems inside it, the endpoints the page reads
//! (skill summaries, similar skills with summaries, a skill's contact forces, a hand's
//! geometry, a replay's frames), phase durations as rounded objects, and MCAP downloads that
//! answer `Range`, `ETag` and the CORS a viewer reading a file by URL needs.

use reqwest::header::{
    ACCEPT_RANGES, ACCESS_CONTROL_ALLOW_HEADERS, ACCESS_CONTROL_ALLOW_ORIGIN,
    ACCESS_CONTROL_EXPOSE_HEADERS, CONTENT_RANGE, CONTENT_SECURITY_POLICY, ETAG,
};
use reqwest::Method;
use serde_json::Value;
use tests::{session_bytes, TestApp};

async fn raw(
    app: &TestApp,
    method: Method,
    path: &str,
    headers: &[(&str, &str)],
) -> reqwest::Response {
    let mut req = reqwest::Client::new().request(method, format!("{}{path}", app.client.base));
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    req.send().await.expect("request")
}

/// The main page's own scripts (not the docs page's, nor vendored ones).
const OWN_SCRIPTS: [&str; 5] = [
    "/assets/app.js",
    "/assets/api.js",
    "/assets/dom.js",
    "/assets/plot.js",
    "/assets/scene.js",
];

#[tokio::test]
async fn the_page_its_files_and_not_found_pages() {
    let app = TestApp::spawn().await;
    for path in ["/", "/docs"] {
        let r = app.client.get(path).await;
        assert_eq!(r.status, 200, "{path}");
        assert_eq!(r.content_type(), "text/html; charset=utf-8", "{path}");
        let csp = r.headers[CONTENT_SECURITY_POLICY].to_str().unwrap();
        assert!(csp.contains("script-src 'self'"), "{csp}");
    }
    let page = String::from_utf8(app.client.get("/").await.body.to_vec()).unwrap();
    // Every file the pages name is served, with a JavaScript or CSS media type.
    for asset in OWN_SCRIPTS.into_iter().chain([
        "/assets/style.css",
        "/assets/docs.js",
        "/assets/vendor/three/three.module.js",
        "/assets/vendor/three/three.core.js",
        "/assets/vendor/uplot/uPlot.esm.js",
        "/assets/vendor/uplot/uPlot.min.css",
        "/assets/vendor/swagger-ui/swagger-ui-bundle.js",
        "/assets/vendor/swagger-ui/swagger-ui.css",
        "/assets/vendor/three/LICENSE",
    ]) {
        let r = app.client.get(asset).await;
        assert_eq!(r.status, 200, "{asset}");
        let ct = r.content_type();
        let want = if asset.ends_with(".js") {
            "text/javascript"
        } else if asset.ends_with(".css") {
            "text/css"
        } else {
            "text/plain"
        };
        assert!(ct.starts_with(want), "{asset}: {ct}");
    }
    assert!(page.contains("/assets/app.js"), "{page}");
    // The page's own scripts never parse strings as HTML: data base strings go in as text.
    for asset in OWN_SCRIPTS {
        let text = String::from_utf8(app.client.get(asset).await.body.to_vec()).unwrap();
        for sink in [
            ".innerHTML",
            ".outerHTML",
            "insertAdjacentHTML",
            "document.write",
            "eval(",
        ] {
            assert!(!text.contains(sink), "{asset} uses {sink}");
        }
    }
    // No page fetches anything from another host.
    for asset in ["/", "/docs", "/assets/app.js", "/assets/docs.js"] {
        let text = String::from_utf8(app.client.get(asset).await.body.to_vec()).unwrap();
        for needle in ["http://", "https://"] {
            for (i, _) in text.match_indices(needle) {
                let around = &text[i..(i + 40).min(text.len())];
                assert!(
                    around.starts_with("https://app.foxglove.dev"),
                    "{asset} names another host: {around}"
                );
            }
        }
    }
    // Unknown pages: HTML for people; the API's paths keep their problems.
    for path in ["/nope", "/skills/1", "/assets/nope.js", "/docs/x"] {
        let r = app.client.get(path).await;
        assert_eq!(r.status, 404, "{path}");
        assert_eq!(r.content_type(), "text/html; charset=utf-8", "{path}");
        assert!(String::from_utf8_lossy(&r.body).contains("Page not found"));
    }
    for path in ["/api/v1/nope", "/api/nope", "/api"] {
        let d = app.client.get(path).await.problem(404);
        assert!(d.contains("no such route"), "{path}: {d}");
    }
    // A method the page's routes do not take is a problem too.
    app.client
        .send(Method::POST, "/", None, None)
        .await
        .problem(405);
    app.stop().await;
}

#[tokio::test]
async fn summaries_similar_forces_geometry_and_frames() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    for (scenario, seed) in [
        ("sphere-lift", 1),
        ("box-pinch-lift", 1),
        ("sphere-lift", 4),
    ] {
        let r = c.upload(&session_bytes(scenario, seed, None), None).await;
        assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    }
    let full = c.get("/api/v1/skills?sort=-quality&limit=2").await.json();
    let brief = c
        .get("/api/v1/skills/summaries?sort=-quality&limit=2")
        .await
        .json();
    assert_eq!(full["next_cursor"], brief["next_cursor"]);
    let ids = |page: &Value| -> Vec<i64> {
        page["items"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["id"].as_i64().unwrap())
            .collect()
    };
    assert_eq!(ids(&full), ids(&brief));
    for (f, b) in full["items"]
        .as_array()
        .unwrap()
        .iter()
        .zip(brief["items"].as_array().unwrap())
    {
        for key in [
            "id",
            "session_id",
            "object_shape",
            "object_mass",
            "mu",
            "contact_count",
            "contact_model",
            "grasp_type",
            "quality",
            "duration_s",
            "created_at",
        ] {
            assert_eq!(f[key], b[key], "{key}");
        }
        assert!(b.get("params").is_none() && b.get("feature").is_none());
        assert!(serde_json::to_vec(b).unwrap().len() < 400, "{b}");
        // Phase durations: objects, to the millisecond.
        for d in f["phase_durations"].as_array().unwrap() {
            let s = d["seconds"].as_f64().unwrap();
            assert!(d["phase"].is_string(), "{d}");
            assert_eq!(s, (s * 1e3).round() / 1e3, "{d}");
        }
    }
    c.get("/api/v1/skills/summaries?shape=torus")
        .await
        .problem(400);
    c.get("/api/v1/skills/summaries?colour=red")
        .await
        .problem(400);

    // Similar skills come with their summaries.
    let id = ids(&full)[0];
    let near = c
        .get(&format!("/api/v1/skills/{id}/similar?k=5"))
        .await
        .json();
    let items = near["items"].as_array().unwrap();
    assert_eq!(items.len(), 2, "{near}");
    for n in items {
        let other = c.get("/api/v1/skills/summaries?limit=1000").await.json()["items"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["id"] == n["skill_id"])
            .cloned()
            .expect("the neighbour is stored");
        assert_eq!(n["skill"], other, "{n}");
    }

    // A skill's contact forces: bounded, on the skill's span, the fingers of its contacts
    // pushing.
    let skill = c.get(&format!("/api/v1/skills/{id}")).await.json();
    let f = c
        .get(&format!("/api/v1/skills/{id}/forces?points=50"))
        .await
        .json();
    let t = f["time_s"].as_array().unwrap();
    assert!(t.len() > 40 && t.len() <= 50, "{}", t.len());
    let (start, end) = (
        skill["start_ns"].as_f64().unwrap() * 1e-9,
        skill["end_ns"].as_f64().unwrap() * 1e-9,
    );
    for w in t.windows(2) {
        assert!(w[0].as_f64() < w[1].as_f64());
    }
    assert!(t[0].as_f64().unwrap() >= start && t.last().unwrap().as_f64().unwrap() <= end);
    let fingers = f["fingers"].as_array().unwrap();
    let pushing: Vec<&str> = fingers
        .iter()
        .filter(|g| {
            g["normal_n"]
                .as_array()
                .unwrap()
                .iter()
                .any(|v| v.as_f64().unwrap() > 1.0)
        })
        .map(|g| g["finger"].as_str().unwrap())
        .collect();
    let contacts: Vec<&str> = skill["params"]["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["finger"].as_str().unwrap())
        .collect();
    for finger in &contacts {
        assert!(pushing.contains(finger), "{finger} does not push: {f}");
    }
    for g in fingers {
        assert_eq!(g["normal_n"].as_array().unwrap().len(), t.len());
        assert_eq!(g["tangential_n"].as_array().unwrap().len(), t.len());
    }
    c.get(&format!("/api/v1/skills/{id}/forces?points=5"))
        .await
        .problem(400);
    c.get("/api/v1/skills/999/forces").await.problem(404);

    // Every built-in hand's geometry: its links, each with a solid, its fingertips flagged.
    let hands = c.get("/api/v1/hands").await.json();
    for h in hands["items"].as_array().unwrap() {
        let name = h["name"].as_str().unwrap();
        let g = c
            .get(&format!("/api/v1/hands/{name}/geometry"))
            .await
            .json();
        let links = g["links"].as_array().unwrap();
        assert!(!links.is_empty(), "{name}");
        let tips = links
            .iter()
            .flat_map(|l| l["shapes"].as_array().unwrap())
            .filter(|s| s["fingertip"] == true)
            .count();
        assert_eq!(tips, h["fingers"].as_array().unwrap().len(), "{name}");
        for l in links {
            assert_eq!(l["pose"].as_array().unwrap().len(), 7);
        }
    }
    c.get("/api/v1/hands/nope/geometry").await.problem(404);

    // A replay's frames: at the asked rate, one pose per link and the object per frame,
    // contact forces while it holds.
    let r = c
        .post_json(
            &format!("/api/v1/skills/{id}/replays"),
            &serde_json::json!({"hand": "barrett"}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let replay = r.json()["replay_id"].as_i64().unwrap();
    let fr = c
        .get(&format!("/api/v1/replays/{replay}/frames?fps=20"))
        .await
        .json();
    let n = fr["time_s"].as_array().unwrap().len();
    let links = fr["links"].as_array().unwrap().len();
    assert!(n > 20, "{n}");
    let dt = fr["time_s"][1].as_f64().unwrap() - fr["time_s"][0].as_f64().unwrap();
    assert!((dt - 0.05).abs() < 0.0015, "{dt}");
    assert_eq!(fr["object_pose"].as_array().unwrap().len(), n);
    assert_eq!(fr["link_poses"].as_array().unwrap().len(), n);
    for poses in fr["link_poses"].as_array().unwrap() {
        assert_eq!(poses.as_array().unwrap().len(), links);
    }
    let touching = fr["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| !c.as_array().unwrap().is_empty())
        .count();
    assert!(touching > n / 4, "{touching} of {n} frames with contacts");
    c.get(&format!("/api/v1/replays/{replay}/frames?fps=0"))
        .await
        .problem(400);
    c.get("/api/v1/replays/999/frames").await.problem(404);
    app.stop().await;
}

#[tokio::test]
async fn mcap_downloads_answer_ranges_etags_and_cors() {
    let origin = "https://app.foxglove.dev";
    let app = TestApp::spawn_with(|a| a.cors_origins = vec![origin.into()]).await;
    let bytes = session_bytes("sphere-lift", 1, Some(1.0));
    let up = app.client.upload(&bytes, None).await.json();
    let url = format!("/api/v1/sessions/{}/mcap", up["session_id"]);

    let whole = raw(&app, Method::GET, &url, &[]).await;
    assert_eq!(whole.status(), 200);
    assert_eq!(whole.headers()[ACCEPT_RANGES], "bytes");
    let etag = whole.headers()[ETAG].to_str().unwrap().to_owned();
    assert_eq!(etag.len(), 66, "{etag}");
    assert_eq!(whole.bytes().await.unwrap().as_ref(), bytes.as_slice());

    let part = raw(&app, Method::GET, &url, &[("Range", "bytes=8-107")]).await;
    assert_eq!(part.status(), 206);
    assert_eq!(
        part.headers()[CONTENT_RANGE],
        format!("bytes 8-107/{}", bytes.len()).as_str()
    );
    assert_eq!(part.bytes().await.unwrap().as_ref(), &bytes[8..108]);
    let tail = raw(&app, Method::GET, &url, &[("Range", "bytes=-16")]).await;
    assert_eq!(tail.status(), 206);
    assert_eq!(
        tail.bytes().await.unwrap().as_ref(),
        &bytes[bytes.len() - 16..]
    );
    let past = raw(
        &app,
        Method::GET,
        &url,
        &[("Range", &format!("bytes={}-", bytes.len()))],
    )
    .await;
    assert_eq!(past.status(), 416);
    assert_eq!(
        past.headers()[CONTENT_RANGE],
        format!("bytes */{}", bytes.len()).as_str()
    );
    let same = raw(&app, Method::GET, &url, &[("If-None-Match", &etag)]).await;
    assert_eq!(same.status(), 304);
    // A stale If-Range: the whole file.
    let stale = raw(
        &app,
        Method::GET,
        &url,
        &[("Range", "bytes=0-9"), ("If-Range", "\"0000\"")],
    )
    .await;
    assert_eq!(stale.status(), 200);

    // A browser app on the allowed origin may ask for ranges and read the answers' headers.
    let pre = raw(
        &app,
        Method::OPTIONS,
        &url,
        &[
            ("Origin", origin),
            ("Access-Control-Request-Method", "GET"),
            ("Access-Control-Request-Headers", "range"),
        ],
    )
    .await;
    assert!(pre.status().is_success(), "{}", pre.status());
    assert_eq!(pre.headers()[ACCESS_CONTROL_ALLOW_ORIGIN], origin);
    let allowed = pre.headers()[ACCESS_CONTROL_ALLOW_HEADERS]
        .to_str()
        .unwrap()
        .to_ascii_lowercase();
    assert!(allowed.contains("range"), "{allowed}");
    let got = raw(
        &app,
        Method::GET,
        &url,
        &[("Origin", origin), ("Range", "bytes=0-9")],
    )
    .await;
    assert_eq!(got.status(), 206);
    let exposed = got.headers()[ACCESS_CONTROL_EXPOSE_HEADERS]
        .to_str()
        .unwrap()
        .to_ascii_lowercase();
    for h in ["content-range", "accept-ranges", "etag", "content-length"] {
        assert!(exposed.contains(h), "{exposed}");
    }
    app.stop().await;
}

/// A skill's forces read its session's stored file: a file gone from the data directory is a
/// 404 naming the session, a file that no longer reads as a recording a 500 naming it (never
/// a bare "internal error").
#[tokio::test]
async fn forces_of_a_session_whose_file_is_gone_or_damaged_name_it() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let r = c
        .upload(&session_bytes("sphere-lift", 2, Some(3.0)), None)
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let stored = r.json();
    let skill = stored["skills"][0]["id"].as_i64().unwrap();
    let session = stored["session_id"].as_i64().unwrap();
    let blobs: Vec<_> = walk(&app.data.join("blobs"));
    assert_eq!(blobs.len(), 1, "{blobs:?}");
    let path = format!("/api/v1/skills/{skill}/forces");

    std::fs::write(&blobs[0], b"not an MCAP file").unwrap();
    let damaged = c.get(&path).await;
    assert_eq!(damaged.status, 500);
    let detail = damaged.json()["detail"].as_str().unwrap().to_owned();
    assert!(detail.contains(&format!("session {session}")), "{detail}");
    assert!(detail.contains("does not read as a recording"), "{detail}");

    std::fs::remove_file(&blobs[0]).unwrap();
    let gone = c.get(&path).await;
    assert_eq!(gone.status, 404);
    let detail = gone.json()["detail"].as_str().unwrap().to_owned();
    assert!(detail.contains(&format!("session {session}")), "{detail}");
    assert!(
        detail.contains("missing from the data directory"),
        "{detail}"
    );
}

/// Every file under `dir`, recursively.
fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}
