//! The auvnav log format: an MCAP file with one channel per topic.
//!
//! Long on purpose: the writer, the bounded streaming reader and their tests are one
//! format with one table of channels and schemas; a change to one side is a change to both.
//!
//! Why MCAP with `ros2msg` schemas and CDR encoding: every message type in `shm-schema` is a
//! padding-free `#[repr(C)]` struct whose fields sit at offsets that are multiples of their size,
//! which is exactly little-endian CDR (XCDR1) for a flat message of primitives and fixed arrays.
//! A log message is therefore the 4-byte CDR encapsulation header `00 01 00 00` followed by the
//! struct's bytes: writing costs one copy, no serialiser can drift from the shared-memory layout,
//! and any MCAP tool with ROS 2 support (Foxglove, the Python `mcap-ros2-support` decoder, `ros2 bag`)
//! decodes the channels from the schema text alone, which also carries every field's unit and
//! frame as comments. Protobuf would need a second, hand-maintained description and an encode step.
//!
//! Layout of a file:
//! - a metadata record [`HEADER_METADATA`] with the format version, the minimum reader version,
//!   the producing program and its version, and the configuration (TOML text);
//! - per topic one schema (`auvnav_msgs/msg/<Type>V<n>`, encoding `ros2msg`) and one channel
//!   (message encoding `cdr`, channel metadata `type_name` and free notes);
//! - messages with log time = publish time = the message's host time (ns);
//! - zstd-compressed chunks, message indexes, chunk indexes and a summary.
//!
//! Reading streams the file with bounded memory (records larger than [`RECORD_LENGTH_LIMIT`] are
//! refused, chunk CRCs are checked before their messages are used), so a crafted file can neither
//! exhaust memory nor yield corrupted messages. A file whose writer was killed is readable up to
//! its last complete chunk; the reader then reports [`LogError::Truncated`]. A chunk that fails
//! its CRC (or does not decompress) in the middle of a file is skipped, counted with its time
//! span in [`Corruption`], and the reader goes on with the next chunk it can frame (`framing`).
#![forbid(unsafe_code)]

use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, AidDiagnosticsV1, AttitudeV1, DepthV1, DvlVelocityV1,
    GnssFixV1, ImuSampleV1, LateAidV1, MagnetometerV1, Message, NavSolutionV1, ProcessHealthV1,
    SessionEventV1, SoundVelocityV1, TruthStateV1, UsblFixV1,
};
use mcap::records::{MessageHeader, Metadata, Record, op};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod chunk;
mod framing;
mod mcap_writer;
use mcap_writer::McapWriter;
pub mod table;
use chunk::ChunkRecords;
use framing::{Frame, Framer};

/// Version of the log layout written by this program.
pub const FORMAT_VERSION: u32 = 1;
/// Oldest reader version that can read what this program writes.
pub const MIN_READER_VERSION: u32 = 1;
/// Name of the metadata record that carries the [`LogHeader`].
pub const HEADER_METADATA: &str = "auvnav.header";
/// The MCAP profile field.
pub const PROFILE: &str = "auvnav";
/// Header note of a log whose truth channel is a reference solution computed with some of the
/// log's own sensors: their channel names, comma-separated, then `:` and a description (e.g.
/// `imu,dvl: …`). Effects of those sensors found against that reference are not judged
/// independently of them.
pub const REFERENCE_AIDED_BY: &str = "reference.aided_by";
/// Header note of a log whose attitude's heading is a magnetic compass's: the declination (deg,
/// east positive) the instrument or its export already added to it (0: the heading is magnetic).
pub const HEADING_DECLINATION_APPLIED: &str = "heading.declination_applied_deg";
/// Header note of a log whose clock starts at 0: the recording's date on the instrument's clock
/// (`YYYY-MM-DD`, as that clock was set).
pub const RECORDED_DATE: &str = "recorded.date";
/// CDR encapsulation header: plain CDR, little endian.
pub const CDR_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Largest record (or decompressed chunk) the reader accepts (bytes).
pub const RECORD_LENGTH_LIMIT: usize = 256 << 20;
/// Uncompressed chunk size the writer aims for (bytes). Bounds the loss when a writer is killed.
pub const CHUNK_SIZE: u64 = 1 << 20;

/// The zstd level of the chunks, chosen by measurement (2026-11-30, release, this 2-vCPU VM).
/// Each whole chunk is compressed in one call (the log's own MCAP writer), which allows zstd's fast negative
/// levels. On the chunks of a smoothing run's solutions (one core): level 1 720 MB/s for 0.557 of
/// the size, -1 1 112 MB/s for 0.575, -3 1 546 MB/s for 0.604. On an hour of `auvnav smooth`
/// writing every solution, -1 took 1.80–1.86 s and -3 1.77–1.80 s (two rounds of three runs
/// each, alternating); on simulated logs -1 is 2.6 % larger than level 1 and -3 13.6 %. -1 buys
/// most of the speed for little disk; the recorder on board spends less of the vehicle's
/// processor with it too.
pub const COMPRESSION_LEVEL: i32 = -1;

