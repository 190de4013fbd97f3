//! The MCAP writer under [`crate::LogWriter`]: records of a chunk are gathered uncompressed and
//! the chunk is compressed in one call when it is full.
//!
//! The `mcap` crate's writer streams every record into zstd as it comes: a message is some seven
//! small writes (the record's fields one at a time), each a call into the compressor, and at a few
//! hundred bytes per message those calls cost more than the compression. Compressing a whole chunk
//! at once is some 50 % faster on the same bytes at the same level (720 against 477 MB/s at level
//! 1 on a smoothing run's solutions, one core), and it allows zstd's fast negative levels.
//!
//! The file is what the specification (<https://mcap.dev/spec>) asks of a chunked, indexed MCAP:
//! magic, header, a data section of metadata records and zstd chunks (schemas and channels inside
//! the chunk where they are declared) each followed by its message indexes, the data end with the
//! data section's CRC, and a summary section (schemas, channels, statistics, chunk and metadata
//! indexes, summary offsets) closed by the footer with its CRC. Third-party readers (the `mcap`
//! crate, the Python `mcap` package) read it; tests check both.

use std::collections::BTreeMap;
use std::io::{self, Write};

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// Appends one record: its opcode, its length and the content `body` writes.
fn record(buf: &mut Vec<u8>, opcode: u8, body: impl FnOnce(&mut Vec<u8>)) {
    buf.push(opcode);
    let length_at = buf.len();
    buf.extend_from_slice(&0u64.to_le_bytes());
    body(buf);
    let length = (buf.len() - length_at - 8) as u64;
    buf[length_at..length_at + 8].copy_from_slice(&length.to_le_bytes());
}

fn put_str(buf: &mut Vec<u8>, s: &str) {
    buf.extend_from_slice(&(s.len() as u32).to_le_bytes());
    buf.extend_from_slice(s.as_bytes());
}

/// A map or an array: its length in bytes, then what `entries` writes.
fn put_prefixed(buf: &mut Vec<u8>, entries: impl FnOnce(&mut Vec<u8>)) {
    let at = buf.len();
    buf.extend_from_slice(&0u32.to_le_bytes());
    entries(buf);
    let length = (buf.len() - at - 4) as u32;
    buf[at..at + 4].copy_from_slice(&length.to_le_bytes());
}

fn put_string_map(buf: &mut Vec<u8>, map: &BTreeMap<String, String>) {
    put_prefixed(buf, |b| {
        for (k, v) in map {
            put_str(b, k);
            put_str(b, v);
        }
    });
}

struct ChunkIndex {
    start_ns: u64,
    end_ns: u64,
    offset: u64,
    length: u64,
    message_index_offsets: Vec<(u16, u64)>,
    message_index_length: u64,
    compressed_size: u64,
    uncompressed_size: u64,
}

struct Schema {
    id: u16,
    name: String,
    encoding: String,
    data: Vec<u8>,
}

struct Channel {
    id: u16,
    schema_id: u16,
    topic: String,
    message_encoding: String,
    metadata: BTreeMap<String, String>,
}

impl Schema {
    /// Its record, as written where it is declared and again in the summary.
    fn write(&self, buf: &mut Vec<u8>) {
        record(buf, op::SCHEMA, |b| {
            b.extend_from_slice(&self.id.to_le_bytes());
            put_str(b, &self.name);
            put_str(b, &self.encoding);
            b.extend_from_slice(&(self.data.len() as u32).to_le_bytes());
            b.extend_from_slice(&self.data);
        });
    }
}

impl Channel {
    /// Its record, as written where it is declared and again in the summary.
    fn write(&self, buf: &mut Vec<u8>) {
        record(buf, op::CHANNEL, |b| {
            b.extend_from_slice(&self.id.to_le_bytes());
            b.extend_from_slice(&self.schema_id.to_le_bytes());
            put_str(b, &self.topic);
            put_str(b, &self.message_encoding);
            put_string_map(b, &self.metadata);
        });
    }
}

