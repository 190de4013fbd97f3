//! A small HTTP/1.1 client for devices that serve their readings over HTTP on the vehicle's
//! network (the Water Linked Underwater GPS topside): `GET` only, plain HTTP, one connection
//! per request (`Connection: close`), a deadline on the whole exchange, and a bounded body.
//! The body is read by `Content-Length`, by chunks (`Transfer-Encoding: chunked`) or to the
//! end of the connection.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

/// Longest header block accepted (bytes).
const MAX_HEADER: usize = 16 * 1024;

/// An `http://host[:port]` base address, resolved.
#[derive(Debug, Clone)]
pub struct HttpBase {
    /// As configured, for messages.
    pub url: String,
    /// The `Host` header.
    pub host: String,
    /// `host:port`, resolved at each request (a name that does not resolve yet, at boot, is a
    /// failed request, not a configuration error).
    pub target: String,
}

impl HttpBase {
    /// Parses `http://host[:port]` (default port 80; a trailing `/` allowed, no path).
    pub fn parse(url: &str) -> Result<HttpBase, String> {
        let rest = url
            .strip_prefix("http://")
            .ok_or_else(|| format!("{url:?}: an http:// address (https is not spoken)"))?;
        let authority = rest.strip_suffix('/').unwrap_or(rest);
        if authority.is_empty() || authority.contains('/') {
            return Err(format!("{url:?}: http://host[:port] without a path"));
        }
        let has_port = authority.parse::<SocketAddr>().is_ok()
            || authority.rsplit_once(':').is_some_and(|(h, p)| {
                !h.is_empty() && !h.contains(':') && p.parse::<u16>().is_ok()
            });
        let with_port = if has_port {
            authority.to_string()
        } else {
            format!("{authority}:80")
        };
        Ok(HttpBase {
            url: url.to_string(),
            host: authority.to_string(),
            target: with_port,
        })
    }
}

/// Why a request gave no body.
#[derive(Debug, thiserror::Error)]
pub enum HttpError {
    #[error("cannot connect: {0}")]
    Connect(std::io::Error),
    #[error("no complete answer within {0:?}")]
    Timeout(Duration),
    #[error("connection: {0}")]
    Io(std::io::Error),
    #[error("HTTP status {0}")]
    Status(u16),
    #[error("not an HTTP answer: {0}")]
    Malformed(String),
    #[error("answer longer than {0} bytes")]
    TooLong(usize),
}

impl HttpError {
    /// True when the device did not answer at all (connection refused, reset, timed out), as
    /// opposed to answering with an error or with a broken response.
    pub fn unreachable(&self) -> bool {
        matches!(
            self,
            HttpError::Connect(_) | HttpError::Timeout(_) | HttpError::Io(_)
        )
    }
}