#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The OS error is the source (printed once, after "opening x" / "reading x" / "creating x").
    #[error("{op} {}", path.display())]
    Io {
        op: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error(
        "the log needs reader version {needed}, this program reads up to {FORMAT_VERSION}; update auvnav"
    )]
    TooNew { needed: u32 },
    #[error("the log has no {HEADER_METADATA} metadata record: not an auvnav log")]
    MissingHeader,
    #[error("header field {key}: {reason}")]
    BadHeader { key: String, reason: String },
    #[error("message on topic {topic}: {reason}")]
    BadMessage { topic: String, reason: String },
    #[error("message refers to unknown channel {0}")]
    UnknownChannel(u16),
    #[error(
        "the log ends inside a record (writer killed before it finished?); everything before was read"
    )]
    Truncated,
}

/// What a log says about itself.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LogHeader {
    pub format_version: u32,
    pub min_reader_version: u32,
    /// Program that wrote the log (`auvnav sim`, `auvnav record`, ...).
    pub producer: String,
    /// Version of that program.
    pub producer_version: String,
    /// The configuration the producer ran with (TOML text).
    pub config: String,
    /// Further key/value notes.
    pub notes: BTreeMap<String, String>,
}

impl LogHeader {
    /// A header for the current format, written by `producer` with `config`.
    pub fn new(producer: &str, config: &str) -> Self {
        LogHeader {
            format_version: FORMAT_VERSION,
            min_reader_version: MIN_READER_VERSION,
            producer: producer.to_string(),
            producer_version: env!("CARGO_PKG_VERSION").to_string(),
            config: config.to_string(),
            notes: BTreeMap::new(),
        }
    }

    pub fn to_metadata(&self) -> Metadata {
        let mut m = self.notes.clone();
        m.insert("format_version".into(), self.format_version.to_string());
        m.insert(
            "min_reader_version".into(),
            self.min_reader_version.to_string(),
        );
        m.insert("producer".into(), self.producer.clone());
        m.insert("producer_version".into(), self.producer_version.clone());
        m.insert("config".into(), self.config.clone());
        Metadata {
            name: HEADER_METADATA.to_string(),
            metadata: m,
        }
    }

    fn from_metadata(mut m: BTreeMap<String, String>) -> Result<Self, LogError> {
        fn num(m: &mut BTreeMap<String, String>, key: &str) -> Result<u32, LogError> {
            let v = m.remove(key).ok_or_else(|| LogError::BadHeader {
                key: key.into(),
                reason: "missing".into(),
            })?;
            v.parse().map_err(|_| LogError::BadHeader {
                key: key.into(),
                reason: format!("not an unsigned integer: {v:?}"),
            })
        }
        let format_version = num(&mut m, "format_version")?;
        let min_reader_version = num(&mut m, "min_reader_version")?;
        Ok(LogHeader {
            format_version,
            min_reader_version,
            producer: m.remove("producer").unwrap_or_default(),
            producer_version: m.remove("producer_version").unwrap_or_default(),
            config: m.remove("config").unwrap_or_default(),
            notes: m,
        })
    }
}

/// Writes an auvnav log. Channels are declared on first use (or explicitly, with notes).
pub struct LogWriter<W: Write + Seek> {
    writer: McapWriter<W>,
    schemas: HashMap<&'static str, u16>,
    /// Topic, channel id and schema name of each channel declared, in order: a handful, looked
    /// up by a scan (hashing the topic of every message cost more).
    channels: Vec<(String, u16, &'static str)>,
    /// The last sequence number written, by channel id.
    sequences: Vec<u32>,
    buf: Vec<u8>,
    messages: u64,
}

impl LogWriter<BufWriter<File>> {
    /// Creates (truncates) `path` and writes the header.
    pub fn create(path: &Path, header: &LogHeader) -> Result<Self, LogError> {
        let file = File::create(path).map_err(|source| LogError::Io {
            op: "creating",
            path: path.to_path_buf(),
            source,
        })?;
        Self::new(BufWriter::with_capacity(1 << 20, file), header)
    }
}

impl<W: Write + Seek> LogWriter<W> {
    pub fn new(w: W, header: &LogHeader) -> Result<Self, LogError> {
        let library = format!("auvnav {}", env!("CARGO_PKG_VERSION"));
        let mut writer =
            McapWriter::new(w, PROFILE, &library, CHUNK_SIZE as usize, COMPRESSION_LEVEL)
                .map_err(mcap::McapError::from)?;
        let metadata = header.to_metadata();
        writer
            .write_metadata(&metadata.name, &metadata.metadata)
            .map_err(mcap::McapError::from)?;
        Ok(LogWriter {
            writer,
            schemas: HashMap::new(),
            channels: Vec::new(),
            sequences: Vec::new(),
            buf: Vec::with_capacity(512),
            messages: 0,
        })
    }

