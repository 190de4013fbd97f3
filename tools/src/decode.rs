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

/// Decodes the file in 64 KiB reads (as a driver would see the bytes) and returns the counters.
pub fn run(a: &DecodeArgs) -> anyhow::Result<DecoderStats> {
    let bytes = std::fs::read(&a.file).with_context(|| format!("reading {}", a.file.display()))?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let mut first: Option<String> = None;
    let mut last: Option<String> = None;
    let stats = match a.protocol {
        Protocol::Pd0 => {
            let mut d = Pd0Decoder::new();
            let mut emit =
                |e: &auvnav_drivers::pd0::Ensemble, out: &mut dyn Write| -> anyhow::Result<()> {
                    let line = serde_json::to_string(e)?;
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
            for chunk in bytes.chunks(1 << 16) {
                d.push(chunk);
                while let Some(r) = d.next_ensemble() {
                    if let Ok(e) = r {
                        emit(&e, &mut out)?;
                    }
                }
            }
            for e in d.finish() {
                emit(&e, &mut out)?;
            }
            d.stats
        }
    };
    let summary = Summary {
        summary: &stats,
        file: a.file.display().to_string(),
        protocol: "pd0",
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
