//! `auvnav info LOG`: what a log holds — its header (producer, version, UTC anchor, notes), its
//! channels with message counts, rates and time spans, the embedded configuration, and whether
//! the file ends cleanly. Reads the whole file (a killed recorder's log has no summary section).

use anyhow::Context;
use auvnav_log::{LogError, LogHeader, LogMessage, LogReader};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The log (MCAP).
    pub log: PathBuf,
    /// Also print the embedded configuration (TOML) in full.
    #[arg(long)]
    pub config: bool,
    /// Print as JSON (docs/json.md).
    #[arg(long)]
    pub json: bool,
}

/// One channel of a log.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelSummary {
    pub topic: String,
    pub schema: String,
    pub messages: u64,
    /// Messages whose bytes do not match their schema.
    pub undecodable: u64,
    /// Log time of the first and last message, seconds after the log's first message.
    pub first_s: f64,
    pub last_s: f64,
    /// Mean rate over the channel's span ((messages - 1) / span), 0 for fewer than two messages.
    pub rate_hz: f64,
    /// Channel notes (type name, driver, ...).
    pub metadata: BTreeMap<String, String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct LogInfo {
    pub log: String,
    pub file_bytes: u64,
    /// The log's format version (the document's own `format_version` is the JSON vocabulary's).
    pub log_format_version: u32,
    pub min_reader_version: u32,
    pub producer: String,
    pub producer_version: String,
    /// UTC of the first message, from the header's anchor (`clock.utc`, `clock.monotonic_ns`);
    /// absent for logs without one (simulated, imported).
    pub start_utc: Option<String>,
    /// Log time of the first message (ns; `CLOCK_MONOTONIC` for recordings).
    pub first_log_time_ns: Option<u64>,
    /// UTC from the GNSS receiver: its first fix with a valid time ties the log's clock to GPS
    /// time, independently of the host's clock.
    pub gnss_time: Option<GnssTime>,
    pub duration_s: f64,
    pub messages: u64,
    pub channels: Vec<ChannelSummary>,
    /// Bytes of the embedded configuration (TOML); the text with `--config`.
    pub config_bytes: usize,
    pub config: Option<String>,
    pub notes: BTreeMap<String, String>,
    /// Why reading stopped before the end (a killed writer's log), if it did.
    pub stopped: Option<String>,
    /// What was passed over as damaged (corrupt chunks and their time spans), if anything.
    pub damaged: Option<auvnav_log::Corruption>,
}

/// The log's time from its GNSS fixes.
#[derive(Debug, Clone, Serialize)]
pub struct GnssTime {
    /// UTC of the first message by the first GNSS fix with a valid time (GPS time minus the
    /// leap seconds, 18 s since 2017).
    pub start_utc: String,
    /// The header's clock anchor minus the GNSS time at the same instant (s): how far the host's
    /// clock was from GNSS time when the recorder started, within the fix's latency. Absent
    /// without a header anchor.
    pub host_clock_minus_gnss_s: Option<f64>,
}

/// UTC (ns since 1970) of log time `t_ns` by a GNSS fix stamped `fix_host_ns` with GPS time
/// `gps_ns`.
fn gnss_utc_ns(t_ns: u64, fix_host_ns: u64, gps_ns: u64) -> i64 {
    use auvnav_drivers::gnss::{GPS_EPOCH_UNIX_S, GPS_MINUS_UTC_S};
    gps_ns as i64 + GPS_EPOCH_UNIX_S * 1_000_000_000 - i64::from(GPS_MINUS_UTC_S) * 1_000_000_000
        + (t_ns as i64 - fix_host_ns as i64)
}

fn gnss_time(header: &LogHeader, first_ns: u64, fix: &auvnav_shm_schema::GnssFixV1) -> GnssTime {
    let utc = gnss_utc_ns(first_ns, fix.host_time_ns, fix.device_time_ns);
    let start_utc = chrono::DateTime::from_timestamp_nanos(utc)
        .to_rfc3339_opts(chrono::SecondsFormat::Micros, true);
    let host_clock_minus_gnss_s = (|| {
        let anchor = chrono::DateTime::parse_from_rfc3339(header.notes.get("clock.utc")?).ok()?;
        let anchor_mono: u64 = header.notes.get("clock.monotonic_ns")?.parse().ok()?;
        let host_ns = anchor.timestamp_nanos_opt()?;
        let gnss_ns = gnss_utc_ns(anchor_mono, fix.host_time_ns, fix.device_time_ns);
        Some((host_ns - gnss_ns) as f64 * 1e-9)
    })();
    GnssTime {
        start_utc,
        host_clock_minus_gnss_s,
    }
}

