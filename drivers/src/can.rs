//! CAN sensors described by a DBC file.
//!
//! [`DbcDecoder`] turns frames into named, scaled signal values using the message and signal
//! definitions of a DBC file (parsed with the `can-dbc` crate): Intel (little-endian) and Motorola
//! (big-endian, "sawtooth" bit numbering) layouts, signed and unsigned, `value = raw * factor +
//! offset`. Frames come from a [`FrameSource`]: [`InMemoryFrames`] for tests and replays, and
//! [`SocketCanSource`] for the live bus, which reports clearly when the interface does not exist
//! (SocketCAN is not available on every machine).

use serde::Serialize;
use std::collections::{HashMap, VecDeque};

/// One CAN frame (classic or FD).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanFrame {
    /// Identifier without flags (11 or 29 bits).
    pub id: u32,
    pub extended: bool,
    pub data: Vec<u8>,
}

/// Byte order of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BitOrder {
    /// Little-endian: the start bit is the least significant bit.
    Intel,
    /// Big-endian: the start bit is the most significant bit, numbered per byte LSB first.
    Motorola,
}

/// A signal as the decoder needs it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SignalSpec {
    pub name: String,
    pub start_bit: u32,
    pub size: u32,
    pub order: BitOrder,
    pub signed: bool,
    pub factor: f64,
    pub offset: f64,
    pub unit: String,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MessageSpec {
    pub name: String,
    pub id: u32,
    pub extended: bool,
    /// Payload length the DBC declares (bytes).
    pub size: usize,
    pub signals: Vec<SignalSpec>,
}

/// A decoded frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DecodedMessage {
    pub message: String,
    pub id: u32,
    /// Signal name, scaled value, unit.
    pub signals: Vec<(String, f64, String)>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CanError {
    #[error("DBC: {0}")]
    Dbc(String),
    #[error("no message with id {id:#x} in the DBC")]
    UnknownId { id: u32 },
    #[error("message {name}: {got} bytes, the DBC declares {expected}")]
    ShortFrame {
        name: String,
        got: usize,
        expected: usize,
    },
}

/// Counters of a CAN decoder.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CanStats {
    pub frames: u64,
    pub decoded: u64,
    pub unknown_id: u64,
    pub short_frames: u64,
}

/// The next (less significant) bit of a Motorola signal: down within a byte, then to bit 7 of
/// the next byte.
fn next_motorola_bit(p: u32) -> u32 {
    if p.is_multiple_of(8) { p + 15 } else { p - 1 }
}

/// Reads `spec`'s raw value from `data` (bits beyond `data` read as absent: the caller checks
/// the length first).
fn extract(data: &[u8], spec: &SignalSpec) -> u64 {
    let bit = |p: u32| -> u64 {
        let byte = (p / 8) as usize;
        data.get(byte)
            .map(|b| u64::from((b >> (p % 8)) & 1))
            .unwrap_or(0)
    };
    let mut raw = 0u64;
    match spec.order {
        BitOrder::Intel => {
            for i in 0..spec.size {
                raw |= bit(spec.start_bit + i) << i;
            }
        }
        BitOrder::Motorola => {
            let mut p = spec.start_bit;
            for _ in 0..spec.size {
                raw = (raw << 1) | bit(p);
                p = next_motorola_bit(p);
            }
        }
    }
    raw
}

/// Writes `raw` into `data` at `spec`'s bits (the inverse of [`extract`]).
fn insert(data: &mut [u8], spec: &SignalSpec, raw: u64) {
    let mut set = |p: u32, v: u64| {
        let byte = (p / 8) as usize;
        if let Some(b) = data.get_mut(byte) {
            let mask = 1u8 << (p % 8);
            if v & 1 == 1 {
                *b |= mask;
            } else {
                *b &= !mask;
            }
        }
    };
    match spec.order {
        BitOrder::Intel => {
            for i in 0..spec.size {
                set(spec.start_bit + i, raw >> i);
            }
        }
        BitOrder::Motorola => {
            let mut p = spec.start_bit;
            for i in 0..spec.size {
                set(p, raw >> (spec.size - 1 - i));
                p = next_motorola_bit(p);
            }
        }
    }
}