    /// Declares `topic` as carrying `T`, with free-text channel metadata (for example where a
    /// derived quantity comes from). Declaring twice with another type is an error.
    pub fn declare<T: Message>(
        &mut self,
        topic: &str,
        notes: &BTreeMap<String, String>,
    ) -> Result<u16, LogError> {
        if let Some((id, schema)) = self.channel(topic) {
            if schema != T::SCHEMA_NAME {
                return Err(LogError::BadMessage {
                    topic: topic.into(),
                    reason: format!("declared as {schema}, written as {}", T::SCHEMA_NAME),
                });
            }
            return Ok(id);
        }
        let schema_id = match self.schemas.get(T::SCHEMA_NAME) {
            Some(&id) => id,
            None => {
                let id = self.writer.add_schema(
                    T::SCHEMA_NAME,
                    "ros2msg",
                    T::ros2msg_definition().as_bytes(),
                );
                self.schemas.insert(T::SCHEMA_NAME, id);
                id
            }
        };
        let mut metadata = notes.clone();
        metadata.insert("type_name".into(), T::TYPE_NAME.into());
        let id = self.writer.add_channel(schema_id, topic, "cdr", &metadata);
        self.channels.push((topic.to_string(), id, T::SCHEMA_NAME));
        Ok(id)
    }

    /// Appends one message on `topic`, stamped with its host time.
    pub fn write<T: Message>(&mut self, topic: &str, msg: &T) -> Result<(), LogError> {
        let id = match self.channel(topic) {
            Some((id, schema)) if schema == T::SCHEMA_NAME => id,
            _ => self.declare::<T>(topic, &BTreeMap::new())?,
        };
        let seq = self.next_sequence(id);
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_HEADER);
        self.buf.extend_from_slice(bytemuck::bytes_of(msg));
        let t = msg.host_time().0;
        self.writer
            .write_message(id, seq, t, t, &self.buf)
            .map_err(mcap::McapError::from)?;
        self.messages += 1;
        Ok(())
    }

    /// Copies a message read from another log (its encoded bytes and log time) onto the same
    /// topic; the schema must be one of ours.
    pub fn write_raw(&mut self, m: &RawLogMessage) -> Result<(), LogError> {
        let id = match self.channel(&m.topic) {
            Some((id, schema)) if schema == &*m.schema_name => id,
            Some((_, schema)) => {
                return Err(LogError::BadMessage {
                    topic: m.topic.to_string(),
                    reason: format!("declared as {schema}, copied as {}", m.schema_name),
                });
            }
            None => {
                let (type_name, schema_name, definition) = auvnav_shm_schema::all_schemas()
                    .into_iter()
                    .find(|(_, s, _)| *s == &*m.schema_name)
                    .ok_or_else(|| LogError::BadMessage {
                        topic: m.topic.to_string(),
                        reason: format!("unknown schema {}", m.schema_name),
                    })?;
                let schema_id = match self.schemas.get(schema_name) {
                    Some(&id) => id,
                    None => {
                        let id =
                            self.writer
                                .add_schema(schema_name, "ros2msg", definition.as_bytes());
                        self.schemas.insert(schema_name, id);
                        id
                    }
                };
                let metadata = BTreeMap::from([("type_name".to_string(), type_name.to_string())]);
                let id = self
                    .writer
                    .add_channel(schema_id, &m.topic, "cdr", &metadata);
                self.channels.push((m.topic.to_string(), id, schema_name));
                id
            }
        };
        let seq = self.next_sequence(id);
        self.writer
            .write_message(id, seq, m.log_time_ns, m.log_time_ns, &m.data)
            .map_err(mcap::McapError::from)?;
        self.messages += 1;
        Ok(())
    }

    fn channel(&self, topic: &str) -> Option<(u16, &'static str)> {
        self.channels
            .iter()
            .find(|(t, _, _)| t == topic)
            .map(|&(_, id, schema)| (id, schema))
    }

    fn next_sequence(&mut self, id: u16) -> u32 {
        let slot = usize::from(id);
        if self.sequences.len() <= slot {
            self.sequences.resize(slot + 1, 0);
        }
        self.sequences[slot] = self.sequences[slot].wrapping_add(1);
        self.sequences[slot]
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Ends the current chunk and flushes it to the underlying writer.
    pub fn flush(&mut self) -> Result<(), LogError> {
        self.writer.flush().map_err(mcap::McapError::from)?;
        Ok(())
    }

    /// Writes the indexes and the summary and returns the underlying writer.
    pub fn finish(self) -> Result<W, LogError> {
        Ok(self.writer.into_inner().map_err(mcap::McapError::from)?)
    }
}

/// One message read from a log, still encoded.
#[derive(Debug, Clone)]
pub struct RawLogMessage {
    pub topic: Arc<str>,
    pub schema_name: Arc<str>,
    pub log_time_ns: u64,
    pub data: Vec<u8>,
}

impl RawLogMessage {
    /// Decodes the message as `T`, checking schema, encapsulation header and length.
    pub fn decode<T: Message>(&self) -> Result<T, LogError> {
        let bad = |reason: String| LogError::BadMessage {
            topic: self.topic.to_string(),
            reason,
        };
        if &*self.schema_name != T::SCHEMA_NAME {
            return Err(bad(format!(
                "schema {} is not {}",
                self.schema_name,
                T::SCHEMA_NAME
            )));
        }
        decode_pod(&self.topic, &self.data)
    }

