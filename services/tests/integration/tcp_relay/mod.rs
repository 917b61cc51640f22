//! A TCP relay to the test PostgreSQL whose new connections can be held back, for the tests
//! of servers and stores that lose their data base for a while. Shared by
//! services/tests/store_follow.rs and api/tests/cli_serve_follow.rs.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// A TCP relay to the test data base whose new connections can be held back: what cuts a
/// server or store off from PostgreSQL for as long as the test says.
pub struct Relay {
    /// Where it listens.
    pub addr: std::net::SocketAddr,
    held: Arc<AtomicBool>,
}

impl Relay {
    /// A relay to `upstream` (host:port) on a free loopback port.
    pub fn to(upstream: String) -> Relay {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let held = Arc::new(AtomicBool::new(false));
        let hold = Arc::clone(&held);
        std::thread::spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else { continue };
                let hold = Arc::clone(&hold);
                let upstream = upstream.clone();
                std::thread::spawn(move || {
                    while hold.load(Ordering::SeqCst) {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    let Ok(server) = TcpStream::connect(&upstream) else {
                        return;
                    };
                    pipe(client, server);
                });
            }
        });
        Relay { addr, held }
    }

    /// New connections wait (existing ones go on) until [`Relay::release`].
    pub fn hold(&self) {
        self.held.store(true, Ordering::SeqCst);
    }

    /// Lets held and new connections through again.
    pub fn release(&self) {
        self.held.store(false, Ordering::SeqCst);
    }
}

/// Copies both ways between `a` and `b` until either side ends.
fn pipe(a: TcpStream, b: TcpStream) {
    let copy = |mut from: TcpStream, mut to: TcpStream| {
        move || {
            let mut buf = [0u8; 16 * 1024];
            loop {
                match from.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        if to.write_all(&buf[..n]).is_err() {
                            break;
                        }
                    }
                }
            }
            let _ = to.shutdown(Shutdown::Both);
            let _ = from.shutdown(Shutdown::Both);
        }
    };
    let (a2, b2) = (a.try_clone().unwrap(), b.try_clone().unwrap());
    std::thread::spawn(copy(a, b));
    std::thread::spawn(copy(b2, a2));
}
