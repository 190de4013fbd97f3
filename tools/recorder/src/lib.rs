//! `auvnav record`: subscribes to every topic of a deployment (and the drivers' raw-byte channels
//! when asked) and writes them to an MCAP log.
//!
//! Crash safety: the log is written in chunks and flushed (and synced to the disk) every
//! `--flush-s` seconds, so a killed recorder or a power cut loses at most that much; streaming
//! readers read such a file up to its last flushed chunk, and `auvnav record --recover FILE`
//! rewrites it as a complete, indexed log. Losses on the bus show as sequence gaps and are
//! counted per topic. A write error (a full disk) stops the recorder with a report; what was
//! flushed before stays readable.
#![forbid(unsafe_code)]

use anyhow::{Context, bail};
use auvnav_log::{Corruption, LogError, LogHeader, LogReader, LogWriter, write_log_atomically};
use auvnav_shm_schema::bus::{Bus, BusSubscriber, Sequenced};
use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1,
    ImuSampleV1, LateAidV1, MagnetometerV1, Message, NavSolutionV1, ProcessHealthV1, RawBytesV1,
    SessionEventV1, SoundVelocityV1, TruthStateV1, UsblFixV1, qos, topic,
};
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// The log to write (MCAP).
    #[arg(long, required_unless_present = "recover")]
    pub out: Option<PathBuf>,
    /// Service-name prefix of the deployment.
    #[arg(long, default_value = topic::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Also record the raw bytes of these drivers (`raw/<name>`; repeatable).
    #[arg(long = "raw", value_name = "DRIVER")]
    pub raw: Vec<String>,
    /// Flush and sync the log this often (s, 0.05..60).
    #[arg(long, default_value_t = 1.0)]
    pub flush_s: f64,
    /// Stop after this many seconds (default: run until SIGTERM/SIGINT).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Store this configuration file (TOML) in the log header, so that `auvnav replay` runs the
    /// log with the daemon's configuration.
    #[arg(long)]
    pub embed_config: Option<PathBuf>,
    /// Rewrite a log whose writer was killed as a complete, indexed log (to --out, or
    /// FILE.recovered.mcap), then exit.
    #[arg(long, value_name = "FILE")]
    pub recover: Option<PathBuf>,
    /// Replace --out if it exists (without it the recorder refuses, exit status 2).
    #[arg(long)]
    pub force: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The recorder would replace an existing file (no `--force`): a usage error, exit status 2.
#[derive(Debug, thiserror::Error)]
#[error("{} exists; give another --out or --force to replace it", .0.display())]
pub struct WouldOverwrite(pub PathBuf);

fn refuse_overwrite(out: &Path, force: bool) -> Result<(), WouldOverwrite> {
    if !force && std::fs::symlink_metadata(out).is_ok() {
        return Err(WouldOverwrite(out.to_path_buf()));
    }
    Ok(())
}

/// Header notes that tie the log's monotonic time stamps to UTC: `clock.utc` (RFC 3339, µs) and
/// `clock.monotonic_ns` read at the same instant (the middle of two monotonic reads around the
/// UTC read; `clock.anchor_uncertainty_ns` is half their distance). A message stamped `t` was
/// taken at `utc + (t - monotonic_ns)`, to the accuracy of the host's clock discipline.
pub fn utc_anchor_notes() -> BTreeMap<String, String> {
    use nix::time::{ClockId, clock_gettime};
    let before = auvnav_shm_schema::clock::monotonic_ns();
    let utc = clock_gettime(ClockId::CLOCK_REALTIME);
    let after = auvnav_shm_schema::clock::monotonic_ns();
    let mut notes = BTreeMap::new();
    let Ok(utc) = utc else {
        return notes;
    };
    let Some(t) = chrono::DateTime::from_timestamp(utc.tv_sec(), utc.tv_nsec() as u32) else {
        return notes;
    };
    notes.insert(
        "clock.utc".into(),
        t.to_rfc3339_opts(chrono::SecondsFormat::Micros, true),
    );
    notes.insert(
        "clock.monotonic_ns".into(),
        (before + after.saturating_sub(before) / 2).to_string(),
    );
    notes.insert(
        "clock.anchor_uncertainty_ns".into(),
        (after.saturating_sub(before) / 2).max(1).to_string(),
    );
    notes
}

/// Per-topic counts of a recording.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TopicCount {
    pub messages: u64,
    /// Messages lost on the bus (sequence gaps seen by the recorder's subscriber).
    pub gaps: u64,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct RecordSummary {
    pub out: String,
    pub messages: u64,
    pub flushes: u64,
    pub seconds: f64,
    pub topics: BTreeMap<String, TopicCount>,
    /// Why recording stopped early (a write error), if it did.
    pub error: Option<String>,
    /// With `--recover`: what was damaged and lost (corrupt chunks, their time spans).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damaged: Option<String>,
}