    /// Decodes into the typed [`LogMessage`] by schema name.
    pub fn decode_any(&self) -> Result<LogMessage, LogError> {
        decode_bytes(MessageKind::of(&self.schema_name), &self.topic, &self.data)
    }
}

/// The message types a log channel can carry, resolved once per channel from its schema name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MessageKind {
    Imu,
    Dvl,
    Usbl,
    Depth,
    Magnetometer,
    SoundVelocity,
    Attitude,
    AcousticRanges,
    AcousticArrayPose,
    Gnss,
    NavSolution,
    AidDiagnostics,
    Health,
    LateAid,
    SessionEvent,
    Truth,
    Unknown,
}

impl MessageKind {
    fn of(schema_name: &str) -> MessageKind {
        match schema_name {
            s if s == ImuSampleV1::SCHEMA_NAME => MessageKind::Imu,
            s if s == DvlVelocityV1::SCHEMA_NAME => MessageKind::Dvl,
            s if s == UsblFixV1::SCHEMA_NAME => MessageKind::Usbl,
            s if s == DepthV1::SCHEMA_NAME => MessageKind::Depth,
            s if s == MagnetometerV1::SCHEMA_NAME => MessageKind::Magnetometer,
            s if s == SoundVelocityV1::SCHEMA_NAME => MessageKind::SoundVelocity,
            s if s == AttitudeV1::SCHEMA_NAME => MessageKind::Attitude,
            s if s == AcousticRangesV1::SCHEMA_NAME => MessageKind::AcousticRanges,
            s if s == AcousticArrayPoseV1::SCHEMA_NAME => MessageKind::AcousticArrayPose,
            s if s == GnssFixV1::SCHEMA_NAME => MessageKind::Gnss,
            s if s == NavSolutionV1::SCHEMA_NAME => MessageKind::NavSolution,
            s if s == AidDiagnosticsV1::SCHEMA_NAME => MessageKind::AidDiagnostics,
            s if s == ProcessHealthV1::SCHEMA_NAME => MessageKind::Health,
            s if s == LateAidV1::SCHEMA_NAME => MessageKind::LateAid,
            s if s == SessionEventV1::SCHEMA_NAME => MessageKind::SessionEvent,
            s if s == TruthStateV1::SCHEMA_NAME => MessageKind::Truth,
            _ => MessageKind::Unknown,
        }
    }
}

/// `T` from a message's bytes (CDR encapsulation header, then the struct), checking both; the
/// bytes are read in place (no allocation).
pub fn decode_pod<T: Message>(topic: &str, data: &[u8]) -> Result<T, LogError> {
    let bad = |reason: String| LogError::BadMessage {
        topic: topic.to_string(),
        reason,
    };
    let expected = CDR_HEADER.len() + std::mem::size_of::<T>();
    if data.len() != expected {
        return Err(bad(format!("{} bytes, expected {expected}", data.len())));
    }
    if data[..4] != CDR_HEADER {
        return Err(bad(format!(
            "encapsulation header {:02x?} is not little-endian CDR",
            &data[..4]
        )));
    }
    Ok(bytemuck::pod_read_unaligned(&data[4..]))
}

fn decode_bytes(kind: MessageKind, topic: &str, data: &[u8]) -> Result<LogMessage, LogError> {
    Ok(match kind {
        MessageKind::Imu => LogMessage::Imu(decode_pod(topic, data)?),
        MessageKind::Dvl => LogMessage::Dvl(decode_pod(topic, data)?),
        MessageKind::Usbl => LogMessage::Usbl(decode_pod(topic, data)?),
        MessageKind::Depth => LogMessage::Depth(decode_pod(topic, data)?),
        MessageKind::Magnetometer => LogMessage::Magnetometer(decode_pod(topic, data)?),
        MessageKind::SoundVelocity => LogMessage::SoundVelocity(decode_pod(topic, data)?),
        MessageKind::Attitude => LogMessage::Attitude(decode_pod(topic, data)?),
        MessageKind::AcousticRanges => LogMessage::AcousticRanges(decode_pod(topic, data)?),
        MessageKind::AcousticArrayPose => LogMessage::AcousticArrayPose(decode_pod(topic, data)?),
        MessageKind::Gnss => LogMessage::Gnss(decode_pod(topic, data)?),
        MessageKind::NavSolution => LogMessage::NavSolution(decode_pod(topic, data)?),
        MessageKind::AidDiagnostics => LogMessage::AidDiagnostics(decode_pod(topic, data)?),
        MessageKind::Health => LogMessage::Health(decode_pod(topic, data)?),
        MessageKind::LateAid => LogMessage::LateAid(decode_pod(topic, data)?),
        MessageKind::SessionEvent => LogMessage::SessionEvent(decode_pod(topic, data)?),
        MessageKind::Truth => LogMessage::Truth(decode_pod(topic, data)?),
        MessageKind::Unknown => LogMessage::Unknown,
    })
}