/// `GET path` from `base`: the body of a `200` answer, within `timeout` for the whole exchange
/// and at most `max_body` bytes.
pub fn get(
    base: &HttpBase,
    path: &str,
    timeout: Duration,
    max_body: usize,
) -> Result<Vec<u8>, HttpError> {
    let deadline = Instant::now() + timeout;
    let address = base
        .target
        .to_socket_addrs()
        .map_err(HttpError::Connect)?
        .next()
        .ok_or_else(|| {
            HttpError::Connect(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("{} resolves to no address", base.target),
            ))
        })?;
    let mut s = TcpStream::connect_timeout(&address, timeout).map_err(|e| {
        if e.kind() == std::io::ErrorKind::TimedOut {
            HttpError::Timeout(timeout)
        } else {
            HttpError::Connect(e)
        }
    })?;
    let _ = s.set_nodelay(true);
    let left = |d: Instant| {
        d.checked_duration_since(Instant::now())
            .filter(|x| !x.is_zero())
            .ok_or(HttpError::Timeout(timeout))
    };
    s.set_write_timeout(Some(left(deadline)?))
        .map_err(HttpError::Io)?;
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: {}\r\nAccept: application/json\r\nUser-Agent: auvnav\r\n\
         Connection: close\r\n\r\n",
        base.host
    );
    s.write_all(request.as_bytes())
        .map_err(|e| io(e, timeout))?;
    let mut reader = DeadlineReader {
        s,
        deadline,
        timeout,
    };
    let mut buf = Vec::with_capacity(4096);
    let header_end = loop {
        if let Some(i) = find(&buf, b"\r\n\r\n") {
            break i + 4;
        }
        if buf.len() > MAX_HEADER {
            return Err(HttpError::Malformed("header block too long".into()));
        }
        if reader.fill(&mut buf)? == 0 {
            return Err(HttpError::Malformed(
                "the connection closed inside the header".into(),
            ));
        }
    };
    let head = std::str::from_utf8(&buf[..header_end])
        .map_err(|_| HttpError::Malformed("header is not text".into()))?;
    let mut lines = head.split("\r\n");
    let status_line = lines.next().unwrap_or_default();
    let status = status_line
        .strip_prefix("HTTP/1.")
        .and_then(|r| r.get(2..5))
        .and_then(|c| c.parse::<u16>().ok())
        .ok_or_else(|| HttpError::Malformed(format!("status line {status_line:?}")))?;
    let mut length = None;
    let mut chunked = false;
    for line in lines {
        let Some((name, value)) = line.split_once(':') else {
            continue;
        };
        let value = value.trim();
        if name.eq_ignore_ascii_case("content-length") {
            length = Some(
                value
                    .parse::<usize>()
                    .map_err(|_| HttpError::Malformed(format!("Content-Length {value:?}")))?,
            );
        } else if name.eq_ignore_ascii_case("transfer-encoding") {
            chunked = value.to_ascii_lowercase().contains("chunked");
        }
    }
    let mut body = buf.split_off(header_end);
    if chunked {
        body = read_chunked(&mut reader, body, max_body)?;
    } else if let Some(n) = length {
        if n > max_body {
            return Err(HttpError::TooLong(max_body));
        }
        while body.len() < n {
            if reader.fill(&mut body)? == 0 {
                return Err(HttpError::Malformed(format!(
                    "the body ended at {} of {n} bytes",
                    body.len()
                )));
            }
        }
        body.truncate(n);
    } else {
        while reader.fill(&mut body)? > 0 {
            if body.len() > max_body {
                return Err(HttpError::TooLong(max_body));
            }
        }
    }
    if status != 200 {
        return Err(HttpError::Status(status));
    }
    Ok(body)
}

