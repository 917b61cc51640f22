//! The whole flow over HTTP against the in-process server: simulate, upload, query, get,
//! download, similar skills, delete; pagination of sessions and skills.

use serde_json::{json, Value};
use tests::{session_bytes, TestApp};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_goes_from_simulation_and_upload_to_query_download_and_delete() {
    let app = TestApp::spawn().await;
    let c = &app.client;

    // Simulate server-side: two grasps in one session.
    let r = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "two-grasps", "seed": 3}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let sim = r.json();
    assert_eq!(sim["created"], true);
    let sim_id = sim["session_id"].as_i64().unwrap();
    assert_eq!(
        r.headers["location"].to_str().unwrap(),
        format!("/api/v1/sessions/{sim_id}")
    );
    assert_eq!(sim["skills"].as_array().unwrap().len(), 2, "{sim}");
    // A recording is a function of its scenario, seed and simulator version: the same request
    // again finds the same session stored (200, as a repeated upload), another seed does not.
    let r = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "two-grasps", "seed": 3}),
            None,
        )
        .await;
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["created"], false);
    assert_eq!(r.json()["session_id"], sim_id);

    // A scenario object, as a scenario file holds it.
    let mut scenario =
        serde_json::to_value(dfs_core::scenario::Scenario::builtin("box-pinch-lift", 0).unwrap())
            .unwrap();
    scenario["name"] = json!("my-lift");
    scenario["object"]["mass"] = json!(0.15);
    let r = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": scenario, "seed": 1}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let custom = r.json();
    let custom_id = custom["session_id"].as_i64().unwrap();

    // Upload a session file.
    let mcap = session_bytes("sphere-lift", 5, None);
    let r = c.upload(&mcap, None).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let up = r.json();
    let up_id = up["session_id"].as_i64().unwrap();
    let up_skills: Vec<i64> = up["skills"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_i64().unwrap())
        .collect();
    assert_eq!(up_skills.len(), 1);
    assert_eq!(up["skills"][0]["object_shape"], "sphere");

    // Query: filters match what each session holds.
    let page = c
        .get("/api/v1/skills?shape=box&contacts=2&sort=-quality")
        .await;
    assert_eq!(page.status, 200);
    let items = page.json()["items"].as_array().unwrap().clone();
    assert_eq!(items.len(), 3, "two from two-grasps, one from my-lift");
    let q: Vec<f64> = items
        .iter()
        .map(|s| s["quality"].as_f64().unwrap())
        .collect();
    assert!(
        q.windows(2).all(|w| w[0] >= w[1]),
        "best quality first: {q:?}"
    );
    let light = c.get("/api/v1/skills?shape=box&mass_max=0.16").await.json();
    let light = light["items"].as_array().unwrap();
    assert_eq!(light.len(), 1);
    assert_eq!(light[0]["session_id"], custom_id);
    let spheres = c
        .get("/api/v1/skills?shape=sphere&phase=hold&phase_min_s=0.5")
        .await
        .json();
    assert_eq!(spheres["items"][0]["id"], up_skills[0]);

    // Get one skill (twice: the second answer comes from the cache and must be identical).
    let one = c.get(&format!("/api/v1/skills/{}", up_skills[0])).await;
    assert_eq!(one.status, 200);
    assert_eq!(one.content_type(), "application/json");
    assert_eq!(one.json(), up["skills"][0]);
    let again = c.get(&format!("/api/v1/skills/{}", up_skills[0])).await;
    assert_eq!(again.body, one.body);

    // Similar skills leave the skill itself out.
    let near = c
        .get(&format!("/api/v1/skills/{}/similar?k=2", up_skills[0]))
        .await
        .json();
    let near = near["items"].as_array().unwrap();
    assert_eq!(near.len(), 2);
    assert!(near.iter().all(|n| n["skill_id"] != up_skills[0]));

    // Get the session and download its file: the bytes uploaded.
    let s = c.get(&format!("/api/v1/sessions/{up_id}")).await.json();
    assert_eq!(s["skill_ids"], json!(up_skills));
    assert_eq!(s["size_bytes"], mcap.len());
    assert_eq!(s["meta"]["scenario"], "sphere-lift");
    let file = c.get(s["mcap_url"].as_str().unwrap()).await;
    assert_eq!(file.status, 200);
    assert_eq!(file.content_type(), "application/x-mcap");
    assert!(file.body == mcap, "the download is the uploaded file");

    // Delete one skill of the simulated session: its session stays.
    let sim_skill = sim["skills"][0]["id"].as_i64().unwrap();
    assert_eq!(
        c.delete(&format!("/api/v1/skills/{sim_skill}"), None)
            .await
            .status,
        204
    );
    c.get(&format!("/api/v1/skills/{sim_skill}"))
        .await
        .problem(404);
    let s = c.get(&format!("/api/v1/sessions/{sim_id}")).await.json();
    assert_eq!(s["skill_ids"].as_array().unwrap().len(), 1);

    // Delete the uploaded session: its skills and its blob go too.
    let blob_files = |dir: &std::path::Path| -> usize {
        walk(&dir.join("blobs"))
            .into_iter()
            .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
            .count()
    };
    assert_eq!(blob_files(&app.data), 3);
    assert_eq!(
        c.delete(&format!("/api/v1/sessions/{up_id}"), None)
            .await
            .status,
        204
    );
    c.get(&format!("/api/v1/sessions/{up_id}"))
        .await
        .problem(404);
    c.get(&format!("/api/v1/sessions/{up_id}/mcap"))
        .await
        .problem(404);
    c.get(&format!("/api/v1/skills/{}", up_skills[0]))
        .await
        .problem(404);
    assert_eq!(blob_files(&app.data), 2);
    let all = c.get("/api/v1/skills?limit=1000").await.json();
    assert_eq!(all["items"].as_array().unwrap().len(), 2);

    let health = c.get("/healthz").await.json();
    assert_eq!(health["status"], "ok");
    assert_eq!(health["skills"], 2);
    app.stop().await;
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(walk(&p));
            } else {
                out.push(p);
            }
        }
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pages_of_sessions_and_skills_follow_their_cursors_to_the_end() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    for seed in 0..3 {
        let r = c
            .post_json(
                "/api/v1/simulations",
                &json!({"scenario": "two-grasps", "seed": seed, "duration": 12.0}),
                None,
            )
            .await;
        assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    }
    let mut sessions = Vec::new();
    let mut url = "/api/v1/sessions?limit=2".to_string();
    loop {
        let page = c.get(&url).await;
        assert_eq!(page.status, 200);
        let page = page.json();
        sessions.extend(
            page["items"]
                .as_array()
                .unwrap()
                .iter()
                .map(|s| s["id"].clone()),
        );
        match page["next_cursor"].as_str() {
            Some(cur) => url = format!("/api/v1/sessions?limit=2&cursor={cur}"),
            None => break,
        }
    }
    assert_eq!(sessions, vec![json!(1), json!(2), json!(3)]);

    let all: Value = c
        .get("/api/v1/skills?sort=duration:desc&limit=1000")
        .await
        .json();
    let all = all["items"].as_array().unwrap().clone();
    let mut paged = Vec::new();
    let mut url = "/api/v1/skills?sort=duration:desc&limit=2".to_string();
    loop {
        let page = c.get(&url).await.json();
        paged.extend(page["items"].as_array().unwrap().iter().cloned());
        match page["next_cursor"].as_str() {
            Some(cur) => url = format!("/api/v1/skills?sort=duration:desc&limit=2&cursor={cur}"),
            None => break,
        }
    }
    assert!(all.len() >= 3, "{} skills", all.len());
    assert_eq!(paged, all, "pages add up to the whole list, in order");
    app.stop().await;
}