/// A decoded log message.
#[derive(Debug, Clone, Copy)]
pub enum LogMessage {
    Imu(ImuSampleV1),
    Dvl(DvlVelocityV1),
    Usbl(UsblFixV1),
    Depth(DepthV1),
    Magnetometer(MagnetometerV1),
    /// The speed of sound from a CTD.
    SoundVelocity(SoundVelocityV1),
    /// Heading, pitch and roll from a compass or an AHRS.
    Attitude(AttitudeV1),
    AcousticRanges(AcousticRangesV1),
    /// Where a moving acoustic array is (its boat's GNSS and heading).
    AcousticArrayPose(AcousticArrayPoseV1),
    Gnss(GnssFixV1),
    NavSolution(NavSolutionV1),
    AidDiagnostics(AidDiagnosticsV1),
    Health(ProcessHealthV1),
    /// An aid message the daemon applied late, and where (replay applies it there too).
    LateAid(LateAidV1),
    /// A session start or checkpoint of the daemon (replay starts its sessions where it did).
    SessionEvent(SessionEventV1),
    Truth(TruthStateV1),
    /// A schema this program does not know (a newer or foreign channel): skipped by users.
    Unknown,
}

impl LogMessage {
    /// The message as an input of the navigation session (the feed path), when it is one.
    pub fn sensor(&self) -> Option<auvnav_shm_schema::sensor::SensorMessage> {
        use auvnav_shm_schema::sensor::SensorMessage as S;
        Some(match self {
            LogMessage::Imu(x) => S::Imu(*x),
            LogMessage::Dvl(x) => S::Dvl(*x),
            LogMessage::Depth(x) => S::Depth(*x),
            LogMessage::Gnss(x) => S::Gnss(*x),
            LogMessage::Usbl(x) => S::Usbl(*x),
            LogMessage::Magnetometer(x) => S::Magnetometer(*x),
            LogMessage::SoundVelocity(x) => S::SoundVelocity(*x),
            LogMessage::AcousticRanges(x) => S::AcousticRanges(*x),
            LogMessage::AcousticArrayPose(x) => S::AcousticArrayPose(*x),
            _ => return None,
        })
    }
}

/// A channel as declared in a log.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: Arc<str>,
    pub schema_name: Arc<str>,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
}

/// What a reader passed over because it was damaged.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Corruption {
    /// Chunks whose CRC failed or that did not decompress (their messages are lost).
    pub chunks_skipped: u64,
    /// Other records the parser refused.
    pub records_skipped: u64,
    /// Bytes passed over while looking for the next chunk after the framing was lost.
    pub bytes_skipped: u64,
    /// The message time spans (log time, ns) the skipped chunks said they held.
    pub spans_ns: Vec<(u64, u64)>,
    /// Messages on channels whose definition was in a lost chunk (skipped).
    pub messages_on_lost_channels: u64,
}

impl Corruption {
    /// True when anything was lost.
    pub fn any(&self) -> bool {
        self.chunks_skipped
            + self.records_skipped
            + self.bytes_skipped
            + self.messages_on_lost_channels
            > 0
    }
}

impl std::fmt::Display for Corruption {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} corrupt chunks skipped, {} other records skipped, {} damaged bytes passed over, {} \
             messages on lost channels",
            self.chunks_skipped,
            self.records_skipped,
            self.bytes_skipped,
            self.messages_on_lost_channels
        )?;
        for (a, b) in &self.spans_ns {
            write!(
                f,
                "; lost {:.3}..{:.3} s",
                *a as f64 * 1e-9,
                *b as f64 * 1e-9
            )?;
        }
        Ok(())
    }
}

/// Streams the records of a log with bounded memory.
pub struct LogReader<R: Read> {
    framer: Framer<R>,
    started: bool,
    /// The records of the chunk being read.
    chunk: ChunkRecords,
    corruption: Corruption,
    /// The file read, for error messages (`<log>` for other sources).
    path: PathBuf,
    schemas: HashMap<u16, Arc<str>>,
    /// The channels and their message kinds, by channel id.
    channels: Vec<Option<(ChannelInfo, MessageKind)>>,
    header: Option<LogHeader>,
    /// `read_header` in progress: return once the header record is read.
    stop_at_header: bool,
    done: bool,
}

/// What [`LogReader::next_decoded_with`] read: a message, or one whose bytes do not match its schema.
pub type Decoded = Result<LogMessage, LogError>;

impl LogReader<std::io::BufReader<File>> {
    pub fn open(path: &Path) -> Result<Self, LogError> {
        let file = File::open(path).map_err(|source| LogError::Io {
            op: "opening",
            path: path.to_path_buf(),
            source,
        })?;
        let mut r = Self::new(std::io::BufReader::with_capacity(1 << 20, file));
        r.path = path.to_path_buf();
        Ok(r)
    }
}

/// What the file's next record gave the reader.
enum TopLevel<T> {
    /// A record taken in (a chunk loaded, a channel defined, damage passed over).
    Read,
    /// A message outside chunks, through the caller's function.
    Message(T),
    /// The header was read and the caller asked to stop there.
    Header,
    /// The end of a finished file.
    End,
}