/// The UTC time of log time `t_ns`, from the header's anchor notes.
pub fn utc_of(header: &LogHeader, t_ns: u64) -> Option<String> {
    let utc = chrono::DateTime::parse_from_rfc3339(header.notes.get("clock.utc")?).ok()?;
    let anchor: u64 = header.notes.get("clock.monotonic_ns")?.parse().ok()?;
    let delta = chrono::TimeDelta::nanoseconds(t_ns as i64 - anchor as i64);
    Some((utc.to_utc() + delta).to_rfc3339_opts(chrono::SecondsFormat::Micros, true))
}

struct Span {
    info: ChannelSummary,
    first_ns: u64,
    last_ns: u64,
}

impl Span {
    /// A channel with no message counted yet, its span starting at `t_ns`.
    fn new(topic: &str, schema: &str, t_ns: u64) -> Span {
        Span {
            info: ChannelSummary {
                topic: topic.to_string(),
                schema: schema.to_string(),
                messages: 0,
                undecodable: 0,
                first_s: 0.0,
                last_s: 0.0,
                rate_hz: 0.0,
                metadata: BTreeMap::new(),
            },
            first_ns: t_ns,
            last_ns: t_ns,
        }
    }
}

/// Reads `path` through and summarises it.
pub fn info(path: &Path, with_config: bool) -> anyhow::Result<LogInfo> {
    let file_bytes = std::fs::metadata(path)
        .with_context(|| format!("opening {}", path.display()))?
        .len();
    let mut reader = LogReader::open(path)?;
    let header = reader
        .read_header()
        .with_context(|| format!("reading {}", path.display()))?;
    let mut spans: BTreeMap<String, Span> = BTreeMap::new();
    let mut first: Option<u64> = None;
    let mut last = 0u64;
    let mut messages = 0u64;
    let mut stopped = None;
    let mut first_timed_fix = None;
    loop {
        let m = match reader.next_message() {
            Ok(Some(m)) => m,
            Ok(None) => break,
            Err(e @ (LogError::Truncated | LogError::Mcap(_))) => {
                stopped = Some(e.to_string());
                break;
            }
            Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
        };
        messages += 1;
        first = Some(first.map_or(m.log_time_ns, |f| f.min(m.log_time_ns)));
        last = last.max(m.log_time_ns);
        let undecodable = u64::from(m.decode_any().is_err());
        let span = spans
            .entry(m.topic.to_string())
            .or_insert_with(|| Span::new(&m.topic, &m.schema_name, m.log_time_ns));
        span.info.messages += 1;
        span.info.undecodable += undecodable;
        if first_timed_fix.is_none()
            && let Ok(LogMessage::Gnss(f)) = m.decode_any()
            && f.validity & auvnav_shm_schema::GnssFixV1::VALID_DEVICE_TIME != 0
        {
            first_timed_fix = Some(f);
        }
        span.first_ns = span.first_ns.min(m.log_time_ns);
        span.last_ns = span.last_ns.max(m.log_time_ns);
    }
    // Declared channels without messages are listed too.
    for c in reader.channels() {
        let span = spans
            .entry(c.topic.to_string())
            .or_insert_with(|| Span::new(&c.topic, &c.schema_name, 0));
        span.info.metadata = c.metadata.clone();
    }
    let t0 = first.unwrap_or(0);
    let channels = spans
        .into_values()
        .map(|s| {
            let mut c = s.info;
            if c.messages > 0 {
                c.first_s = s.first_ns.saturating_sub(t0) as f64 * 1e-9;
                c.last_s = s.last_ns.saturating_sub(t0) as f64 * 1e-9;
                let span = c.last_s - c.first_s;
                if c.messages > 1 && span > 0.0 {
                    c.rate_hz = (c.messages - 1) as f64 / span;
                }
            }
            c
        })
        .collect();
    Ok(LogInfo {
        log: path.display().to_string(),
        file_bytes,
        log_format_version: header.format_version,
        min_reader_version: header.min_reader_version,
        producer: header.producer.clone(),
        producer_version: header.producer_version.clone(),
        start_utc: first.and_then(|f| utc_of(&header, f)),
        first_log_time_ns: first,
        gnss_time: first
            .zip(first_timed_fix.as_ref())
            .map(|(f, fix)| gnss_time(&header, f, fix)),
        duration_s: last.saturating_sub(t0) as f64 * 1e-9,
        messages,
        channels,
        config_bytes: header.config.len(),
        config: with_config.then(|| header.config.clone()),
        notes: header.notes.clone(),
        stopped,
        damaged: reader
            .corruption()
            .any()
            .then(|| reader.corruption().clone()),
    })
}