/// The byte span a signal occupies, to check a frame is long enough.
fn last_byte(spec: &SignalSpec) -> usize {
    match spec.order {
        BitOrder::Intel => ((spec.start_bit + spec.size.max(1) - 1) / 8) as usize,
        BitOrder::Motorola => {
            let mut p = spec.start_bit;
            for _ in 1..spec.size.max(1) {
                p = next_motorola_bit(p);
            }
            (p / 8) as usize
        }
    }
}

impl SignalSpec {
    /// The scaled value of this signal in `data`.
    pub fn decode(&self, data: &[u8]) -> f64 {
        let raw = extract(data, self);
        let value = if self.signed && self.size > 0 && self.size < 64 {
            let shift = 64 - self.size;
            (((raw << shift) as i64) >> shift) as f64
        } else if self.signed {
            raw as i64 as f64
        } else {
            raw as f64
        };
        value * self.factor + self.offset
    }

    /// Writes the raw value nearest to `value` into `data`.
    pub fn encode(&self, data: &mut [u8], value: f64) {
        let raw = ((value - self.offset) / self.factor).round();
        let bits = if self.size >= 64 {
            u64::MAX
        } else {
            (1u64 << self.size) - 1
        };
        let raw = if self.signed {
            (raw as i64) as u64 & bits
        } else {
            (raw.max(0.0) as u64) & bits
        };
        insert(data, self, raw);
    }
}

/// Decodes frames with the messages of a DBC file.
#[derive(Debug, Clone)]
pub struct DbcDecoder {
    messages: HashMap<(u32, bool), MessageSpec>,
    pub stats: CanStats,
}

impl DbcDecoder {
    /// Parses DBC text.
    pub fn from_dbc(text: &str) -> Result<DbcDecoder, CanError> {
        let dbc = can_dbc::Dbc::try_from(text).map_err(|e| CanError::Dbc(format!("{e:?}")))?;
        let mut messages = HashMap::new();
        for m in &dbc.messages {
            let (id, extended) = match m.id {
                can_dbc::MessageId::Standard(id) => (u32::from(id), false),
                can_dbc::MessageId::Extended(id) => (id, true),
            };
            let signals = m
                .signals
                .iter()
                .map(|s| SignalSpec {
                    name: s.name.clone(),
                    start_bit: s.start_bit as u32,
                    size: s.size as u32,
                    order: match s.byte_order {
                        can_dbc::ByteOrder::LittleEndian => BitOrder::Intel,
                        can_dbc::ByteOrder::BigEndian => BitOrder::Motorola,
                    },
                    signed: s.value_type == can_dbc::ValueType::Signed,
                    factor: s.factor,
                    offset: s.offset,
                    unit: s.unit.clone(),
                })
                .collect::<Vec<_>>();
            for s in &signals {
                if s.size == 0 || s.size > 64 || last_byte(s) >= 64 {
                    return Err(CanError::Dbc(format!(
                        "message {}: signal {} does not fit a CAN FD frame",
                        m.name, s.name
                    )));
                }
            }
            messages.insert(
                (id, extended),
                MessageSpec {
                    name: m.name.clone(),
                    id,
                    extended,
                    size: m.size as usize,
                    signals,
                },
            );
        }
        Ok(DbcDecoder {
            messages,
            stats: CanStats::default(),
        })
    }

    pub fn message(&self, id: u32, extended: bool) -> Option<&MessageSpec> {
        self.messages.get(&(id, extended))
    }

    pub fn message_by_name(&self, name: &str) -> Option<&MessageSpec> {
        self.messages.values().find(|m| m.name == name)
    }

