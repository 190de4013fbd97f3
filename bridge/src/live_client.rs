//! A small blocking client of the live view's Foxglove WebSocket protocol (`foxglove.sdk.v1`):
//! what the tests and `auvnav bench` use to subscribe as Foxglove does and decode what arrives.
//!
//! Protocol: the server sends JSON `serverInfo` and `advertise` (channels with id, topic,
//! encoding, schema name and text); the client sends `subscribe` with its own subscription ids;
//! messages arrive as binary frames: opcode `0x01`, subscription id (u32 LE), log time (u64 LE,
//! ns), then the message's bytes.

use serde::Deserialize;
use std::collections::HashMap;
use std::net::TcpStream;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message as WsMessage, WebSocket};

/// The WebSocket subprotocol the live view serves.
pub const SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// A channel the server advertised.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Channel {
    pub id: u64,
    pub topic: String,
    pub encoding: String,
    pub schema_name: String,
    #[serde(default)]
    pub schema: String,
    #[serde(default)]
    pub schema_encoding: Option<String>,
}

/// One message received on a subscription.
#[derive(Debug, Clone)]
pub struct Received {
    pub topic: String,
    /// Log time (Unix ns).
    pub log_time_ns: u64,
    pub data: Vec<u8>,
}

/// A client error, in words.
#[derive(Debug, thiserror::Error)]
#[error("live view client: {0}")]
pub struct ClientError(pub String);

fn e(what: &str) -> impl Fn(&dyn std::fmt::Display) -> ClientError + '_ {
    move |x| ClientError(format!("{what}: {x}"))
}

/// A connection to the live view.
pub struct LiveClient {
    ws: WebSocket<TcpStream>,
    /// Advertised channels by topic.
    pub channels: HashMap<String, Channel>,
    subscriptions: HashMap<u32, String>,
    /// Text messages other than `serverInfo` and `advertise` (status, errors), in order.
    pub other_text: Vec<String>,
}

impl LiveClient {
    /// Connects to `host:port` (plain TCP, WebSocket handshake with the subprotocol).
    pub fn connect(addr: &str, timeout: Duration) -> Result<LiveClient, ClientError> {
        let sock: std::net::SocketAddr = addr.parse().map_err(|x| e("address")(&x))?;
        let stream = TcpStream::connect_timeout(&sock, timeout).map_err(|x| e("connect")(&x))?;
        stream
            .set_read_timeout(Some(timeout))
            .map_err(|x| e("socket")(&x))?;
        stream.set_nodelay(true).map_err(|x| e("socket")(&x))?;
        let mut request = format!("ws://{addr}/")
            .into_client_request()
            .map_err(|x| e("request")(&x))?;
        request.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            SUBPROTOCOL.parse().map_err(|x| e("header")(&x))?,
        );
        let (ws, _) = tungstenite::client::client(request, stream)
            .map_err(|x| ClientError(format!("handshake with {addr}: {x}")))?;
        Ok(LiveClient {
            ws,
            channels: HashMap::new(),
            subscriptions: HashMap::new(),
            other_text: Vec::new(),
        })
    }

    /// Connects, retrying until `within` has passed (the server may still be starting).
    pub fn connect_retrying(addr: &str, within: Duration) -> Result<LiveClient, ClientError> {
        let end = Instant::now() + within;
        loop {
            match LiveClient::connect(addr, Duration::from_secs(2)) {
                Ok(c) => return Ok(c),
                Err(x) if Instant::now() >= end => return Err(x),
                Err(_) => std::thread::sleep(Duration::from_millis(100)),
            }
        }
    }

    /// Sets the read time-out of one [`LiveClient::read`] call.
    pub fn set_read_timeout(&mut self, t: Duration) -> Result<(), ClientError> {
        self.ws
            .get_mut()
            .set_read_timeout(Some(t))
            .map_err(|x| e("socket")(&x))
    }

    /// Reads until every topic in `topics` is advertised, or `within` has passed.
    pub fn wait_for_channels(
        &mut self,
        topics: &[&str],
        within: Duration,
    ) -> Result<(), ClientError> {
        let end = Instant::now() + within;
        while topics.iter().any(|t| !self.channels.contains_key(*t)) {
            if Instant::now() >= end {
                let missing: Vec<_> = topics
                    .iter()
                    .filter(|t| !self.channels.contains_key(**t))
                    .collect();
                return Err(ClientError(format!("not advertised: {missing:?}")));
            }
            self.read()?;
        }
        Ok(())
    }

    /// Subscribes to these topics (advertised ones only).
    pub fn subscribe(&mut self, topics: &[&str]) -> Result<(), ClientError> {
        let mut subs = Vec::new();
        for t in topics {
            let ch = self
                .channels
                .get(*t)
                .ok_or_else(|| ClientError(format!("{t} is not advertised")))?;
            let id = self.subscriptions.len() as u32 + 1;
            self.subscriptions.insert(id, t.to_string());
            subs.push(serde_json::json!({"id": id, "channelId": ch.id}));
        }
        let msg = serde_json::json!({"op": "subscribe", "subscriptions": subs});
        self.send_text(&msg.to_string())
    }

    /// Sends a text frame as it is (the tests send commands the server must refuse).
    pub fn send_text(&mut self, text: &str) -> Result<(), ClientError> {
        self.ws
            .send(WsMessage::text(text))
            .map_err(|x| e("send")(&x))
    }

    /// Sends a binary frame as it is.
    pub fn send_binary(&mut self, bytes: Vec<u8>) -> Result<(), ClientError> {
        self.ws
            .send(WsMessage::binary(bytes))
            .map_err(|x| e("send")(&x))
    }

    /// The next subscribed message, or `None` when a control message was handled instead or the
    /// read timed out.
    pub fn read(&mut self) -> Result<Option<Received>, ClientError> {
        let m = match self.ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(x))
                if matches!(
                    x.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return Ok(None);
            }
            Err(x) => return Err(e("read")(&x)),
        };
        match m {
            WsMessage::Text(t) => {
                self.control(t.as_str())?;
                Ok(None)
            }
            WsMessage::Binary(b) => Ok(self.data(&b)),
            _ => Ok(None),
        }
    }

    fn control(&mut self, text: &str) -> Result<(), ClientError> {
        #[derive(Deserialize)]
        struct Op {
            op: String,
            #[serde(default)]
            channels: Vec<Channel>,
        }
        let op: Op = serde_json::from_str(text).map_err(|x| e("server message")(&x))?;
        match op.op.as_str() {
            "advertise" => {
                for c in op.channels {
                    self.channels.insert(c.topic.clone(), c);
                }
            }
            "serverInfo" => {}
            _ => self.other_text.push(text.to_string()),
        }
        Ok(())
    }

    fn data(&self, b: &[u8]) -> Option<Received> {
        if b.len() < 13 || b[0] != 0x01 {
            return None;
        }
        let sub = u32::from_le_bytes(b[1..5].try_into().ok()?);
        let log_time_ns = u64::from_le_bytes(b[5..13].try_into().ok()?);
        let topic = self.subscriptions.get(&sub)?.clone();
        Some(Received {
            topic,
            log_time_ns,
            data: b[13..].to_vec(),
        })
    }

    /// Closes the connection politely.
    pub fn close(mut self) {
        let _ = self.ws.close(None);
        let _ = self.ws.flush();
    }
}