trait Drain {
    /// Moves every waiting message into the log; returns how many.
    fn drain(&mut self, log: &mut LogWriter<BufWriter<std::fs::File>>) -> Result<u64, LogError>;
    fn topic(&self) -> &str;
    fn gaps(&self) -> u64;
}

struct Channel<T: Message + Sequenced> {
    topic: String,
    sub: BusSubscriber<T>,
}

impl<T: Message + Sequenced> Drain for Channel<T> {
    fn drain(&mut self, log: &mut LogWriter<BufWriter<std::fs::File>>) -> Result<u64, LogError> {
        let mut n = 0;
        // A receive error is a bus fault, not a log fault: it ends this drain and is retried.
        while let Ok(Some(m)) = self.sub.receive() {
            log.write(&self.topic, &m)?;
            n += 1;
        }
        Ok(n)
    }
    fn topic(&self) -> &str {
        &self.topic
    }
    fn gaps(&self) -> u64 {
        self.sub.gaps()
    }
}

fn channel<T: Message + Sequenced + 'static>(
    bus: &Bus,
    name: &str,
    q: qos::ServiceQos,
) -> anyhow::Result<Box<dyn Drain>> {
    Ok(Box::new(Channel {
        topic: name.to_string(),
        sub: bus.subscriber::<T>(name, q)?,
    }))
}

/// The channels of every topic the recorder keeps but raw bytes: the sensors' (aid topics before
/// the IMU, as the daemon takes them), the daemon's outputs, health and truth.
fn channels(bus: &Bus) -> anyhow::Result<Vec<Box<dyn Drain>>> {
    Ok(vec![
        channel::<DvlVelocityV1>(bus, topic::DVL, qos::SENSOR)?,
        channel::<UsblFixV1>(bus, topic::USBL, qos::SENSOR)?,
        channel::<DepthV1>(bus, topic::DEPTH, qos::SENSOR)?,
        channel::<MagnetometerV1>(bus, topic::MAGNETOMETER, qos::SENSOR)?,
        channel::<GnssFixV1>(bus, topic::GNSS, qos::SENSOR)?,
        channel::<SoundVelocityV1>(bus, topic::SOUND_VELOCITY, qos::SENSOR)?,
        channel::<AcousticRangesV1>(bus, topic::ACOUSTIC_RANGES, qos::SENSOR)?,
        channel::<AcousticArrayPoseV1>(bus, topic::ACOUSTIC_ARRAY_POSE, qos::SENSOR)?,
        channel::<ImuSampleV1>(bus, topic::IMU, qos::SENSOR)?,
        channel::<NavSolutionV1>(bus, topic::NAV_SOLUTION, qos::NAVIGATION)?,
        channel::<AidDiagnosticsV1>(bus, topic::NAV_AID_DIAGNOSTICS, qos::NAVIGATION)?,
        channel::<LateAidV1>(bus, topic::NAV_LATE_AIDS, qos::NAVIGATION)?,
        channel::<SessionEventV1>(bus, topic::NAV_SESSION_EVENTS, qos::NAVIGATION)?,
        channel::<ProcessHealthV1>(bus, topic::HEALTH, qos::HEALTH)?,
        channel::<TruthStateV1>(bus, topic::TRUTH, qos::SENSOR)?,
    ])
}

/// An error with its causes ("writing x: MCAP I/O error: File too large (os error 27)").
fn with_causes(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(c) = source {
        s.push_str(": ");
        s.push_str(&c.to_string());
        source = c.source();
    }
    s
}

