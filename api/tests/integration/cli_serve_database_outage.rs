//! `icms serve` on PostgreSQL losing its data base while serving (issue 24, bad input): the
//! requests that need it answer 503 problems with `Retry-After`, the server goes on, and it
//! answers again once the data base is back, without a restart; nothing accepted is lost.
//! The outage is a TCP relay between the server and the test PostgreSQL that the test stops
//! (closing every relayed connection) and starts again on the same port.

use crate::common;

use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::pg::{fresh_schema, postgres_or_skip};
use common::server::Running;

/// Relays 127.0.0.1:`port` to `target` while up.
struct Relay {
    port: u16,
    target: String,
    up: Arc<AtomicBool>,
    open: Arc<Mutex<Vec<TcpStream>>>,
    accept: Option<std::thread::JoinHandle<()>>,
}

impl Relay {
    fn start(target: &str) -> Relay {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let mut relay = Relay {
            port,
            target: target.to_owned(),
            up: Arc::new(AtomicBool::new(false)),
            open: Arc::default(),
            accept: None,
        };
        relay.serve(listener);
        relay
    }

    fn serve(&mut self, listener: TcpListener) {
        listener.set_nonblocking(true).unwrap();
        self.up.store(true, Ordering::SeqCst);
        let (up, open, target) = (
            Arc::clone(&self.up),
            Arc::clone(&self.open),
            self.target.clone(),
        );
        self.accept = Some(std::thread::spawn(move || {
            while up.load(Ordering::SeqCst) {
                let client = match listener.accept() {
                    Ok((c, _)) => c,
                    Err(_) => {
                        std::thread::sleep(Duration::from_millis(5));
                        continue;
                    }
                };
                client.set_nonblocking(false).unwrap();
                let Ok(server) = TcpStream::connect(&target) else {
                    continue;
                };
                let mut open = open.lock().unwrap();
                open.push(client.try_clone().unwrap());
                open.push(server.try_clone().unwrap());
                for (mut from, mut to) in [
                    (client.try_clone().unwrap(), server.try_clone().unwrap()),
                    (server, client),
                ] {
                    std::thread::spawn(move || {
                        let _ = std::io::copy(&mut from, &mut to);
                        let _ = to.shutdown(Shutdown::Both);
                    });
                }
            }
        }));
    }

    /// Stops accepting and breaks every relayed connection: the data base is gone.
    fn down(&mut self) {
        self.up.store(false, Ordering::SeqCst);
        if let Some(t) = self.accept.take() {
            t.join().unwrap();
        }
        for s in self.open.lock().unwrap().drain(..) {
            let _ = s.shutdown(Shutdown::Both);
        }
    }

    /// Listens again on the same port: the data base is back.
    fn back(&mut self) {
        let listener = TcpListener::bind(("127.0.0.1", self.port)).unwrap();
        self.serve(listener);
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.down();
    }
}

#[test]
fn losing_the_data_base_gives_503_and_the_server_recovers_when_it_is_back() {
    let Some(base) = postgres_or_skip("losing_the_data_base_gives_503") else {
        return;
    };
    // postgres://user:pw@HOST:PORT/db → the same through the relay.
    let (scheme_user, rest) = base.split_once('@').expect("a URL with user@host");
    let (authority, path) = rest.split_once('/').expect("a URL with a data base");
    let mut relay = Relay::start(authority);
    let schema = format!("api_outage_{}", std::process::id());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    // The schema made directly; the server's URL for it goes through the relay.
    fresh_schema(&rt, &base, &schema);
    let sep = if path.contains('?') { '&' } else { '?' };
    let url = format!(
        "{scheme_user}@127.0.0.1:{}/{path}{sep}options=-c%20search_path%3D{schema}",
        relay.port
    );
    let tmp = tempfile::tempdir().unwrap();
    let server = Running::serve(&tmp.path().join("data"), &["--database-url", &url]);
    let simulate = r#"{"scenario": "sphere-lift", "duration": 2}"#;
    let (status, _, body) = server.request("POST", "/api/v1/simulations", simulate);
    assert_eq!(status, 201, "{}", String::from_utf8_lossy(&body));
    let stored: serde_json::Value = serde_json::from_slice(&body).unwrap();
    let session = stored["session_id"].as_i64().unwrap();

    relay.down();
    for (method, path, body) in [
        ("GET", format!("/api/v1/sessions/{session}"), ""),
        ("GET", "/api/v1/skills?limit=5".to_owned(), ""),
        (
            "POST",
            "/api/v1/simulations".to_owned(),
            r#"{"scenario": "box-pinch-lift", "duration": 2}"#,
        ),
    ] {
        let (status, head, reply) = server.request(method, &path, body);
        let reply = String::from_utf8_lossy(&reply).into_owned();
        assert_eq!(
            status, 503,
            "{method} {path} with the data base gone: {head}\n{reply}"
        );
        assert!(head.to_ascii_lowercase().contains("retry-after"), "{head}");
        assert!(
            reply.contains("cannot be reached") || reply.contains("unreachable"),
            "{reply}"
        );
    }
    // The health check says so (a load balancer takes the server out), and what needs no
    // data base is still served.
    let (status, _, _) = server.request("GET", "/healthz", "");
    assert_eq!(status, 503, "the health check sees the data base gone");
    let (status, _, _) = server.request("GET", "/api/v1/openapi.json", "");
    assert_eq!(status, 200, "the server goes on");

    relay.back();
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        let (status, _, _) = server.request("GET", &format!("/api/v1/sessions/{session}"), "");
        if status == 200 || Instant::now() > deadline {
            break status;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(
        status, 200,
        "the server answers again once the data base is back"
    );
    let (status, _, body) = server.request("POST", "/api/v1/simulations", simulate);
    // The same simulation: the session stored before the outage, not a second one.
    assert!(
        status == 200 || status == 201,
        "{status}: {}",
        String::from_utf8_lossy(&body)
    );
    let (_, _, body) = server.request("GET", "/api/v1/sessions", "");
    let page: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(
        page["items"].as_array().unwrap().len(),
        1,
        "nothing was stored during the outage, nothing accepted was lost: {page}"
    );
}
