//! A running `icms serve` for the end-to-end tests that start one as a user would: the
//! child process, its address once it said it serves, and raw HTTP/1.1 requests to it.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// A running server and its address, once it said it serves.
pub struct Running {
    /// The server process.
    pub child: Child,
    /// Its address, host:port.
    pub addr: String,
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Running {
    /// `icms serve --no-demo` on any free loopback port with data directory `data` and the
    /// extra `args`, without the caller's DATABASE_URL or ICMS_TOKEN, its stderr piped.
    pub fn command(data: &Path, args: &[&str]) -> Command {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_icms"));
        cmd.args(["serve", "--no-demo", "--addr", "127.0.0.1:0", "--data"])
            .arg(data)
            .args(args)
            .env_remove("DATABASE_URL")
            .env_remove("ICMS_TOKEN")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        cmd
    }

    /// [`Running::start`] of [`Running::command`].
    pub fn serve(data: &Path, args: &[&str]) -> Running {
        Running::start(Running::command(data, args))
    }

    /// `METHOD path` without a body: the status code and the body as text.
    pub fn call(&self, method: &str, path: &str) -> (u16, String) {
        let (status, _, body) = self.request(method, path, "");
        (status, String::from_utf8_lossy(&body).into_owned())
    }

    /// Asks `GET path` until it answers `status`, at most `deadline`; fails naming `what`.
    pub fn eventually(&self, path: &str, status: u16, deadline: Duration, what: &str) {
        let start = Instant::now();
        loop {
            let (got, body) = self.call("GET", path);
            if got == status {
                return;
            }
            assert!(
                start.elapsed() < deadline,
                "not within {deadline:?}: {what} (GET {path} answers {got}: {body})"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Starts `cmd` (an `icms serve` with its stderr piped) and waits up to a minute for it
    /// to say it serves.
    pub fn start(mut cmd: Command) -> Running {
        let mut child = cmd.spawn().unwrap();
        let stderr = child.stderr.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let addr = line
                    .strip_prefix("icms: serving on http://")
                    .map(|rest| rest.split('/').next().unwrap_or_default().to_owned());
                let _ = tx.send(addr.ok_or(line));
            }
        });
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut log = Vec::new();
        while Instant::now() < deadline {
            match rx.recv_timeout(Duration::from_millis(200)) {
                Ok(Ok(addr)) => return Running { child, addr },
                Ok(Err(line)) => log.push(line),
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
        }
        let _ = child.kill();
        let _ = child.wait();
        panic!("icms serve did not start:\n{}", log.join("\n"));
    }

    /// `METHOD path` with a JSON body: the status code, the headers and the body.
    pub fn request(&self, method: &str, path: &str, json: &str) -> (u16, String, Vec<u8>) {
        let mut s = TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        write!(
            s,
            "{method} {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\
             Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{json}",
            self.addr,
            json.len()
        )
        .unwrap();
        let mut reply = Vec::new();
        s.read_to_end(&mut reply).unwrap();
        let split = reply
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .expect("a response head");
        let head = String::from_utf8_lossy(&reply[..split]).into_owned();
        let status = head
            .split(' ')
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0);
        (status, head, reply[split + 4..].to_vec())
    }
}

/// The body of a chunked response, unchunked (the MCAP download streams).
pub fn unchunk(head: &str, body: Vec<u8>) -> Vec<u8> {
    if !head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        return body;
    }
    let mut out = Vec::new();
    let mut rest = &body[..];
    loop {
        let line_end = rest.windows(2).position(|w| w == b"\r\n").unwrap();
        let size =
            usize::from_str_radix(std::str::from_utf8(&rest[..line_end]).unwrap().trim(), 16)
                .unwrap();
        if size == 0 {
            return out;
        }
        out.extend_from_slice(&rest[line_end + 2..line_end + 2 + size]);
        rest = &rest[line_end + 2 + size + 2..];
    }
}