/// The channel of a message and the kind of its schema; `None` (counted) when the channel was
/// defined in a chunk that was lost, an error when it was never defined in an undamaged file.
fn channel_of<'c>(
    channels: &'c [Option<(ChannelInfo, MessageKind)>],
    corruption: &mut Corruption,
    id: u16,
) -> Result<Option<(&'c ChannelInfo, MessageKind)>, LogError> {
    match channels.get(usize::from(id)) {
        Some(Some((ch, kind))) => Ok(Some((ch, *kind))),
        _ if corruption.any() => {
            corruption.messages_on_lost_channels += 1;
            Ok(None)
        }
        _ => Err(LogError::UnknownChannel(id)),
    }
}

/// The fixed part of an MCAP message record: channel id (u16), sequence (u32), log time and
/// publish time (u64 each), little-endian; the message bytes follow.
const MESSAGE_HEADER_LEN: usize = 2 + 4 + 8 + 8;

/// The header and the message bytes of a message record's body (at least
/// [`MESSAGE_HEADER_LEN`] bytes long).
fn message_in_place(body: &[u8]) -> (MessageHeader, &[u8]) {
    let (head, data) = body.split_at(MESSAGE_HEADER_LEN);
    let u64_at = |i: usize| u64::from_le_bytes(head[i..i + 8].try_into().expect("8 bytes"));
    let header = MessageHeader {
        channel_id: u16::from_le_bytes([head[0], head[1]]),
        sequence: u32::from_le_bytes(head[2..6].try_into().expect("4 bytes")),
        log_time: u64_at(6),
        publish_time: u64_at(14),
    };
    (header, data)
}

impl<R: Read> LogReader<R> {
    pub fn new(source: R) -> Self {
        LogReader {
            framer: Framer::new(source, RECORD_LENGTH_LIMIT),
            started: false,
            chunk: ChunkRecords::default(),
            corruption: Corruption::default(),
            path: PathBuf::from("<log>"),
            schemas: HashMap::new(),
            channels: Vec::new(),
            header: None,
            stop_at_header: false,
            done: false,
        }
    }

    /// What was passed over as damaged so far.
    pub fn corruption(&self) -> &Corruption {
        &self.corruption
    }

    /// The header, once its metadata record has been read (it is the first record we write).
    pub fn header(&self) -> Option<&LogHeader> {
        self.header.as_ref()
    }

    /// Channels seen so far.
    pub fn channels(&self) -> impl Iterator<Item = &ChannelInfo> {
        self.channels.iter().flatten().map(|(c, _)| c)
    }

    /// Reads up to the first message and returns the header; fails for logs that are not ours or
    /// are too new. Call before [`Self::next_message`] when the header matters.
    pub fn read_header(&mut self) -> Result<LogHeader, LogError> {
        if self.header.is_none() {
            self.stop_at_header = true;
            let first = self.next_with(|_, _, _, _| ());
            self.stop_at_header = false;
            if first?.is_some() {
                // A message before the header: the file is not ours.
                return Err(LogError::MissingHeader);
            }
        }
        self.header.clone().ok_or(LogError::MissingHeader)
    }

    /// The next message, `Ok(None)` at the end of the log.
    pub fn next_message(&mut self) -> Result<Option<RawLogMessage>, LogError> {
        self.next_with(|ch, _, header, data| RawLogMessage {
            topic: ch.topic.clone(),
            schema_name: ch.schema_name.clone(),
            log_time_ns: header.log_time,
            data: data.to_vec(),
        })
    }

    /// The next message decoded in place (no allocation per message) and handed to `f` where it
    /// was decoded, not moved out of the reader first (a `LogMessage` is 256 bytes): the fast
    /// path of replay. `f`'s result, or `None` at the end. A [`Decoded`] error is a message whose
    /// bytes do not match its schema (the reader goes on).
    pub fn next_decoded_with<T>(
        &mut self,
        mut f: impl FnMut(&Decoded) -> T,
    ) -> Result<Option<T>, LogError> {
        self.next_with(|ch, kind, _, data| f(&decode_bytes(kind, &ch.topic, data)))
    }

    /// The next message through `f`, records of other kinds handled on the way; `None` at the
    /// end. The records of the chunk being read come first, then the file's next record.
    fn next_with<T>(
        &mut self,
        mut f: impl FnMut(&ChannelInfo, MessageKind, &MessageHeader, &[u8]) -> T,
    ) -> Result<Option<T>, LogError> {
        if self.done {
            return Ok(None);
        }
        loop {
            let (opcode, body) = match self.chunk.next_record() {
                Some(Ok(r)) => r,
                Some(Err(())) => {
                    // A record runs past its chunk's end: the rest of the chunk is lost.
                    self.corruption.chunks_skipped += 1;
                    continue;
                }
                None => match self.next_top_level(&mut f) {
                    Ok(TopLevel::Read) => continue,
                    Ok(TopLevel::Message(t)) => return Ok(Some(t)),
                    Ok(TopLevel::Header) => return Ok(None),
                    Ok(TopLevel::End) => {
                        self.done = true;
                        return Ok(None);
                    }
                    Err(e) => {
                        self.done = true;
                        return Err(e);
                    }
                },
            };
            let body = &self.chunk.bytes()[body];
            if opcode == op::MESSAGE && body.len() >= MESSAGE_HEADER_LEN {
                let (header, data) = message_in_place(body);
                match channel_of(&self.channels, &mut self.corruption, header.channel_id)? {
                    Some((ch, kind)) => return Ok(Some(f(ch, kind, &header, data))),
                    None => continue,
                }
            }
            if !matches!(
                opcode,
                op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA
            ) {
                // Indexes say nothing the linear read needs: not parsed.
                continue;
            }
            match mcap::parse_record(opcode, body).map(Record::into_owned) {
                Ok(record) => {
                    self.handle(record)?;
                    if self.stop_at_header && self.header.is_some() {
                        return Ok(None);
                    }
                }
                Err(_) => {
                    // A schema, channel or metadata record that does not parse (or a message
                    // too short for its header): the rest of the chunk is not trusted.
                    self.chunk.clear();
                    self.corruption.chunks_skipped += 1;
                }
            }
        }
    }