/// The ids of a page of `GET /api/v1/sessions...` and its cursor.
async fn session_ids(c: &tests::Client, url: &str) -> (Vec<i64>, Option<String>) {
    let r = c.get(url).await;
    assert_eq!(r.status, 200, "{url}: {}", String::from_utf8_lossy(&r.body));
    let page = r.json();
    let ids = page["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_i64().unwrap())
        .collect();
    (ids, page["next_cursor"].as_str().map(str::to_owned))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_filter_by_scenario_hand_and_shape_newest_first_in_pages() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let mut stored = Vec::new();
    for (scenario, seed) in [
        ("sphere-lift", 1),
        ("box-pinch-lift", 1),
        ("sphere-lift", 2),
        ("box-pinch-lift", 2),
    ] {
        let r = c
            .upload(&tests::session_bytes(scenario, seed, None), None)
            .await;
        assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
        stored.push(r.json()["session_id"].as_i64().unwrap());
    }
    let [s1, b1, s2, b2] = stored[..] else {
        unreachable!()
    };
    let hand = c.get(&format!("/api/v1/sessions/{s1}")).await.json()["meta"]["hand"]
        .as_str()
        .unwrap()
        .to_owned();

    // Oldest first by default (as before), newest first with sort=-id or id:desc.
    assert_eq!(session_ids(c, "/api/v1/sessions").await.0, [s1, b1, s2, b2]);
    assert_eq!(
        session_ids(c, "/api/v1/sessions?sort=-id").await.0,
        [b2, s2, b1, s1]
    );
    assert_eq!(
        session_ids(c, "/api/v1/sessions?sort=id:desc").await.0,
        [b2, s2, b1, s1]
    );
    // Newest first, one per page, follows its cursors to the end.
    let mut paged = Vec::new();
    let mut url = "/api/v1/sessions?sort=-id&limit=1".to_owned();
    loop {
        let (ids, next) = session_ids(c, &url).await;
        assert_eq!(ids.len(), 1, "{url}");
        paged.extend(ids);
        match next {
            Some(cur) => url = format!("/api/v1/sessions?sort=-id&limit=1&cursor={cur}"),
            None => break,
        }
    }
    assert_eq!(paged, [b2, s2, b1, s1]);

    // Filters, alone and together, in either order and across pages.
    assert_eq!(
        session_ids(c, "/api/v1/sessions?scenario=sphere-lift&sort=-id")
            .await
            .0,
        [s2, s1]
    );
    assert_eq!(
        session_ids(c, "/api/v1/sessions?shape=box").await.0,
        [b1, b2]
    );
    assert_eq!(
        session_ids(c, &format!("/api/v1/sessions?hand={hand}&sort=-id"))
            .await
            .0,
        [b2, s2, b1, s1]
    );
    assert_eq!(
        session_ids(c, "/api/v1/sessions?scenario=box-pinch-lift&shape=sphere")
            .await
            .0,
        Vec::<i64>::new()
    );
    assert_eq!(
        session_ids(c, "/api/v1/sessions?hand=no-such-hand").await,
        (vec![], None)
    );
    let (first, cursor) = session_ids(
        c,
        "/api/v1/sessions?scenario=box-pinch-lift&sort=-id&limit=1",
    )
    .await;
    assert_eq!(first, [b2]);
    let cursor = cursor.expect("a second page");
    assert_eq!(
        session_ids(
            c,
            &format!("/api/v1/sessions?scenario=box-pinch-lift&sort=-id&limit=1&cursor={cursor}")
        )
        .await,
        (vec![b1], None)
    );

    // Refused: another sort, an unknown shape, and a cursor of the other order.
    let detail = c.get("/api/v1/sessions?sort=quality").await.problem(400);
    assert!(detail.contains("\"quality\""), "{detail}");
    let detail = c.get("/api/v1/sessions?shape=torus").await.problem(400);
    assert!(detail.contains("torus"), "{detail}");
    let (_, ascending) = session_ids(c, "/api/v1/sessions?limit=1").await;
    c.get(&format!(
        "/api/v1/sessions?sort=-id&limit=1&cursor={}",
        ascending.unwrap()
    ))
    .await
    .problem(400);
    app.stop().await;
}
