//! A real S3 server for tests: `s3s-fs` (the Rust registry's S3 server on a directory;
//! scripts/test installs it), one per test, whose directory shows what the bucket holds.
//! Shared by services/tests/store_s3.rs and api/tests/cli_serve_blobs.rs.
#![allow(dead_code)]

use std::io::Write as _;
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use services::store::S3Bucket;

pub const BUCKET: &str = "icms-test";
pub const KEY_ID: &str = "icms-test-key";
pub const SECRET: &str = "icms-test-secret";

/// A running `s3s-fs` with the bucket [`BUCKET`], stopped when dropped.
pub struct S3Server {
    child: Child,
    /// Its port on 127.0.0.1.
    pub port: u16,
    /// The directory it serves: the bucket is the directory [`BUCKET`] in it.
    pub root: tempfile::TempDir,
}

impl Drop for S3Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The `s3s-fs` binary: on PATH or in cargo's bin directory.
fn s3s_fs() -> Option<PathBuf> {
    let cargo_bin = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")))
        .map(|h| h.join("bin"));
    std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .unwrap_or_default()
        .into_iter()
        .chain(cargo_bin)
        .map(|d| d.join("s3s-fs"))
        .find(|p| p.is_file())
}

impl S3Server {
    /// Starts a server, or returns `None` after saying the test was skipped (a failure under
    /// `ICMS_REQUIRE_TOOLS`, as scripts/test sets it).
    pub fn start(test: &str) -> Option<S3Server> {
        let Some(bin) = s3s_fs() else {
            assert!(
                std::env::var_os("ICMS_REQUIRE_TOOLS").is_none_or(|v| v.is_empty()),
                "{test}: s3s-fs is not installed but ICMS_REQUIRE_TOOLS is set (scripts/test \
                 installs it: cargo install s3s-fs --version 0.14.1 --features binary)"
            );
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED {test}: s3s-fs is not installed (scripts/test installs it)"
            );
            return None;
        };
        for _ in 0..5 {
            let root = tempfile::tempdir().unwrap();
            std::fs::create_dir(root.path().join(BUCKET)).unwrap();
            let port = std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port();
            let child = spawn(&bin, port, root.path());
            let mut server = S3Server { child, port, root };
            let deadline = Instant::now() + Duration::from_secs(10);
            while Instant::now() < deadline {
                if let Ok(Some(_)) = server.child.try_wait() {
                    break; // the port was taken meanwhile: try another
                }
                if TcpStream::connect(("127.0.0.1", port)).is_ok() {
                    return Some(server);
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = server.child.kill();
        }
        panic!("{test}: s3s-fs did not start in five tries");
    }

    pub fn bucket(&self, prefix: &str) -> S3Bucket {
        S3Bucket {
            bucket: BUCKET.into(),
            prefix: prefix.into(),
            endpoint: Some(format!("http://127.0.0.1:{}", self.port)),
            credentials: Some((KEY_ID.into(), SECRET.into())),
        }
    }

    /// The file s3s-fs keeps the object at `key` in.
    pub fn object(&self, key: &str) -> PathBuf {
        self.root.path().join(BUCKET).join(key)
    }

    /// The environment `icms serve --blobs` reads the endpoint and credentials from.
    pub fn env(&self) -> [(&'static str, String); 4] {
        [
            (
                "AWS_ENDPOINT_URL",
                format!("http://127.0.0.1:{}", self.port),
            ),
            ("AWS_ACCESS_KEY_ID", KEY_ID.to_owned()),
            ("AWS_SECRET_ACCESS_KEY", SECRET.to_owned()),
            ("AWS_REGION", "us-east-1".to_owned()),
        ]
    }

    /// Stops the server (the bucket's directory stays).
    pub fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Starts it again on the same port and directory.
    pub fn restart(&mut self) {
        self.stop();
        self.child = spawn(&s3s_fs().expect("s3s-fs"), self.port, self.root.path());
        let deadline = Instant::now() + Duration::from_secs(10);
        while TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(Instant::now() < deadline, "s3s-fs did not restart");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

fn spawn(bin: &std::path::Path, port: u16, root: &std::path::Path) -> Child {
    Command::new(bin)
        .args(["--host", "127.0.0.1", "--port", &port.to_string()])
        .args(["--access-key", KEY_ID, "--secret-key", SECRET])
        .arg(root)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("s3s-fs starts")
}