    /// Reads the file's next record: a chunk is loaded (or skipped, counted, when damaged), a
    /// message outside chunks goes to `f`, a schema, channel or metadata record is taken in.
    fn next_top_level<T>(
        &mut self,
        f: &mut impl FnMut(&ChannelInfo, MessageKind, &MessageHeader, &[u8]) -> T,
    ) -> Result<TopLevel<T>, LogError> {
        let io = |path: &Path, source| LogError::Io {
            op: "reading",
            path: path.to_path_buf(),
            source,
        };
        if !self.started {
            self.started = true;
            if !self.framer.start_magic().map_err(|e| io(&self.path, e))? {
                return Err(mcap::McapError::BadMagic.into());
            }
        }
        let (opcode, len) = match self.framer.next().map_err(|e| io(&self.path, e))? {
            Frame::Record { opcode, len, .. } => (opcode, len),
            Frame::EndMagic => return Ok(TopLevel::End),
            Frame::Eof { .. } => return Err(LogError::Truncated),
            Frame::Resynchronised { skipped, .. } => {
                self.corruption.bytes_skipped += skipped;
                return Ok(TopLevel::Read);
            }
        };
        let body = &self.framer.bytes()[9..len];
        let mut message = None;
        let record = match opcode {
            op::CHUNK => {
                if self.chunk.load(body, RECORD_LENGTH_LIMIT).is_err() {
                    self.corruption.chunks_skipped += 1;
                    if let Some(span) = self.framer.chunk_span() {
                        self.corruption.spans_ns.push(span);
                    }
                }
                None
            }
            op::MESSAGE if body.len() >= MESSAGE_HEADER_LEN => {
                let (header, data) = message_in_place(body);
                message = Some(
                    channel_of(&self.channels, &mut self.corruption, header.channel_id)
                        .map(|c| c.map(|(ch, kind)| f(ch, kind, &header, data))),
                );
                None
            }
            op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA => {
                match mcap::parse_record(opcode, body).map(Record::into_owned) {
                    Ok(r) => Some(r),
                    Err(_) => {
                        self.corruption.records_skipped += 1;
                        None
                    }
                }
            }
            _ => None,
        };
        // Consumed before any error is returned: a reader called again goes on after it.
        self.framer.consume(len);
        if let Some(t) = message.transpose()?.flatten() {
            return Ok(TopLevel::Message(t));
        }
        if let Some(r) = record {
            self.handle(r)?;
            if self.stop_at_header && self.header.is_some() {
                return Ok(TopLevel::Header);
            }
        }
        Ok(TopLevel::Read)
    }

    /// A record other than a message.
    fn handle(&mut self, record: Record<'_>) -> Result<(), LogError> {
        match record {
            Record::Schema { header, .. } => {
                self.schemas
                    .insert(header.id, Arc::from(header.name.as_str()));
            }
            Record::Channel(c) => {
                let schema_name = self
                    .schemas
                    .get(&c.schema_id)
                    .cloned()
                    .unwrap_or_else(|| Arc::from(""));
                let i = usize::from(c.id);
                if self.channels.len() <= i {
                    self.channels.resize(i + 1, None);
                }
                let kind = MessageKind::of(&schema_name);
                self.channels[i] = Some((
                    ChannelInfo {
                        id: c.id,
                        topic: Arc::from(c.topic.as_str()),
                        schema_name,
                        message_encoding: c.message_encoding,
                        metadata: c.metadata,
                    },
                    kind,
                ));
            }
            Record::Metadata(m) if m.name == HEADER_METADATA && self.header.is_none() => {
                let h = LogHeader::from_metadata(m.metadata)?;
                if h.min_reader_version > FORMAT_VERSION {
                    return Err(LogError::TooNew {
                        needed: h.min_reader_version,
                    });
                }
                self.header = Some(h);
            }
            _ => {}
        }
        Ok(())
    }
}