/// Runs `auvnav info`.
pub fn run(a: &InfoArgs) -> anyhow::Result<LogInfo> {
    let i = info(&a.log, a.config)?;
    if a.json {
        crate::json::print(&i)?;
    } else {
        print(&i);
    }
    Ok(i)
}

fn print(i: &LogInfo) {
    println!("{} ({} bytes)", i.log, i.file_bytes);
    println!(
        "  written by {} {} (log format {}, readers from {})",
        i.producer, i.producer_version, i.log_format_version, i.min_reader_version
    );
    match &i.start_utc {
        Some(t) => println!("  starts {t} (UTC, from the header's clock anchor)"),
        None => println!("  no UTC anchor (simulated or imported log)"),
    }
    if let Some(g) = &i.gnss_time {
        println!(
            "  starts {} (UTC, from the GNSS fixes){}",
            g.start_utc,
            g.host_clock_minus_gnss_s
                .map(|d| format!("; the host clock was {d:+.3} s from GNSS time"))
                .unwrap_or_default()
        );
    }
    println!(
        "  {} messages over {:.3} s{}",
        i.messages,
        i.duration_s,
        i.stopped
            .as_ref()
            .map(|s| format!("; stopped early: {s}"))
            .unwrap_or_default()
    );
    if let Some(d) = &i.damaged {
        println!("  DAMAGED: {d}");
    }
    println!(
        "  {:<20} {:<34} {:>9} {:>9} {:>10} {:>10} {:>11}",
        "topic", "schema", "messages", "rate Hz", "first s", "last s", "undecodable"
    );
    for c in &i.channels {
        println!(
            "  {:<20} {:<34} {:>9} {:>9.2} {:>10.3} {:>10.3} {:>11}",
            c.topic, c.schema, c.messages, c.rate_hz, c.first_s, c.last_s, c.undecodable
        );
    }
    if !i.notes.is_empty() {
        println!("  header notes:");
        for (k, v) in &i.notes {
            let v = if v.len() > 100 {
                format!(
                    "{}… ({} bytes)",
                    v.chars().take(100).collect::<String>(),
                    v.len()
                )
            } else {
                v.clone()
            };
            println!("    {k} = {v}");
        }
    }
    match &i.config {
        Some(c) if !c.is_empty() => {
            println!("  configuration:");
            for l in c.lines() {
                println!("    {l}");
            }
        }
        Some(_) | None if i.config_bytes == 0 => println!("  no embedded configuration"),
        _ => println!(
            "  embedded configuration: {} bytes (--config prints it)",
            i.config_bytes
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_of_a_log_time_follows_the_anchor() {
        let mut h = LogHeader::new("test", "");
        assert_eq!(utc_of(&h, 5), None);
        h.notes
            .insert("clock.utc".into(), "2026-02-28T23:59:59.500000Z".into());
        h.notes
            .insert("clock.monotonic_ns".into(), "1000000000".into());
        assert_eq!(
            utc_of(&h, 1_750_000_000).as_deref(),
            Some("2026-03-01T00:00:00.250000Z")
        );
        assert_eq!(
            utc_of(&h, 0).as_deref(),
            Some("2026-02-28T23:59:58.500000Z")
        );
    }
}