/// Rewrites the readable part of `path` as a complete log at `out`; returns the messages kept.
pub fn recover(path: &Path, out: &Path) -> anyhow::Result<(u64, Option<String>, Corruption)> {
    let mut reader = LogReader::open(path)?;
    let header = reader
        .read_header()
        .with_context(|| format!("reading the header of {}", path.display()))?;
    let mut stopped = None;
    let mut kept = 0;
    write_log_atomically(out, &header, |w| {
        loop {
            match reader.next_message() {
                Ok(Some(m)) => {
                    w.write_raw(&m)?;
                    kept += 1;
                }
                Ok(None) => break,
                Err(e @ (LogError::Truncated | LogError::Mcap(_))) => {
                    stopped = Some(e.to_string());
                    break;
                }
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    })?;
    Ok((kept, stopped, reader.corruption().clone()))
}

/// Runs `auvnav record`.
// Long on purpose: the recorder's loop: subscriptions, the chunked writer, flushes, signals and the
// summary share the open file's state; recovery and the writer are functions.
pub fn run(a: &RecordArgs) -> anyhow::Result<RecordSummary> {
    if let Some(src) = &a.recover {
        let out = a
            .out
            .clone()
            .unwrap_or_else(|| src.with_extension("recovered.mcap"));
        refuse_overwrite(&out, a.force)?;
        let (kept, stopped, corruption) = recover(src, &out)?;
        let damaged = corruption.any().then(|| corruption.to_string());
        let summary = RecordSummary {
            out: out.display().to_string(),
            messages: kept,
            error: stopped,
            damaged: damaged.clone(),
            ..Default::default()
        };
        print(a.json, &summary);
        if let Some(d) = damaged {
            // Every intact chunk is in the recovered log; what the damaged ones held is gone.
            bail!(
                "{}: damaged, {kept} messages recovered into {}; lost: {d}",
                src.display(),
                summary.out
            );
        }
        if kept == 0 {
            bail!("{}: no message could be recovered", src.display());
        }
        return Ok(summary);
    }
    let Some(out) = &a.out else {
        bail!("--out FILE is required");
    };
    auvnav_shm_schema::logging::init();
    if !(a.flush_s.is_finite() && (0.05..=60.0).contains(&a.flush_s)) {
        bail!("--flush-s {}: expected 0.05..=60 s", a.flush_s);
    }
    let config = match &a.embed_config {
        Some(p) => {
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?
        }
        None => String::new(),
    };
    refuse_overwrite(out, a.force)?;
    let mut header = LogHeader::new("auvnav record", &config);
    header.producer_version = auvnav_version::LONG.to_string();
    header.notes.extend(utc_anchor_notes());
    header
        .notes
        .insert("record.prefix".into(), a.prefix.clone());
    let bus = Bus::new(&format!("record{}", std::process::id()), &a.prefix)?;
    // Aid topics are drained before the IMU in every pass, as the daemon takes them, so the log
    // is close to time order; replay puts messages in their time-stamp order anyway (within a
    // window) and applies aids the daemon took late where its `nav/late_aids` records say.
    let mut channels = channels(&bus)?;
    for r in &a.raw {
        channels.push(channel::<RawBytesV1>(&bus, &topic::raw(r), qos::RAW)?);
    }
    let mut log = LogWriter::create(out, &header)?;
    // A second handle syncs the file's data to the disk after each flush, on its own thread: a
    // sync can take hundreds of milliseconds on a busy disk, while the bus buffers hold a few
    // hundred milliseconds of a fast topic. The latest request is enough (a bounded channel of
    // one: a sync still running covers the next).
    let (sync_tx, sync_rx) = crossbeam::channel::bounded::<()>(1);
    let syncer = std::fs::File::open(out).ok().map(|f| {
        std::thread::spawn(move || {
            while sync_rx.recv().is_ok() {
                let _ = f.sync_data();
            }
            let _ = f.sync_data();
        })
    });
    let start = Instant::now();
    let flush_every = Duration::from_secs_f64(a.flush_s);
    let mut next_flush = start + flush_every;
    let mut summary = RecordSummary {
        out: out.display().to_string(),
        ..Default::default()
    };
    let mut counts = vec![0u64; channels.len()];
    tracing::info!(
        "auvnav record: {} topics under {}/ -> {}",
        channels.len(),
        a.prefix,
        out.display()
    );
    let mut failed: Option<String> = None;
    bus.ready(&format!(
        "recording {} topics to {}",
        channels.len(),
        out.display()
    ));
    'run: loop {
        if bus.termination_requested() {
            break;
        }
        if a.seconds
            .is_some_and(|s| start.elapsed().as_secs_f64() >= s)
        {
            break;
        }
        for (i, c) in channels.iter_mut().enumerate() {
            match c.drain(&mut log) {
                Ok(n) => counts[i] += n,
                Err(e) => {
                    failed = Some(format!("writing {}: {}", out.display(), with_causes(&e)));
                    break 'run;
                }
            }
        }
        if Instant::now() >= next_flush {
            if let Err(e) = log.flush() {
                failed = Some(format!("flushing {}: {}", out.display(), with_causes(&e)));
                break;
            }
            let _ = sync_tx.try_send(());
            summary.flushes += 1;
            next_flush += flush_every;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    if failed.is_none() {
        for (i, c) in channels.iter_mut().enumerate() {
            match c.drain(&mut log) {
                Ok(n) => counts[i] += n,
                Err(e) => failed = Some(format!("writing {}: {}", out.display(), with_causes(&e))),
            }
        }
    }
    summary.seconds = start.elapsed().as_secs_f64();
    for (i, c) in channels.iter().enumerate() {
        summary.topics.insert(
            c.topic().to_string(),
            TopicCount {
                messages: counts[i],
                gaps: c.gaps(),
            },
        );
    }
    summary.messages = counts.iter().sum();
    match failed {
        None => {
            log.finish()
                .with_context(|| format!("finishing {}", out.display()))?;
        }
        Some(e) => {
            // Whatever was flushed stays readable; the unfinished tail is not indexed.
            tracing::error!(
                "auvnav record: {e}; stopped. The log is readable up to its last flush (use \
                 `auvnav record --recover {}` for an indexed copy).",
                out.display()
            );
            summary.error = Some(e);
        }
    }
    drop(sync_tx);
    if let Some(h) = syncer {
        let _ = h.join();
    }
    let lost: u64 = summary.topics.values().map(|t| t.gaps).sum();
    let lossy: Vec<String> = summary
        .topics
        .iter()
        .filter(|(_, t)| t.gaps > 0)
        .map(|(name, t)| format!("{name} {}", t.gaps))
        .collect();
    tracing::info!(
        messages = summary.messages,
        lost,
        "auvnav record: stopping; {} messages in {:.1} s, {lost} lost on the bus{}",
        summary.messages,
        summary.seconds,
        if lossy.is_empty() {
            String::new()
        } else {
            format!(" ({})", lossy.join(", "))
        }
    );
    print(a.json, &summary);
    if summary.error.is_some() {
        bail!(
            "recording stopped: {}",
            summary.error.clone().unwrap_or_default()
        );
    }
    Ok(summary)
}

fn print(json: bool, s: &RecordSummary) {
    if json {
        // The JSON vocabulary's version first (docs/json.md), as every auvnav document has it.
        #[derive(Serialize)]
        struct Versioned<'a> {
            format_version: u32,
            #[serde(flatten)]
            summary: &'a RecordSummary,
        }
        let doc = Versioned {
            format_version: auvnav_version::JSON_FORMAT_VERSION,
            summary: s,
        };
        println!("{}", serde_json::to_string_pretty(&doc).unwrap_or_default());
    } else {
        println!(
            "auvnav record: {} messages in {:.1} s to {} ({} flushes)",
            s.messages, s.seconds, s.out, s.flushes
        );
        for (t, c) in &s.topics {
            if c.messages > 0 || c.gaps > 0 {
                println!("  {t:24} {:>9} messages, {} lost", c.messages, c.gaps);
            }
        }
        if let Some(e) = &s.error {
            println!("  stopped: {e}");
        }
        if let Some(d) = &s.damaged {
            println!("  damaged: {d}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_anchor_is_a_utc_time_and_a_monotonic_time_read_together() {
        let before = auvnav_shm_schema::clock::monotonic_ns();
        let notes = utc_anchor_notes();
        let after = auvnav_shm_schema::clock::monotonic_ns();
        let utc = chrono::DateTime::parse_from_rfc3339(&notes["clock.utc"]).expect("RFC 3339");
        assert_eq!(utc.offset().local_minus_utc(), 0);
        assert!(utc.timestamp() > 1_700_000_000, "{utc}");
        let mono: u64 = notes["clock.monotonic_ns"].parse().expect("integer");
        assert!((before..=after).contains(&mono));
        let half: u64 = notes["clock.anchor_uncertainty_ns"]
            .parse()
            .expect("integer");
        assert!(half >= 1 && half <= after - before);
    }

    /// Every topic that carries sensor data into the daemon is recorded, so that a replay
    /// fuses what the daemon fused.
    #[test]
    fn every_sensor_topic_is_recorded() {
        let bus = Bus::new(&format!("rectest{}", std::process::id()), "recordertest").expect("bus");
        let recorded: Vec<String> = channels(&bus)
            .expect("channels")
            .iter()
            .map(|c| c.topic().to_string())
            .collect();
        for t in topic::SENSOR_TOPICS {
            assert!(recorded.iter().any(|r| r == t), "{t} is not recorded");
        }
    }

    #[test]
    fn an_existing_file_is_kept_unless_forced() {
        let dir = std::env::temp_dir().join(format!("auvnav-overwrite-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let f = dir.join("x.mcap");
        assert!(refuse_overwrite(&f, false).is_ok());
        std::fs::write(&f, b"x").expect("write");
        let e = refuse_overwrite(&f, false).expect_err("exists");
        assert!(e.to_string().contains("--force"), "{e}");
        assert!(refuse_overwrite(&f, true).is_ok());
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