    /// Decodes one frame; unknown identifiers and frames shorter than their signals are counted
    /// errors.
    pub fn decode(&mut self, f: &CanFrame) -> Result<DecodedMessage, CanError> {
        self.stats.frames += 1;
        let Some(m) = self.messages.get(&(f.id, f.extended)) else {
            self.stats.unknown_id += 1;
            return Err(CanError::UnknownId { id: f.id });
        };
        let needed = m
            .signals
            .iter()
            .map(|s| last_byte(s) + 1)
            .max()
            .unwrap_or(0);
        if f.data.len() < needed {
            self.stats.short_frames += 1;
            return Err(CanError::ShortFrame {
                name: m.name.clone(),
                got: f.data.len(),
                expected: m.size.max(needed),
            });
        }
        self.stats.decoded += 1;
        Ok(DecodedMessage {
            message: m.name.clone(),
            id: m.id,
            signals: m
                .signals
                .iter()
                .map(|s| (s.name.clone(), s.decode(&f.data), s.unit.clone()))
                .collect(),
        })
    }

    /// Builds a frame of message `name` from signal values (for emulators and tests).
    pub fn encode(&self, name: &str, values: &[(&str, f64)]) -> Option<CanFrame> {
        let m = self.message_by_name(name)?;
        let mut data = vec![0u8; m.size];
        for (signal, value) in values {
            m.signals
                .iter()
                .find(|s| s.name == *signal)?
                .encode(&mut data, *value);
        }
        Some(CanFrame {
            id: m.id,
            extended: m.extended,
            data,
        })
    }
}

/// Why a frame source stopped.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error(
        "CAN interface {iface} is not available ({reason}); SocketCAN needs a Linux kernel with \
         CAN support and the interface up (for a test bus: `ip link add dev vcan0 type vcan`)"
    )]
    NoInterface { iface: String, reason: String },
    #[error("reading {iface}: {source}")]
    Read {
        iface: String,
        source: std::io::Error,
    },
}

/// Where frames come from.
pub trait FrameSource {
    /// The next frame, `Ok(None)` when none arrived within the source's timeout (or, for a
    /// finite source, at its end).
    fn next_frame(&mut self) -> Result<Option<CanFrame>, SourceError>;
}

/// Frames from memory, in order.
#[derive(Debug, Clone, Default)]
pub struct InMemoryFrames {
    frames: VecDeque<CanFrame>,
}

impl InMemoryFrames {
    pub fn new(frames: impl IntoIterator<Item = CanFrame>) -> Self {
        InMemoryFrames {
            frames: frames.into_iter().collect(),
        }
    }
}

impl FrameSource for InMemoryFrames {
    fn next_frame(&mut self) -> Result<Option<CanFrame>, SourceError> {
        Ok(self.frames.pop_front())
    }
}

/// A SocketCAN interface.
pub struct SocketCanSource {
    iface: String,
    socket: socketcan::CanSocket,
}

impl SocketCanSource {
    /// Opens `iface` with a read timeout; fails with [`SourceError::NoInterface`] when it does
    /// not exist or the kernel has no CAN support.
    pub fn open(iface: &str, timeout: std::time::Duration) -> Result<Self, SourceError> {
        use socketcan::Socket;
        let no = |e: std::io::Error| SourceError::NoInterface {
            iface: iface.to_string(),
            reason: e.to_string(),
        };
        let socket = socketcan::CanSocket::open(iface).map_err(no)?;
        socket.set_read_timeout(timeout).map_err(no)?;
        Ok(SocketCanSource {
            iface: iface.to_string(),
            socket,
        })
    }
}

impl FrameSource for SocketCanSource {
    fn next_frame(&mut self) -> Result<Option<CanFrame>, SourceError> {
        use socketcan::{EmbeddedFrame, Frame, Socket};
        match self.socket.read_frame() {
            Ok(f) => Ok(Some(CanFrame {
                id: f.raw_id() & 0x1fff_ffff,
                extended: f.is_extended(),
                data: f.data().to_vec(),
            })),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(source) => Err(SourceError::Read {
                iface: self.iface.clone(),
                source,
            }),
        }
    }
}
