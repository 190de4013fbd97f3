//! `auvnav decode --protocol P FILE`: decodes a captured byte file with the same decoder the
//! driver runs, prints one JSON object per frame (with `--json`) and a summary.

use anyhow::Context;
use auvnav_drivers::framing::{DecoderStats, StreamDecoder, decode_stream};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

/// The protocols, as the drivers name them.
pub use auvnav_drivers::device::Protocol;

#[derive(clap::Args, Debug, Clone)]
pub struct DecodeArgs {
    /// Protocol of the capture.
    #[arg(long, value_parser = crate::args::config_enum::<Protocol>(&Protocol::NAMES))]
    pub protocol: Protocol,
    /// The captured bytes.
    pub file: PathBuf,
    /// One JSON object per frame on standard output, then the summary as the last line.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
struct Summary<'a> {
    /// The JSON vocabulary's version (docs/json.md); only the summary line carries it.
    format_version: u32,
    summary: &'a DecoderStats,
    file: String,
    protocol: &'static str,
}

/// Decodes the file in 1 KiB reads (as a driver would see the bytes) and returns the counters.
pub fn run(a: &DecodeArgs) -> anyhow::Result<DecoderStats> {
    use auvnav_drivers::{kvh, nmea, nortek, pd0, seatrac, ubx, wldvl, wldvl_json, xsens};
    let bytes = std::fs::read(&a.file).with_context(|| format!("reading {}", a.file.display()))?;
    let (stats, lines) = match a.protocol {
        Protocol::Pd0 => frames_as_json(pd0::Pd0Decoder::new(), &bytes)?,
        Protocol::Wldvl => frames_as_json(wldvl::WlDecoder::new(), &bytes)?,
        Protocol::Kvh1750 => frames_as_json(kvh::KvhDecoder::new(), &bytes)?,
        Protocol::Xsens => frames_as_json(xsens::XbusDecoder::new(), &bytes)?,
        Protocol::Seatrac => frames_as_json(seatrac::SeatracDecoder::new(), &bytes)?,
        Protocol::Nortek => frames_as_json(nortek::NortekDecoder::new(), &bytes)?,
        Protocol::WldvlJson => frames_as_json(wldvl_json::JsonDecoder::new(), &bytes)?,
        Protocol::Nmea => frames_as_json(nmea::NmeaDecoder::new(), &bytes)?,
        Protocol::Ubx => frames_as_json(ubx::UbxDecoder::new(), &bytes)?,
    };
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let summary = Summary {
        format_version: auvnav_version::JSON_FORMAT_VERSION,
        summary: &stats,
        file: a.file.display().to_string(),
        protocol: a.protocol.name(),
    };
    if a.json {
        for l in &lines {
            writeln!(out, "{l}")?;
        }
        writeln!(out, "{}", serde_json::to_string(&summary)?)?;
    } else {
        writeln!(
            out,
            "{}: {} frames, {} checksum errors, {} malformed, {} resyncs, {} of {} bytes skipped",
            a.file.display(),
            stats.frames,
            stats.checksum_errors,
            stats.malformed,
            stats.resyncs,
            stats.bytes_skipped,
            stats.bytes
        )?;
        if let Some(f) = lines.first() {
            writeln!(out, "first frame: {f}")?;
        }
        if let Some(l) = lines.last() {
            writeln!(out, "last frame:  {l}")?;
        }
    }
    out.flush()?;
    Ok(stats)
}

/// Every frame of `bytes` as a JSON line, and the decoder's counters.
fn frames_as_json<D: StreamDecoder>(
    mut d: D,
    bytes: &[u8],
) -> anyhow::Result<(DecoderStats, Vec<String>)> {
    let mut lines = Vec::new();
    let mut error = None;
    decode_stream(&mut d, bytes, 1024, |f| match serde_json::to_string(&f) {
        Ok(l) => lines.push(l),
        Err(e) => error = Some(e),
    });
    if let Some(e) = error {
        return Err(e.into());
    }
    Ok((*d.stats(), lines))
}