/// A chunked, zstd-compressed, indexed MCAP written to `W`.
pub(crate) struct McapWriter<W: Write> {
    /// `None` once handed back by [`Self::into_inner`].
    out: Option<W>,
    /// Bytes written to `out`.
    position: u64,
    /// CRC of everything written before the data end record.
    data_crc: crc32fast::Hasher,
    compressor: zstd::bulk::Compressor<'static>,
    chunk_size: usize,
    /// The open chunk's records, uncompressed.
    chunk: Vec<u8>,
    chunk_bounds: Option<(u64, u64)>,
    /// Per channel id: the open chunk's messages (log time, offset in the chunk).
    chunk_messages: Vec<Vec<(u64, u64)>>,
    scratch: Vec<u8>,
    schemas: Vec<Schema>,
    channels: Vec<Channel>,
    chunk_indexes: Vec<ChunkIndex>,
    /// (offset, length, name) of each metadata record.
    metadata_indexes: Vec<(u64, u64, String)>,
    channel_message_counts: BTreeMap<u16, u64>,
    bounds: Option<(u64, u64)>,
    finished: bool,
}

impl<W: Write> McapWriter<W> {
    /// Writes the magic and the header record.
    pub(crate) fn new(
        out: W,
        profile: &str,
        library: &str,
        chunk_size: usize,
        level: i32,
    ) -> io::Result<Self> {
        let mut w = McapWriter {
            out: Some(out),
            position: 0,
            data_crc: crc32fast::Hasher::new(),
            compressor: zstd::bulk::Compressor::new(level)?,
            chunk_size,
            chunk: Vec::with_capacity(chunk_size + (64 << 10)),
            chunk_bounds: None,
            chunk_messages: Vec::new(),
            scratch: Vec::with_capacity(64 << 10),
            schemas: Vec::new(),
            channels: Vec::new(),
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            channel_message_counts: BTreeMap::new(),
            bounds: None,
            finished: false,
        };
        let mut head = MAGIC.to_vec();
        record(&mut head, op::HEADER, |b| {
            put_str(b, profile);
            put_str(b, library);
        });
        w.emit(&head)?;
        Ok(w)
    }

    fn output(&mut self) -> io::Result<&mut W> {
        self.out
            .as_mut()
            .ok_or_else(|| io::Error::other("the MCAP writer was already closed"))
    }