fn io(e: std::io::Error, timeout: Duration) -> HttpError {
    if matches!(
        e.kind(),
        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
    ) {
        HttpError::Timeout(timeout)
    } else {
        HttpError::Io(e)
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Reads of a stream that stop at the exchange's deadline.
struct DeadlineReader {
    s: TcpStream,
    deadline: Instant,
    timeout: Duration,
}

impl DeadlineReader {
    /// Appends what arrives next to `buf`: its length (0 at the end of the connection).
    fn fill(&mut self, buf: &mut Vec<u8>) -> Result<usize, HttpError> {
        let left = self
            .deadline
            .checked_duration_since(Instant::now())
            .filter(|x| !x.is_zero())
            .ok_or(HttpError::Timeout(self.timeout))?;
        self.s.set_read_timeout(Some(left)).map_err(HttpError::Io)?;
        let mut chunk = [0u8; 4096];
        let n = self.s.read(&mut chunk).map_err(|e| io(e, self.timeout))?;
        buf.extend_from_slice(&chunk[..n]);
        Ok(n)
    }
}

/// The body of a chunked answer, `have` being what already arrived after the header.
fn read_chunked(
    r: &mut DeadlineReader,
    mut have: Vec<u8>,
    max_body: usize,
) -> Result<Vec<u8>, HttpError> {
    let mut body = Vec::new();
    let mut at = 0;
    loop {
        let line_end = loop {
            if let Some(i) = find(&have[at..], b"\r\n") {
                break at + i;
            }
            if have.len() - at > 64 || r.fill(&mut have)? == 0 {
                return Err(HttpError::Malformed("broken chunk size".into()));
            }
        };
        let size_text = std::str::from_utf8(&have[at..line_end]).unwrap_or("?");
        let size_text = size_text.split(';').next().unwrap_or("").trim();
        let size = usize::from_str_radix(size_text, 16)
            .map_err(|_| HttpError::Malformed(format!("chunk size {size_text:?}")))?;
        at = line_end + 2;
        if size == 0 {
            return Ok(body);
        }
        if body.len() + size > max_body {
            return Err(HttpError::TooLong(max_body));
        }
        while have.len() < at + size + 2 {
            if r.fill(&mut have)? == 0 {
                return Err(HttpError::Malformed(
                    "the connection closed inside a chunk".into(),
                ));
            }
        }
        body.extend_from_slice(&have[at..at + size]);
        at += size + 2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::TcpListener;

    /// Serves `answers` one per connection on a loopback port.
    fn serve(answers: Vec<Vec<u8>>) -> HttpBase {
        let l = TcpListener::bind("127.0.0.1:0").expect("listener");
        let url = format!("http://{}", l.local_addr().expect("address"));
        std::thread::spawn(move || {
            for a in answers {
                let (mut c, _) = l.accept().expect("accept");
                let mut req = [0u8; 1024];
                let _ = c.read(&mut req);
                let _ = c.write_all(&a);
            }
        });
        HttpBase::parse(&url).expect("url")
    }

    #[test]
    fn bodies_are_read_by_length_by_chunks_and_to_the_end() {
        let base = serve(vec![
            b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhelloEXTRA".to_vec(),
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n3\r\nhel\r\n2;x=1\r\nlo\r\n0\r\n\r\n"
                .to_vec(),
            b"HTTP/1.0 200 OK\r\n\r\nhello".to_vec(),
            b"HTTP/1.1 500 Internal Server Error\r\nContent-Length: 2\r\n\r\n{}".to_vec(),
            b"garbage\r\n\r\n".to_vec(),
            b"HTTP/1.1 200 OK\r\nContent-Length: 50\r\n\r\nshort".to_vec(),
        ]);
        let t = Duration::from_secs(5);
        for _ in 0..3 {
            assert_eq!(get(&base, "/x", t, 100).expect("body"), b"hello");
        }
        assert!(matches!(
            get(&base, "/x", t, 100),
            Err(HttpError::Status(500))
        ));
        assert!(matches!(
            get(&base, "/x", t, 100),
            Err(HttpError::Malformed(_))
        ));
        assert!(matches!(
            get(&base, "/x", t, 100),
            Err(HttpError::Malformed(_))
        ));
    }

    #[test]
    fn a_silent_server_times_out_and_a_closed_port_is_unreachable() {
        let l = TcpListener::bind("127.0.0.1:0").expect("listener");
        let base = HttpBase::parse(&format!("http://{}", l.local_addr().expect("a"))).expect("u");
        let e = get(&base, "/x", Duration::from_millis(100), 100).expect_err("no answer");
        assert!(matches!(e, HttpError::Timeout(_)), "{e}");
        drop(l);
        let e = get(&base, "/x", Duration::from_millis(100), 100).expect_err("closed");
        assert!(e.unreachable(), "{e}");
    }

    #[test]
    fn addresses_are_http_host_and_optional_port() {
        assert_eq!(
            HttpBase::parse("http://127.0.0.1")
                .expect("default port")
                .target,
            "127.0.0.1:80"
        );
        assert_eq!(
            HttpBase::parse("http://topside.local:8080/")
                .expect("port")
                .target,
            "topside.local:8080"
        );
        assert!(HttpBase::parse("https://127.0.0.1").is_err());
        assert!(HttpBase::parse("http://127.0.0.1/api").is_err());
        assert!(HttpBase::parse("127.0.0.1:80").is_err());
    }
}