/// Writes a log to `path` atomically: into `path` + `.partial`, renamed over `path` only when
/// `body` succeeded and the file is finished. On any error no file is left at `path` (nor the
/// partial one).
pub fn write_log_atomically<F>(path: &Path, header: &LogHeader, body: F) -> anyhow::Result<u64>
where
    F: FnOnce(&mut LogWriter<BufWriter<File>>) -> anyhow::Result<()>,
{
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let result = (|| -> anyhow::Result<u64> {
        let mut w = LogWriter::create(&partial, header)?;
        body(&mut w)?;
        let n = w.messages();
        let mut inner = w.finish()?;
        inner.flush()?;
        let file = inner.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&partial, path)?;
        Ok(n)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&partial);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn a_message_header_read_in_place_equals_the_parsers() {
        let mut body = Vec::new();
        body.extend_from_slice(&0x0102u16.to_le_bytes());
        body.extend_from_slice(&0x0304_0506u32.to_le_bytes());
        body.extend_from_slice(&0x1112_1314_1516_1718u64.to_le_bytes());
        body.extend_from_slice(&0x2122_2324_2526_2728u64.to_le_bytes());
        body.extend_from_slice(b"payload");
        let (header, data) = message_in_place(&body);
        match mcap::parse_record(op::MESSAGE, &body) {
            Ok(Record::Message { header: h, data: d }) => {
                assert_eq!(
                    (h.channel_id, h.sequence, h.log_time, h.publish_time),
                    (
                        header.channel_id,
                        header.sequence,
                        header.log_time,
                        header.publish_time
                    )
                );
                assert_eq!(&*d, data);
                assert_eq!(data, b"payload");
            }
            other => panic!("the parser read {other:?}"),
        }
    }

    fn sample_log() -> Vec<u8> {
        let header = LogHeader::new("test", "seed = 1\n");
        let mut w = LogWriter::new(Cursor::new(Vec::new()), &header).expect("writer");
        for i in 0..5000u64 {
            let imu = ImuSampleV1 {
                host_time_ns: i * 5_000_000,
                sequence: i,
                angular: [i as f64, 0.5, -0.25],
                ..Default::default()
            };
            w.write("imu", &imu).expect("write");
            if i % 40 == 0 {
                let d = DepthV1 {
                    host_time_ns: i * 5_000_000,
                    depth_m: i as f64 * 0.01,
                    ..Default::default()
                };
                w.write("depth", &d).expect("write");
            }
        }
        w.finish().expect("finish").into_inner()
    }

    #[test]
    fn roundtrips_messages_and_header() {
        let bytes = sample_log();
        let mut r = LogReader::new(Cursor::new(bytes));
        let h = r.read_header().expect("header");
        assert_eq!(h.producer, "test");
        assert_eq!(h.config, "seed = 1\n");
        assert_eq!(h.format_version, FORMAT_VERSION);
        let (mut imu, mut depth) = (0u64, 0u64);
        while let Some(m) = r.next_message().expect("message") {
            match m.decode_any().expect("decode") {
                LogMessage::Imu(s) => {
                    assert_eq!(s.angular[0], imu as f64);
                    assert_eq!(m.log_time_ns, imu * 5_000_000);
                    imu += 1;
                }
                LogMessage::Depth(d) => {
                    assert_eq!(d.depth_m, depth as f64 * 40.0 * 0.01);
                    depth += 1;
                }
                other => panic!("unexpected {other:?}"),
            }
        }
        assert_eq!((imu, depth), (5000, 125));
    }

    #[test]
    fn truncated_log_reads_up_to_the_cut_and_reports_it() {
        let bytes = sample_log();
        let cut = &bytes[..bytes.len() * 2 / 3];
        let mut r = LogReader::new(Cursor::new(cut.to_vec()));
        let mut n = 0;
        let err = loop {
            match r.next_message() {
                Ok(Some(_)) => n += 1,
                Ok(None) => panic!("a truncated file must not end cleanly"),
                Err(e) => break e,
            }
        };
        assert!(matches!(err, LogError::Truncated), "{err}");
        assert!(n > 0, "messages before the cut are readable");
    }

    #[test]
    fn crafted_bytes_give_errors_not_panics() {
        let bytes = sample_log();
        let mut state = 0x1234_5678_9abc_def0u64;
        for trial in 0..300 {
            let mut b = bytes.clone();
            for _ in 0..(1 + trial % 8) {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let i = (state % b.len() as u64) as usize;
                b[i] = (state >> 32) as u8;
            }
            let mut r = LogReader::new(Cursor::new(b));
            let mut count = 0;
            while let Ok(Some(m)) = r.next_message() {
                let _ = m.decode_any();
                count += 1;
                assert!(count <= 5200, "no messages invented");
            }
        }
    }

    #[test]
    fn rejects_wrong_schema_and_length() {
        let m = RawLogMessage {
            topic: Arc::from("imu"),
            schema_name: Arc::from(ImuSampleV1::SCHEMA_NAME),
            log_time_ns: 0,
            data: vec![0, 1, 0, 0, 1, 2, 3],
        };
        assert!(m.decode::<ImuSampleV1>().is_err());
        assert!(m.decode::<DepthV1>().is_err());
    }

    #[test]
    fn refuses_logs_from_newer_formats() {
        let mut header = LogHeader::new("test", "");
        header.min_reader_version = FORMAT_VERSION + 1;
        let w = LogWriter::new(Cursor::new(Vec::new()), &header).expect("writer");
        let bytes = w.finish().expect("finish").into_inner();
        let mut r = LogReader::new(Cursor::new(bytes));
        assert!(matches!(r.read_header(), Err(LogError::TooNew { .. })));
    }
}
