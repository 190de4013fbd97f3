//! `auvnav decode --protocol P FILE`: decodes a captured byte file with the same decoder the
//! driver runs, prints one JSON object per frame (with `--json`) and a summary.

use anyhow::Context;
use auvnav_drivers::framing::DecoderStats;
use auvnav_drivers::pd0::Pd0Decoder;
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Protocol {
    /// Teledyne RDI PD0 (DVL/ADCP ensembles).
    Pd0,
    /// Water Linked DVL serial protocol (wrz, wru, wrp, ...).
    Wldvl,
    /// KVH 1750/1775 IMU, formats A and B.
    Kvh1750,
    /// Xsens MTi XBus / MTData2.
    Xsens,
    /// Blueprint SeaTrac USBL serial command interface.
    Seatrac,
}

impl Protocol {
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Pd0 => "pd0",
            Protocol::Wldvl => "wldvl",
            Protocol::Kvh1750 => "kvh1750",
            Protocol::Xsens => "xsens",
            Protocol::Seatrac => "seatrac",
        }
    }
}

#[derive(clap::Args, Debug, Clone)]
pub struct DecodeArgs {
    /// Protocol of the capture.
    #[arg(long, value_enum)]
    pub protocol: Protocol,
    /// The captured bytes.
    pub file: PathBuf,
    /// One JSON object per frame on standard output, then the summary as the last line.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
struct Summary<'a> {
    summary: &'a DecoderStats,
    file: String,
    protocol: &'static str,
}

/// Decodes the file in 1 KiB reads (as a driver would see the bytes) and returns the counters.
pub fn run(a: &DecodeArgs) -> anyhow::Result<DecoderStats> {
    let bytes = std::fs::read(&a.file).with_context(|| format!("reading {}", a.file.display()))?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let mut first: Option<String> = None;
    let mut last: Option<String> = None;
    let mut emit = |line: String, out: &mut dyn Write| -> anyhow::Result<()> {
        if a.json {
            writeln!(out, "{line}")?;
        } else {
            if first.is_none() {
                first = Some(line.clone());
            }
            last = Some(line);
        }
        Ok(())
    };
    let chunks = bytes.chunks(1024);
    let stats = match a.protocol {
        Protocol::Pd0 => {
            let mut d = Pd0Decoder::new();
            for chunk in chunks {
                d.push(chunk);
                while let Some(r) = d.next_ensemble() {
                    if let Ok(e) = r {
                        emit(serde_json::to_string(&e)?, &mut out)?;
                    }
                }
            }
            for e in d.finish() {
                emit(serde_json::to_string(&e)?, &mut out)?;
            }
            d.stats
        }
        Protocol::Wldvl => {
            let mut d = auvnav_drivers::wldvl::WlDecoder::new();
            for chunk in chunks {
                d.push(chunk);
                while let Some(r) = d.next_frame() {
                    if let Ok(f) = r {
                        emit(serde_json::to_string(&f)?, &mut out)?;
                    }
                }
            }
            d.stats
        }
        Protocol::Kvh1750 => {
            let mut d = auvnav_drivers::kvh::KvhDecoder::new();
            for chunk in chunks {
                d.push(chunk);
                while let Some(f) = d.next_sample() {
                    emit(serde_json::to_string(&f)?, &mut out)?;
                }
            }
            d.stats
        }
        Protocol::Seatrac => {
            let mut d = auvnav_drivers::seatrac::SeatracDecoder::new();
            for chunk in chunks {
                d.push(chunk);
                while let Some(r) = d.next_frame() {
                    if let Ok(f) = r {
                        emit(serde_json::to_string(&f)?, &mut out)?;
                    }
                }
            }
            d.stats
        }
        Protocol::Xsens => {
            let mut d = auvnav_drivers::xsens::XbusDecoder::new();
            for chunk in chunks {
                d.push(chunk);
                while let Some(f) = d.next_message() {
                    emit(serde_json::to_string(&f)?, &mut out)?;
                }
            }
            d.stats
        }
    };
    let summary = Summary {
        summary: &stats,
        file: a.file.display().to_string(),
        protocol: a.protocol.name(),
    };
    if a.json {
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
        if let Some(f) = first {
            writeln!(out, "first frame: {f}")?;
        }
        if let Some(l) = last {
            writeln!(out, "last frame:  {l}")?;
        }
    }
    out.flush()?;
    Ok(stats)
}
