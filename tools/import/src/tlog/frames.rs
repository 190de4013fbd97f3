//! The records of a tlog: an 8-byte big-endian receive time (µs, Unix), then a MAVLink 1 or 2
//! frame whose length and checksum hold; damage is skipped byte by byte to the next record.

use super::TlogSummary;
use mavlink::Message;
use mavlink::dialects::ardupilotmega::MavMessage;

/// One frame: receive time (µs, Unix) and the parsed message.
pub(super) struct Frame {
    pub received_us: u64,
    pub message: MavMessage,
}

/// The frames of a tlog, and the counts of what could not be read.
pub(super) fn frames(bytes: &[u8], s: &mut TlogSummary) -> Vec<Frame> {
    let mut out = Vec::new();
    let mut pos = 0;
    let mut skipping = false;
    while pos + 8 < bytes.len() {
        match frame_at(bytes, pos) {
            FrameAt::Frame(len, f) => {
                out.push(*f);
                s.frames += 1;
                pos += 8 + len;
                skipping = false;
            }
            FrameAt::BadChecksum(len) if !skipping => {
                s.bad_checksum += 1;
                pos += 8 + len;
            }
            FrameAt::Unknown(len) if !skipping => {
                s.unknown += 1;
                s.frames += 1;
                pos += 8 + len;
            }
            _ => {
                // Not a record here: look for the next one byte by byte.
                skipping = true;
                s.bytes_skipped += 1;
                pos += 1;
            }
        }
    }
    s.bytes_skipped += bytes.len() - pos.min(bytes.len());
    drop_damaged_stamps(out, s)
}

/// Leaves out the frames whose receive time stands [`super::STAMP_JUMP_S`] away from both
/// neighbours while the neighbours agree (the 8 time-stamp bytes are outside the frame's
/// checksum); counted as out of order.
fn drop_damaged_stamps(frames: Vec<Frame>, s: &mut TlogSummary) -> Vec<Frame> {
    let jump_us = (super::STAMP_JUMP_S * 1e6) as u64;
    let far = |a: u64, b: u64| a.abs_diff(b) > jump_us;
    let t: Vec<u64> = frames.iter().map(|f| f.received_us).collect();
    let damaged = |i: usize| {
        let before = i.checked_sub(1).map(|j| t[j]);
        let after = t.get(i + 1).copied();
        match (before, after) {
            (Some(b), Some(a)) => far(t[i], b) && far(t[i], a) && !far(b, a),
            // The first or last record: against the next two (or previous two).
            (None, Some(a)) => t.get(i + 2).is_some_and(|&a2| far(t[i], a) && !far(a, a2)),
            (Some(b), None) => i
                .checked_sub(2)
                .is_some_and(|j| far(t[i], b) && !far(t[j], b)),
            (None, None) => false,
        }
    };
    let keep: Vec<bool> = (0..frames.len()).map(|i| !damaged(i)).collect();
    s.out_of_order += keep.iter().filter(|k| !**k).count();
    frames
        .into_iter()
        .zip(keep)
        .filter_map(|(f, k)| k.then_some(f))
        .collect()
}

enum FrameAt {
    /// A frame of this many bytes (boxed: a message is some 300 bytes).
    Frame(usize, Box<Frame>),
    BadChecksum(usize),
    Unknown(usize),
    None,
}

/// The record at `pos`: a time stamp and a frame whose length and checksum hold.
fn frame_at(bytes: &[u8], pos: usize) -> FrameAt {
    let mut stamp = [0u8; 8];
    stamp.copy_from_slice(&bytes[pos..pos + 8]);
    let received_us = u64::from_be_bytes(stamp);
    let f = &bytes[pos + 8..];
    // (version, header length, payload length, message id, signature length)
    let (version, header, len, id, signature) = match f {
        [0xFD, len, incompat, _, _, _, _, a, b, c, ..] => (
            mavlink::MavlinkVersion::V2,
            10,
            usize::from(*len),
            u32::from_le_bytes([*a, *b, *c, 0]),
            if incompat & 1 != 0 { 13 } else { 0 },
        ),
        [0xFE, len, _, _, _, id, ..] => (
            mavlink::MavlinkVersion::V1,
            6,
            usize::from(*len),
            u32::from(*id),
            0,
        ),
        _ => return FrameAt::None,
    };
    let total = header + len + 2 + signature;
    if f.len() < total {
        return FrameAt::None;
    }
    let crc = u16::from_le_bytes([f[header + len], f[header + len + 1]]);
    if mavlink::calculate_crc(&f[1..header + len], MavMessage::extra_crc(id)) != crc {
        return FrameAt::BadChecksum(total);
    }
    match MavMessage::parse(version, id, &f[header..header + len]) {
        Ok(message) => FrameAt::Frame(
            total,
            Box::new(Frame {
                received_us,
                message,
            }),
        ),
        Err(_) => FrameAt::Unknown(total),
    }
}
