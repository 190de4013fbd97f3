//! The live view's front door: a TCP listener in front of the Foxglove SDK's WebSocket server
//! (which binds loopback on a port of its own and offers no hook for either check) that
//!
//! - refuses a WebSocket upgrade whose `Origin` header names a site not in `allowed_origins`
//!   (`403 Forbidden`): a web page open in the operator's browser cannot read the stream;
//!   requests without an `Origin` (the Foxglove desktop app, scripts) are let through;
//! - refuses connections beyond `max_connections` (`503 Service Unavailable`), so that many
//!   clients cannot exhaust the vehicle's memory;
//! - then relays bytes both ways, unchanged.
//!
//! Counters: connections accepted, refused for their origin, refused for the limit.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

/// What the gate counted.
#[derive(Debug, Default)]
pub struct GateCounters {
    pub accepted: AtomicU64,
    pub refused_origin: AtomicU64,
    pub refused_limit: AtomicU64,
    pub open: AtomicUsize,
}

/// The running gate.
pub struct Gate {
    pub port: u16,
    pub counters: Arc<GateCounters>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Whether `origin` (an `Origin` header value) is allowed by `allowed` (exact, case-insensitive
/// matches of scheme://host[:port]; `*` allows any).
pub fn origin_allowed(origin: Option<&str>, allowed: &[String]) -> bool {
    match origin {
        None => true,
        Some(o) => allowed
            .iter()
            .any(|a| a == "*" || a.eq_ignore_ascii_case(o.trim())),
    }
}

/// Whether `s` is an origin as browsers send it: `scheme://host` or `scheme://host:port`, with
/// no path; or `*`.
pub fn is_origin(s: &str) -> bool {
    if s == "*" {
        return true;
    }
    let Some((scheme, rest)) = s.split_once("://") else {
        return false;
    };
    let scheme_ok = !scheme.is_empty()
        && scheme
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c));
    let host_ok = !rest.is_empty()
        && rest
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-.:[]".contains(c));
    scheme_ok && host_ok
}

/// The `Origin` header of an HTTP request head, if any.
fn origin_of(head: &str) -> Option<&str> {
    head.lines().skip(1).find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.trim().eq_ignore_ascii_case("origin").then(|| v.trim())
    })
}

/// Reads an HTTP request head (up to the blank line; at most 16 KiB, within 5 s).
fn read_head(s: &mut TcpStream) -> std::io::Result<Vec<u8>> {
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut head = Vec::with_capacity(1024);
    let mut b = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        if head.len() > 16 << 10 {
            return Err(std::io::Error::other("request head over 16 KiB"));
        }
        let n = s.read(&mut b)?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        head.extend_from_slice(&b[..n]);
    }
    s.set_read_timeout(None)?;
    Ok(head)
}

fn refuse(mut s: TcpStream, status: &str) {
    let body = format!("{status}\r\n");
    let _ = write!(
        s,
        "HTTP/1.1 {status}\r\nContent-Type: text/plain\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = s.shutdown(Shutdown::Both);
}

/// Relays one accepted client to the server at `upstream` after the checks.
fn serve(
    mut client: TcpStream,
    upstream: std::net::SocketAddr,
    allowed: &[String],
    c: &GateCounters,
) {
    let Ok(head) = read_head(&mut client) else {
        return;
    };
    let text = String::from_utf8_lossy(&head);
    if !origin_allowed(origin_of(&text), allowed) {
        c.refused_origin.fetch_add(1, Ordering::Relaxed);
        tracing::warn!(
            origin = origin_of(&text).unwrap_or_default(),
            "live: refused a connection from origin {:?} (not in allowed_origins)",
            origin_of(&text).unwrap_or_default()
        );
        refuse(client, "403 Forbidden");
        return;
    }
    let Ok(mut server) = TcpStream::connect(upstream) else {
        refuse(client, "502 Bad Gateway");
        return;
    };
    let _ = server.set_nodelay(true);
    let _ = client.set_nodelay(true);
    if server.write_all(&head).is_err() {
        return;
    }
    c.accepted.fetch_add(1, Ordering::Relaxed);
    let (Ok(mut client2), Ok(mut server2)) = (client.try_clone(), server.try_clone()) else {
        return;
    };
    let up = std::thread::spawn(move || {
        let _ = std::io::copy(&mut client2, &mut server2);
        let _ = server2.shutdown(Shutdown::Write);
    });
    let _ = std::io::copy(&mut server, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = up.join();
}

impl Gate {
    /// Listens on `address:port` and relays to `upstream` (the SDK server on loopback).
    pub fn start(
        address: &str,
        port: u16,
        upstream: std::net::SocketAddr,
        allowed: Vec<String>,
        max_connections: usize,
    ) -> std::io::Result<Gate> {
        let listener = TcpListener::bind((address, port))?;
        listener.set_nonblocking(true)?;
        let port = listener.local_addr()?.port();
        let counters = Arc::new(GateCounters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (c, s) = (counters.clone(), stop.clone());
        let allowed = Arc::new(allowed);
        let thread = std::thread::Builder::new()
            .name("live-gate".into())
            .spawn(move || {
                while !s.load(Ordering::Relaxed) {
                    let client = match listener.accept() {
                        Ok((client, _)) => client,
                        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                            std::thread::sleep(Duration::from_millis(20));
                            continue;
                        }
                        Err(_) => continue,
                    };
                    let _ = client.set_nonblocking(false);
                    if c.open.load(Ordering::Relaxed) >= max_connections {
                        c.refused_limit.fetch_add(1, Ordering::Relaxed);
                        refuse(client, "503 Service Unavailable");
                        continue;
                    }
                    c.open.fetch_add(1, Ordering::Relaxed);
                    let (c2, allowed) = (c.clone(), allowed.clone());
                    let spawned = std::thread::Builder::new()
                        .name("live-client".into())
                        .spawn(move || {
                            serve(client, upstream, &allowed, &c2);
                            c2.open.fetch_sub(1, Ordering::Relaxed);
                        });
                    if spawned.is_err() {
                        c.open.fetch_sub(1, Ordering::Relaxed);
                    }
                }
            })?;
        Ok(Gate {
            port,
            counters,
            stop,
            thread: Some(thread),
        })
    }

    /// Stops accepting (open connections end with the server).
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origins_are_matched_exactly_and_requests_without_one_pass() {
        let allowed = vec!["https://app.foxglove.dev".to_string()];
        assert!(origin_allowed(None, &allowed));
        assert!(origin_allowed(Some("https://app.foxglove.dev"), &allowed));
        assert!(origin_allowed(Some("HTTPS://APP.FOXGLOVE.DEV"), &allowed));
        assert!(!origin_allowed(Some("https://evil.example"), &allowed));
        assert!(!origin_allowed(
            Some("https://app.foxglove.dev.evil.example"),
            &allowed
        ));
        assert!(origin_allowed(Some("https://x"), &["*".to_string()]));
        assert!(is_origin("https://app.foxglove.dev"));
        assert!(is_origin("http://192.168.1.2:8080"));
        assert!(!is_origin("not an origin"));
        assert!(!is_origin("https://host/path"));
        let head = "GET / HTTP/1.1\r\nHost: x\r\norigin:  https://a.b \r\n\r\n";
        assert_eq!(origin_of(head), Some("https://a.b"));
    }
}