    fn emit(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.output()?.write_all(bytes)?;
        self.data_crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    /// Declares a schema (written into the open chunk, and into the summary); returns its id.
    pub(crate) fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> u16 {
        let schema = Schema {
            id: self.schemas.len() as u16 + 1,
            name: name.into(),
            encoding: encoding.into(),
            data: data.into(),
        };
        schema.write(&mut self.chunk);
        let id = schema.id;
        self.schemas.push(schema);
        id
    }

    /// Declares a channel (written into the open chunk, and into the summary); returns its id.
    pub(crate) fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> u16 {
        let channel = Channel {
            id: self.channels.len() as u16 + 1,
            schema_id,
            topic: topic.into(),
            message_encoding: message_encoding.into(),
            metadata: metadata.clone(),
        };
        channel.write(&mut self.chunk);
        let id = channel.id;
        self.channels.push(channel);
        id
    }

    /// Appends a message to the open chunk; the chunk is compressed and written when full.
    pub(crate) fn write_message(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> io::Result<()> {
        let offset = self.chunk.len() as u64;
        self.chunk.push(op::MESSAGE);
        let length = (2 + 4 + 8 + 8 + data.len()) as u64;
        self.chunk.extend_from_slice(&length.to_le_bytes());
        self.chunk.extend_from_slice(&channel_id.to_le_bytes());
        self.chunk.extend_from_slice(&sequence.to_le_bytes());
        self.chunk.extend_from_slice(&log_time_ns.to_le_bytes());
        self.chunk.extend_from_slice(&publish_time_ns.to_le_bytes());
        self.chunk.extend_from_slice(data);
        let slot = usize::from(channel_id);
        if self.chunk_messages.len() <= slot {
            self.chunk_messages.resize_with(slot + 1, Vec::new);
        }
        self.chunk_messages[slot].push((log_time_ns, offset));
        *self.channel_message_counts.entry(channel_id).or_insert(0) += 1;
        let widen = |b: Option<(u64, u64)>| match b {
            Some((s, e)) => Some((s.min(log_time_ns), e.max(log_time_ns))),
            None => Some((log_time_ns, log_time_ns)),
        };
        self.chunk_bounds = widen(self.chunk_bounds);
        self.bounds = widen(self.bounds);
        if self.chunk.len() >= self.chunk_size {
            self.finish_chunk()?;
        }
        Ok(())
    }

    /// Compresses and writes the open chunk and its message indexes (nothing when it is empty).
    fn finish_chunk(&mut self) -> io::Result<()> {
        if self.chunk.is_empty() {
            return Ok(());
        }
        let compressed = self.compressor.compress(&self.chunk)?;
        let (start_ns, end_ns) = self.chunk_bounds.take().unwrap_or((0, 0));
        let offset = self.position;
        let mut head = std::mem::take(&mut self.scratch);
        head.clear();
        head.push(op::CHUNK);
        let length = (8 + 8 + 8 + 4 + 4 + 4 + 8 + compressed.len()) as u64;
        head.extend_from_slice(&length.to_le_bytes());
        head.extend_from_slice(&start_ns.to_le_bytes());
        head.extend_from_slice(&end_ns.to_le_bytes());
        head.extend_from_slice(&(self.chunk.len() as u64).to_le_bytes());
        head.extend_from_slice(&crc32fast::hash(&self.chunk).to_le_bytes());
        put_str(&mut head, "zstd");
        head.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
        self.emit(&head)?;
        self.emit(&compressed)?;
        let chunk_end = self.position;
        head.clear();
        let mut message_index_offsets = Vec::new();
        for (id, entries) in self.chunk_messages.iter_mut().enumerate() {
            if entries.is_empty() {
                continue;
            }
            message_index_offsets.push((id as u16, chunk_end + head.len() as u64));
            record(&mut head, op::MESSAGE_INDEX, |b| {
                b.extend_from_slice(&(id as u16).to_le_bytes());
                put_prefixed(b, |b| {
                    for &(t, o) in entries.iter() {
                        b.extend_from_slice(&t.to_le_bytes());
                        b.extend_from_slice(&o.to_le_bytes());
                    }
                });
            });
            entries.clear();
        }
        self.emit(&head)?;
        self.chunk_indexes.push(ChunkIndex {
            start_ns,
            end_ns,
            offset,
            length: chunk_end - offset,
            message_index_offsets,
            message_index_length: head.len() as u64,
            compressed_size: compressed.len() as u64,
            uncompressed_size: self.chunk.len() as u64,
        });
        self.scratch = head;
        self.chunk.clear();
        Ok(())
    }

    /// Writes a metadata record into the data section (after the open chunk).
    pub(crate) fn write_metadata(
        &mut self,
        name: &str,
        metadata: &BTreeMap<String, String>,
    ) -> io::Result<()> {
        self.finish_chunk()?;
        let mut rec = Vec::new();
        record(&mut rec, op::METADATA, |b| {
            put_str(b, name);
            put_string_map(b, metadata);
        });
        self.metadata_indexes
            .push((self.position, rec.len() as u64, name.to_string()));
        self.emit(&rec)
    }

    /// Ends the open chunk and flushes the output.
    pub(crate) fn flush(&mut self) -> io::Result<()> {
        self.finish_chunk()?;
        self.output()?.flush()
    }

    /// Writes the last chunk, the data end, the summary section, the footer and the closing
    /// magic. Calling it again does nothing.
    pub(crate) fn finish(&mut self) -> io::Result<()> {
        if self.finished {
            return Ok(());
        }
        self.finish_chunk()?;
        let data_crc = self.data_crc.clone().finalize();
        let mut end = Vec::new();
        record(&mut end, op::DATA_END, |b| {
            b.extend_from_slice(&data_crc.to_le_bytes())
        });
        self.emit(&end)?;
        let summary_start = self.position;
        let (summary, offsets) = self.summary(summary_start);
        let mut tail = summary;
        let summary_offset_start = summary_start + tail.len() as u64;
        tail.extend_from_slice(&offsets);
        tail.push(op::FOOTER);
        tail.extend_from_slice(&20u64.to_le_bytes());
        tail.extend_from_slice(&summary_start.to_le_bytes());
        tail.extend_from_slice(&summary_offset_start.to_le_bytes());
        let summary_crc = crc32fast::hash(&tail);
        tail.extend_from_slice(&summary_crc.to_le_bytes());
        tail.extend_from_slice(MAGIC);
        self.emit(&tail)?;
        self.output()?.flush()?;
        self.finished = true;
        Ok(())
    }

    /// The summary section's groups and their summary offset records.
    fn summary(&self, start: u64) -> (Vec<u8>, Vec<u8>) {
        let mut s = Vec::new();
        let mut offsets = Vec::new();
        let mut group = |s: &mut Vec<u8>, opcode: u8, write: &dyn Fn(&mut Vec<u8>)| {
            let at = s.len();
            write(s);
            if s.len() > at {
                record(&mut offsets, op::SUMMARY_OFFSET, |b| {
                    b.push(opcode);
                    b.extend_from_slice(&(start + at as u64).to_le_bytes());
                    b.extend_from_slice(&((s.len() - at) as u64).to_le_bytes());
                });
            }
        };
        group(&mut s, op::SCHEMA, &|s| {
            self.schemas.iter().for_each(|x| x.write(s))
        });
        group(&mut s, op::CHANNEL, &|s| {
            self.channels.iter().for_each(|c| c.write(s))
        });
        group(&mut s, op::STATISTICS, &|s| self.statistics(s));
        group(&mut s, op::CHUNK_INDEX, &|s| {
            for c in &self.chunk_indexes {
                record(s, op::CHUNK_INDEX, |b| {
                    for v in [c.start_ns, c.end_ns, c.offset, c.length] {
                        b.extend_from_slice(&v.to_le_bytes());
                    }
                    put_prefixed(b, |b| {
                        for &(id, o) in &c.message_index_offsets {
                            b.extend_from_slice(&id.to_le_bytes());
                            b.extend_from_slice(&o.to_le_bytes());
                        }
                    });
                    b.extend_from_slice(&c.message_index_length.to_le_bytes());
                    put_str(b, "zstd");
                    b.extend_from_slice(&c.compressed_size.to_le_bytes());
                    b.extend_from_slice(&c.uncompressed_size.to_le_bytes());
                });
            }
        });
        group(&mut s, op::METADATA_INDEX, &|s| {
            for (offset, length, name) in &self.metadata_indexes {
                record(s, op::METADATA_INDEX, |b| {
                    b.extend_from_slice(&offset.to_le_bytes());
                    b.extend_from_slice(&length.to_le_bytes());
                    put_str(b, name);
                });
            }
        });
        (s, offsets)
    }

    fn statistics(&self, s: &mut Vec<u8>) {
        let (start_ns, end_ns) = self.bounds.unwrap_or((0, 0));
        record(s, op::STATISTICS, |b| {
            let messages: u64 = self.channel_message_counts.values().sum();
            b.extend_from_slice(&messages.to_le_bytes());
            b.extend_from_slice(&(self.schemas.len() as u16).to_le_bytes());
            b.extend_from_slice(&(self.channels.len() as u32).to_le_bytes());
            b.extend_from_slice(&0u32.to_le_bytes());
            b.extend_from_slice(&(self.metadata_indexes.len() as u32).to_le_bytes());
            b.extend_from_slice(&(self.chunk_indexes.len() as u32).to_le_bytes());
            b.extend_from_slice(&start_ns.to_le_bytes());
            b.extend_from_slice(&end_ns.to_le_bytes());
            put_prefixed(b, |b| {
                for (id, n) in &self.channel_message_counts {
                    b.extend_from_slice(&id.to_le_bytes());
                    b.extend_from_slice(&n.to_le_bytes());
                }
            });
        });
    }

    /// Finishes the file (see [`Self::finish`]) and hands back the output.
    pub(crate) fn into_inner(mut self) -> io::Result<W> {
        self.finish()?;
        self.output()?;
        Ok(self.out.take().expect("checked just above"))
    }
}

/// A writer dropped unfinished (an error on the way, a panic) still closes the file: everything
/// written so far stays readable with its indexes, as with the `mcap` crate's writer.
impl<W: Write> Drop for McapWriter<W> {
    fn drop(&mut self) {
        if self.out.is_some() {
            let _ = self.finish();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::read::Options;

    /// Three hundred messages on two channels over many small chunks, with metadata.
    fn sample(chunk_size: usize) -> Vec<u8> {
        let mut w = McapWriter::new(Vec::new(), "ros2", "test", chunk_size, 1).expect("writer");
        w.write_metadata("header", &BTreeMap::from([("k".into(), "v".into())]))
            .expect("metadata");
        let schema = w.add_schema("pkg/msg/A", "ros2msg", b"float64 x");
        let a = w.add_channel(schema, "a", "cdr", &BTreeMap::new());
        let b = w.add_channel(
            schema,
            "b",
            "cdr",
            &BTreeMap::from([("type_name".into(), "A".into())]),
        );
        for k in 0..300u64 {
            let channel = if k % 3 == 0 { b } else { a };
            let data = [k as u8; 40];
            w.write_message(channel, k as u32, 1000 + k, 1000 + k, &data)
                .expect("message");
        }
        w.into_inner().expect("finished")
    }

    /// The `mcap` crate reads every message back in order, with chunk CRCs checked, and its
    /// summary, statistics and message indexes point at the right messages.
    #[test]
    fn the_mcap_crate_reads_messages_summary_and_indexes() {
        let bytes = sample(2048);
        let stream =
            mcap::MessageStream::new_with_options(&bytes, Options::ValidateChunkCrcs.into())
                .expect("stream");
        let messages: Vec<_> = stream.collect::<Result<_, _>>().expect("messages");
        assert_eq!(messages.len(), 300);
        for (k, m) in messages.iter().enumerate() {
            assert_eq!(m.log_time, 1000 + k as u64);
            assert_eq!(m.sequence, k as u32);
            assert_eq!(m.channel.topic, if k % 3 == 0 { "b" } else { "a" });
            assert_eq!(m.data.as_ref(), &[k as u8; 40]);
        }
        let summary = mcap::Summary::read(&bytes)
            .expect("summary")
            .expect("present");
        let stats = summary.stats.as_ref().expect("statistics");
        assert_eq!(stats.message_count, 300);
        assert_eq!(
            (stats.message_start_time, stats.message_end_time),
            (1000, 1299)
        );
        assert_eq!(stats.channel_message_counts.values().sum::<u64>(), 300);
        assert_eq!(stats.chunk_count as usize, summary.chunk_indexes.len());
        assert!(
            summary.chunk_indexes.len() > 5,
            "{}",
            summary.chunk_indexes.len()
        );
        assert_eq!(summary.channels.len(), 2);
        assert_eq!(summary.metadata_indexes.len(), 1);
        let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).expect("metadata");
        assert_eq!(meta.metadata.get("k").map(String::as_str), Some("v"));
        let mut seen = 0;
        for index in &summary.chunk_indexes {
            for (channel, entries) in summary
                .read_message_indexes(&bytes, index)
                .expect("indexes")
            {
                for entry in entries {
                    let m = summary.seek_message(&bytes, index, &entry).expect("seek");
                    assert_eq!(m.log_time, entry.log_time);
                    assert_eq!(m.channel.topic, channel.topic);
                    assert!(
                        (index.message_start_time..=index.message_end_time).contains(&m.log_time)
                    );
                    seen += 1;
                }
            }
        }
        assert_eq!(seen, 300);
    }

    /// The data section's and the summary's CRCs are those of the bytes they cover.
    #[test]
    fn the_crcs_cover_what_the_specification_says() {
        let bytes = sample(4096);
        let footer = mcap::read::footer(&bytes).expect("footer");
        let summary_start = footer.summary_start as usize;
        // The data end record: opcode, length 4, the CRC, just before the summary.
        let data_end = summary_start - 13;
        assert_eq!(bytes[data_end], op::DATA_END);
        let data_crc =
            u32::from_le_bytes(bytes[data_end + 9..summary_start].try_into().expect("4"));
        assert_eq!(data_crc, crc32fast::hash(&bytes[..data_end]));
        let footer_crc_at = bytes.len() - MAGIC.len() - 4;
        assert_eq!(
            footer.summary_crc,
            crc32fast::hash(&bytes[summary_start..footer_crc_at])
        );
    }

    /// A writer dropped without `finish` still closes the file.
    #[test]
    fn a_dropped_writer_closes_the_file() {
        let mut out = Vec::new();
        {
            let mut w = McapWriter::new(&mut out, "ros2", "test", 1 << 20, 1).expect("writer");
            let s = w.add_schema("pkg/msg/A", "ros2msg", b"");
            let c = w.add_channel(s, "a", "cdr", &BTreeMap::new());
            w.write_message(c, 1, 5, 5, b"abc").expect("message");
        }
        let messages: Vec<_> = mcap::MessageStream::new(&out)
            .expect("stream")
            .collect::<Result<_, _>>()
            .expect("messages");
        assert_eq!(messages.len(), 1);
        assert!(out.ends_with(MAGIC));
    }
}
