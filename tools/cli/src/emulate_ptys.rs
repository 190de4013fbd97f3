//! `auvnav emulate`: plays a log's sensor messages into pseudo-terminals in the devices' own
//! protocols, in real time or faster, so that the drivers run against "devices" without hardware.
//!
//! Each emulated device gets a pseudo-terminal pair; the driver opens the slave side. With
//! `--link-dir DIR` a stable symbolic link `DIR/<device>` points at the slave (as udev's
//! `/dev/serial/by-id` links do for real adapters); an unplug closes the pair and a replug creates
//! a new one and moves the link, so a driver configured with the link finds the device again.
//!
//! Faults: `--corrupt P` flips a bit in a byte in the middle of a frame (probability per frame),
//! `--drop P` leaves a frame out, `--garbage P` writes 1–64 random bytes before a frame,
//! `--pause DEVICE,AT,FOR` stops writing (a silent device) and `--unplug DEVICE,AT,FOR` closes the
//! pseudo-terminal (times in seconds of log time from the first message). Every fault is counted
//! in the summary, so a test can check the driver against what was played.
//!
//! Long on purpose: the last 43 lines are the unit tests, beside the code they test; the code is
//! 674 lines, one loop over the log's devices (the line timing is `emulate_line`).

use crate::emulate_line::{Lines, SendRecord};
use anyhow::{Context, bail};
use auvnav_drivers::device::{DeviceClass, Protocol, XSENS_FIELD_UNIT_UT};
use auvnav_drivers::to_device as enc;
use auvnav_drivers::to_schema::KvhConfig;
use auvnav_log::{LogMessage, LogReader};
use auvnav_sim::rng::Rng;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The coordinate system an emulated PD0 DVL records its bottom track in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Pd0Coordinates {
    Instrument,
    Beam,
    Earth,
}

impl Pd0Coordinates {
    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Pd0Coordinates::Instrument => "instrument",
            Pd0Coordinates::Beam => "beam",
            Pd0Coordinates::Earth => "earth",
        }
    }
}

#[derive(Debug, clap::Args)]
pub struct EmulateArgs {
    /// The log to play (MCAP, as written by `auvnav sim` or the recorder).
    pub log: PathBuf,
    /// Emulate the DVL in this protocol (pd0, wldvl or nortek).
    #[arg(long, value_parser = ["pd0", "wldvl", "nortek"])]
    pub dvl: Option<String>,
    /// The coordinate system of an emulated PD0 DVL's bottom track: instrument (x, y, z and
    /// error velocity), beam (the four radial velocities) or earth (east, north, up, rotated
    /// with the attitude the ensemble records: the log's truth, else its navigation solution).
    #[arg(long, value_enum, default_value_t = Pd0Coordinates::Instrument)]
    pub pd0_coordinates: Pd0Coordinates,
    /// Emulate the IMU in this protocol (kvh1750 or xsens).
    #[arg(long, value_parser = ["kvh1750", "xsens"])]
    pub imu: Option<String>,
    /// Emulate the USBL in this protocol (seatrac).
    #[arg(long, value_parser = ["seatrac"])]
    pub usbl: Option<String>,
    /// Also play the log's acoustic ranges (an LBL survey, `auvnav sim --scenario ranges_lbl`)
    /// through the emulated SeaTrac, as ping responses from these beacon IDs: receiver k's range
    /// from beacon k of the list (comma-separated; with `--usbl seatrac`; the driver's
    /// `[settings.seatrac] range_beacons`).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u8).range(1..=15))]
    pub lbl_beacons: Vec<u8>,
    /// Emulate the GNSS receiver in this protocol (nmea or ubx): the log's fixes, stamped with
    /// the UTC at which they are written, as a live receiver's.
    #[arg(long, value_parser = ["nmea", "ubx"])]
    pub gnss: Option<String>,
    /// Play this many times faster than real time (0.01..1000).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Pace every device's bytes at this line rate (bit/s, 8N1): a frame takes its length in
    /// characters on the line, waits while the line is busy, and reaches the terminal in pieces of
    /// about 1 ms as its bytes arrive. Without it a frame is written whole when due.
    #[arg(long, value_parser = clap::value_parser!(u32).range(50..=4_000_000))]
    pub baud: Option<u32>,
    /// Deliver each piece up to this much later than its bytes arrived, at random, in order (a
    /// USB adapter's latency timer, a busy host) (ms, 0..100).
    #[arg(long, default_value_t = 0.0)]
    pub jitter_ms: f64,
    /// Write when each frame's first byte was on the line, when its first piece was due (its
    /// bytes arrived) and when it was written to the terminal (CSV:
    /// device,kind,index,line_ns,due_ns,written_ns; CLOCK_MONOTONIC ns), to measure a driver's
    /// time stamps against.
    #[arg(long, value_name = "FILE")]
    pub send_times: Option<PathBuf>,
    /// Keep stable links DIR/dvl, DIR/imu, DIR/usbl, DIR/gnss to the pseudo-terminals (needed by
    /// --unplug).
    #[arg(long)]
    pub link_dir: Option<PathBuf>,
    /// Wait this long after creating the terminals before playing, so drivers can open them (s).
    #[arg(long, default_value_t = 1.0)]
    pub start_delay: f64,
    /// Play only this many seconds of the log.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Probability per frame of one corrupted byte.
    #[arg(long, default_value_t = 0.0)]
    pub corrupt: f64,
    /// Probability per frame of leaving the frame out.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Probability per frame of 1–64 random bytes written before it.
    #[arg(long, default_value_t = 0.0)]
    pub garbage: f64,
    /// DEVICE,AT,FOR: the device goes silent at AT s for FOR s (repeatable).
    #[arg(long, value_name = "DEVICE,AT,FOR", value_parser = window_spec)]
    pub pause: Vec<String>,
    /// DEVICE,AT,FOR: the device's pseudo-terminal is closed at AT s and a new one appears FOR s
    /// later (repeatable; needs --link-dir).
    #[arg(long, value_name = "DEVICE,AT,FOR", value_parser = window_spec)]
    pub unplug: Vec<String>,
    /// Seed of the fault injection.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output as JSON lines (terminals, events, summary) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// What was played into one device.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct DeviceSummary {
    pub device: String,
    pub protocol: String,
    /// Messages of the log the device sends (within the played duration): its class's, and the
    /// magnetometer's for an IMU that carries the field (Xsens, in units of the drivers' default
    /// `settings.xsens_field_unit_ut`).
    pub messages: u64,
    /// Frames sent intact (with `--baud`, onto the line: written in pieces as they arrive; a
    /// piece the terminal refuses counts its frame in `blocked` too).
    pub written: u64,
    /// Frames written with a corrupted byte.
    pub corrupted: u64,
    /// Frames left out by --drop.
    pub dropped: u64,
    /// Frames not written while paused.
    pub paused: u64,
    /// Frames not written while unplugged.
    pub unplugged: u64,
    /// Frames (whole or partly) not accepted by the terminal within 1 s (reader not keeping up).
    pub blocked: u64,
    /// Random bytes written between frames.
    pub garbage_bytes: u64,
    /// Bytes written in total.
    pub bytes: u64,
    /// DVL water-track velocities of the log not played: the emulated protocols' bottom-track
    /// records cannot carry them, and played as bottom track they would be a wrong velocity over
    /// the ground.
    pub water_track_skipped: u64,
    /// DVL readings not sent in PD0 earth coordinates because the log had given no attitude yet.
    pub no_attitude: u64,
}

#[derive(Debug, Clone, Copy)]
struct Window {
    at_s: f64,
    for_s: f64,
}

impl Window {
    fn contains(&self, t: f64) -> bool {
        t >= self.at_s && t < self.at_s + self.for_s
    }
}

/// clap value parser of `--pause` and `--unplug`.
fn window_spec(s: &str) -> Result<String, String> {
    // The messages start "--OPTION SPEC: "; clap names the option and the value itself.
    parse_window(s, "").map(|_| s.to_string()).map_err(|e| {
        let m = e.to_string();
        m.split_once(": ")
            .map_or(m.clone(), |(_, rest)| rest.to_string())
    })
}

fn parse_window(spec: &str, option: &str) -> anyhow::Result<(DeviceClass, Window)> {
    let parts: Vec<&str> = spec.split(',').collect();
    let [dev, at, dur] = parts[..] else {
        bail!("--{option} {spec:?}: expected DEVICE,AT,FOR (e.g. dvl,10,3)");
    };
    let class = match dev {
        "dvl" => DeviceClass::Dvl,
        "imu" => DeviceClass::Imu,
        "usbl" => DeviceClass::Usbl,
        "gnss" => DeviceClass::Gnss,
        _ => bail!("--{option} {spec:?}: device must be dvl, imu, usbl or gnss"),
    };
    let num = |s: &str, what: &str| -> anyhow::Result<f64> {
        let v: f64 = s
            .parse()
            .with_context(|| format!("--{option} {spec:?}: {what} {s:?} is not a number"))?;
        if !(v.is_finite() && v >= 0.0) {
            bail!("--{option} {spec:?}: {what} must be >= 0 s");
        }
        Ok(v)
    };
    Ok((
        class,
        Window {
            at_s: num(at, "AT")?,
            for_s: num(dur, "FOR")?,
        },
    ))
}

/// One emulated device: its pseudo-terminal, encoder state and fault schedule.
struct Device {
    class: DeviceClass,
    protocol: Protocol,
    master: Option<serialport::TTYPort>,
    // The slave stays open here so that the terminal exists while no driver has it open.
    slave: Option<serialport::TTYPort>,
    link: Option<PathBuf>,
    pauses: Vec<Window>,
    unplugs: Vec<Window>,
    counter: u32,
    kvh: KvhConfig,
    pd0_coordinates: Pd0Coordinates,
    /// The latest attitude in the log (roll, pitch, yaw, rad): truth, else the navigation
    /// solution's, for a PD0 DVL in earth coordinates.
    attitude: Option<[f64; 3]>,
    /// A SeaTrac's LBL beacons: receiver k's range is sent from beacon k.
    lbl_beacons: Vec<u8>,
    summary: DeviceSummary,
}

impl Device {
    fn plug(&mut self) -> anyhow::Result<String> {
        let (master, slave, path) = open_terminal(self.link.as_deref())?;
        self.master = Some(master);
        self.slave = Some(slave);
        Ok(path)
    }

    fn unplug(&mut self) {
        self.master = None;
        self.slave = None;
    }

    fn encode(&mut self, m: &LogMessage) -> Option<Vec<u8>> {
        if let LogMessage::Dvl(d) = m
            && d.is_water_track()
        {
            self.summary.water_track_skipped += 1;
            return None;
        }
        let bytes = match (self.protocol, m) {
            (Protocol::Pd0, LogMessage::Dvl(d)) => match self.pd0_coordinates {
                Pd0Coordinates::Instrument => enc::pd0_from_dvl(d, self.counter),
                Pd0Coordinates::Beam => enc::pd0_beam_from_dvl(d, self.counter),
                Pd0Coordinates::Earth => {
                    let Some(euler) = self.attitude else {
                        self.summary.no_attitude += 1;
                        return None;
                    };
                    enc::pd0_earth_from_dvl(d, self.counter, euler)
                }
            },
            (Protocol::Wldvl, LogMessage::Dvl(d)) => enc::wrz_from_dvl(d, 0.0),
            (Protocol::Nortek, LogMessage::Dvl(d)) => enc::nortek_from_dvl(d),
            (Protocol::Kvh1750, LogMessage::Imu(s)) => {
                let mut cfg = self.kvh;
                cfg.increments = s.status & auvnav_shm_schema::ImuSampleV1::STATUS_INCREMENTS != 0;
                enc::kvh_from_imu(s, &cfg, (self.counter % 128) as u8)
            }
            (Protocol::Xsens, LogMessage::Imu(s)) => {
                enc::xsens_from_imu(s, (self.counter % 65_536) as u16)
            }
            (Protocol::Xsens, LogMessage::Magnetometer(m)) => {
                enc::xsens_from_magnetometer(m, XSENS_FIELD_UNIT_UT, (self.counter % 65_536) as u16)
            }
            (Protocol::Seatrac, LogMessage::Usbl(u)) => enc::seatrac_from_usbl(u, 1),
            (Protocol::Seatrac, LogMessage::AcousticRanges(r)) => {
                let b = enc::seatrac_pings_from_ranges(r, &self.lbl_beacons, 1);
                if b.is_empty() {
                    return None;
                }
                b
            }
            (Protocol::Nmea, LogMessage::Gnss(f)) => enc::nmea_from_gnss(f, utc_now_ns()),
            (Protocol::Ubx, LogMessage::Gnss(f)) => enc::ubx_from_gnss(f, utc_now_ns()),
            _ => return None,
        };
        self.counter = self.counter.wrapping_add(1);
        Some(bytes)
    }
}

/// The wall clock's UTC (ns since 1970).
fn utc_now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

/// Line printed for each terminal (and again after a replug).
#[derive(Serialize)]
struct TerminalLine<'a> {
    /// The JSON vocabulary's version (docs/json.md).
    format_version: u32,
    event: &'a str,
    device: &'a str,
    protocol: &'a str,
    path: &'a str,
    link: Option<String>,
    at_s: f64,
}

fn say(json: bool, line: &TerminalLine) {
    if json {
        println!("{}", serde_json::to_string(line).unwrap_or_default());
    } else {
        println!(
            "{} {} ({}): {}{}",
            line.event,
            line.device,
            line.protocol,
            line.path,
            line.link
                .as_ref()
                .map(|l| format!(" (link {l})"))
                .unwrap_or_default()
        );
    }
    let _ = std::io::stdout().flush();
}

fn protocol_for(class: DeviceClass, name: &Option<String>) -> anyhow::Result<Option<Protocol>> {
    let Some(name) = name else { return Ok(None) };
    match Protocol::from_name(name) {
        Some(p) if p.class() == class => Ok(Some(p)),
        _ => {
            let allowed: Vec<_> = Protocol::ALL
                .iter()
                .filter(|p| p.class() == class)
                .map(|p| p.name())
                .collect();
            bail!(
                "--{} {name:?}: expected {}",
                class.name(),
                allowed.join(" or ")
            )
        }
    }
}

/// A new pseudo-terminal pair for an emulated device: the master (written, with a one-second
/// write timeout), the slave (kept open so that the terminal exists while no driver has it) and
/// the slave's path. With `link`, a symbolic link there points at the slave, replaced atomically
/// (a driver never sees it missing or half-written), as udev's `/dev/serial/by-id` links do.
pub fn open_terminal(
    link: Option<&Path>,
) -> anyhow::Result<(serialport::TTYPort, serialport::TTYPort, String)> {
    use serialport::SerialPort;
    let (mut master, slave) =
        serialport::TTYPort::pair().context("creating a pseudo-terminal pair")?;
    let path = slave
        .name()
        .context("the pseudo-terminal has no slave path")?;
    master
        .set_timeout(Duration::from_secs(1))
        .context("setting the terminal's write timeout")?;
    if let Some(link) = link {
        let tmp = link.with_extension("new");
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(&path, &tmp)
            .with_context(|| format!("linking {} to {path}", tmp.display()))?;
        std::fs::rename(&tmp, link)
            .with_context(|| format!("moving the link to {}", link.display()))?;
    }
    Ok((master, slave, path))
}

/// Runs the emulator; returns the per-device summary (also printed).
// Long on purpose: the emulator's one loop over every device of the log: pseudo-terminals, pacing,
// per-device encoders and counts share its state.
pub fn run(a: &EmulateArgs) -> anyhow::Result<Vec<DeviceSummary>> {
    if !(a.speed.is_finite() && (0.01..=1000.0).contains(&a.speed)) {
        bail!("--speed {}: expected 0.01..=1000", a.speed);
    }
    for (name, p) in [
        ("corrupt", a.corrupt),
        ("drop", a.drop),
        ("garbage", a.garbage),
    ] {
        if !(0.0..=1.0).contains(&p) {
            bail!("--{name} {p}: expected a probability 0..=1");
        }
    }
    if !(a.jitter_ms.is_finite() && (0.0..=100.0).contains(&a.jitter_ms)) {
        bail!("--jitter-ms {}: expected 0..=100 ms", a.jitter_ms);
    }
    if !(a.start_delay.is_finite() && (0.0..=600.0).contains(&a.start_delay)) {
        bail!("--start-delay {}: expected 0..=600 s", a.start_delay);
    }
    let mut devices = Vec::new();
    for (class, name) in [
        (DeviceClass::Dvl, &a.dvl),
        (DeviceClass::Imu, &a.imu),
        (DeviceClass::Usbl, &a.usbl),
        (DeviceClass::Gnss, &a.gnss),
    ] {
        if let Some(protocol) = protocol_for(class, name)? {
            devices.push(Device {
                class,
                protocol,
                master: None,
                slave: None,
                link: a.link_dir.as_ref().map(|d| d.join(class.name())),
                pauses: Vec::new(),
                unplugs: Vec::new(),
                counter: 0,
                kvh: KvhConfig {
                    increments: false,
                    degrees: false,
                    rate_hz: 0.0,
                    temperature_centi: false,
                },
                pd0_coordinates: a.pd0_coordinates,
                attitude: None,
                lbl_beacons: a.lbl_beacons.clone(),
                summary: DeviceSummary {
                    device: class.name().to_string(),
                    protocol: protocol.name().to_string(),
                    ..Default::default()
                },
            });
        }
    }
    if devices.is_empty() {
        bail!("nothing to emulate: give at least one of --dvl, --imu, --usbl, --gnss");
    }
    if !a.lbl_beacons.is_empty() && a.usbl.as_deref() != Some("seatrac") {
        bail!("--lbl-beacons needs --usbl seatrac");
    }
    if a.lbl_beacons.len() > 4 {
        bail!("--lbl-beacons: {} beacons; at most 4", a.lbl_beacons.len());
    }
    for (specs, option) in [(&a.pause, "pause"), (&a.unplug, "unplug")] {
        for spec in specs {
            let (class, w) = parse_window(spec, option)?;
            let Some(d) = devices.iter_mut().find(|d| d.class == class) else {
                bail!("--{option} {spec:?}: {} is not emulated", class.name());
            };
            if option == "pause" {
                d.pauses.push(w);
            } else {
                d.unplugs.push(w);
            }
        }
    }
    if devices.iter().any(|d| !d.unplugs.is_empty()) && a.link_dir.is_none() {
        bail!("--unplug needs --link-dir: a replugged device gets a new terminal path");
    }
    if let Some(dir) = &a.link_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut reader = LogReader::open(&a.log)?;
    // Pairs are created one at a time (serialport's pair() is not thread-safe).
    for d in &mut devices {
        let path = d.plug()?;
        say(
            a.json,
            &TerminalLine {
                format_version: auvnav_version::JSON_FORMAT_VERSION,
                event: "terminal",
                device: d.class.name(),
                protocol: d.protocol.name(),
                path: &path,
                link: d.link.as_ref().map(|l| l.display().to_string()),
                at_s: 0.0,
            },
        );
    }
    std::thread::sleep(Duration::from_secs_f64(a.start_delay));
    let mut rng = Rng::new(a.seed, "emulate");
    let mut lines = Lines::new(
        devices.len(),
        a.baud,
        a.jitter_ms,
        a.send_times.as_deref(),
        a.seed,
    )?;
    let mut kind_counts: std::collections::HashMap<&'static str, u64> = Default::default();
    // The frame of each device whose piece the terminal last refused (counted once per frame).
    let mut refused: Vec<Option<u64>> = vec![None; devices.len()];
    let start_ns = auvnav_drivers::clock::monotonic_ns();
    let mut first_ns: Option<u64> = None;
    let mut truth_seen = false;
    while let Some(raw) = reader.next_message().context("reading the log")? {
        let m = raw.decode_any().context("decoding a log message")?;
        // The attitude an earth-coordinate PD0 DVL records: the truth's, else the solution's.
        let attitude = match &m {
            LogMessage::Truth(t) => {
                truth_seen = true;
                Some(t.euler_rad)
            }
            LogMessage::NavSolution(s) if !truth_seen => Some(s.euler_rad),
            _ => None,
        };
        if attitude.is_some() {
            for d in &mut devices {
                d.attitude = attitude;
            }
        }
        let (class, kind, host_ns) = match &m {
            LogMessage::Imu(s) => (DeviceClass::Imu, "imu", s.host_time_ns),
            LogMessage::Dvl(s) => (DeviceClass::Dvl, "dvl", s.host_time_ns),
            LogMessage::Usbl(s) => (DeviceClass::Usbl, "usbl", s.host_time_ns),
            LogMessage::AcousticRanges(s) if !a.lbl_beacons.is_empty() => {
                (DeviceClass::Usbl, "ranges", s.host_time_ns)
            }
            LogMessage::Gnss(s) => (DeviceClass::Gnss, "gnss", s.host_time_ns),
            // An IMU that carries the magnetic field (Xsens) sends it in its own packets.
            LogMessage::Magnetometer(s) => (DeviceClass::Imu, "mag", s.host_time_ns),
            _ => continue,
        };
        let Some(device) = devices.iter().position(|d| d.class == class) else {
            continue;
        };
        let t0 = *first_ns.get_or_insert(host_ns);
        let t = host_ns.saturating_sub(t0) as f64 * 1e-9;
        if a.duration.is_some_and(|dur| t > dur) {
            break;
        }
        // Everything due on the lines before this frame goes out first.
        let due_ns = start_ns + (t / a.speed * 1e9).round() as u64;
        deliver(&mut lines, Some(due_ns), &mut devices, &mut refused)?;
        let d = &mut devices[device];
        // Unplug and replug at the window edges.
        let unplugged = d.unplugs.iter().any(|w| w.contains(t));
        if unplugged && d.master.is_some() {
            d.unplug();
            say(
                a.json,
                &TerminalLine {
                    format_version: auvnav_version::JSON_FORMAT_VERSION,
                    event: "unplugged",
                    device: d.class.name(),
                    protocol: d.protocol.name(),
                    path: "",
                    link: d.link.as_ref().map(|l| l.display().to_string()),
                    at_s: t,
                },
            );
        } else if !unplugged && d.master.is_none() {
            let path = d.plug()?;
            say(
                a.json,
                &TerminalLine {
                    format_version: auvnav_version::JSON_FORMAT_VERSION,
                    event: "replugged",
                    device: d.class.name(),
                    protocol: d.protocol.name(),
                    path: &path,
                    link: d.link.as_ref().map(|l| l.display().to_string()),
                    at_s: t,
                },
            );
        }
        let Some(mut bytes) = d.encode(&m) else {
            continue;
        };
        d.summary.messages += 1;
        if unplugged {
            d.summary.unplugged += 1;
            continue;
        }
        if d.pauses.iter().any(|w| w.contains(t)) {
            d.summary.paused += 1;
            continue;
        }
        if rng.uniform() < a.drop {
            d.summary.dropped += 1;
            continue;
        }
        let mut out = Vec::with_capacity(bytes.len() + 64);
        if rng.uniform() < a.garbage {
            let n = 1 + (rng.next_u64() % 64) as usize;
            out.extend((0..n).map(|_| rng.next_u64() as u8));
            d.summary.garbage_bytes += n as u64;
        }
        let corrupt = rng.uniform() < a.corrupt;
        if corrupt {
            // A byte in the middle third: never the sync bytes, length fields or line end, so
            // exactly this frame is lost. XOR 1 keeps ASCII printable and never makes CR/LF.
            let i = bytes.len() / 3 + (rng.next_u64() as usize) % (bytes.len() / 3).max(1);
            bytes[i] ^= 0x01;
        }
        out.extend_from_slice(&bytes);
        if d.master.is_none() {
            continue;
        }
        if corrupt {
            d.summary.corrupted += 1;
        } else {
            d.summary.written += 1;
        }
        let index = kind_counts.entry(kind).or_default();
        let record = SendRecord {
            device: class.name(),
            kind,
            index: *index,
            line_ns: due_ns,
        };
        *index += 1;
        lines.send(device, due_ns, out, record);
    }
    deliver(&mut lines, None, &mut devices, &mut refused)?;
    lines.finish()?;
    let summaries: Vec<DeviceSummary> = devices.iter().map(|d| d.summary.clone()).collect();
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "format_version": auvnav_version::JSON_FORMAT_VERSION, "event": "summary", "devices": summaries })
        );
    } else {
        for s in &summaries {
            println!(
                "{} ({}): {} messages, {} written, {} corrupted, {} dropped, {} paused, {} unplugged, {} blocked, {} garbage bytes{}",
                s.device,
                s.protocol,
                s.messages,
                s.written,
                s.corrupted,
                s.dropped,
                s.paused,
                s.unplugged,
                s.blocked,
                s.garbage_bytes,
                if s.water_track_skipped > 0 {
                    format!(
                        ", {} water-track velocities not played (no such record in the protocol)",
                        s.water_track_skipped
                    )
                } else {
                    String::new()
                } + &if s.no_attitude > 0 {
                    format!(
                        ", {} DVL readings not played before the log gave an attitude (PD0 earth coordinates)",
                        s.no_attitude
                    )
                } else {
                    String::new()
                }
            );
        }
    }
    // Give the drivers time to read the last bytes before the terminals close.
    std::thread::sleep(Duration::from_millis(300));
    if let Some(dir) = &a.link_dir {
        for d in &devices {
            if let Some(l) = &d.link {
                let _ = std::fs::remove_file(l);
            }
        }
        let _ = std::fs::remove_dir(dir);
    }
    Ok(summaries)
}

/// Writes the pieces due by `until_ns` (all with `None`) into the devices' terminals, counting the
/// bytes taken and the frames of which a piece was refused.
fn deliver(
    lines: &mut Lines,
    until_ns: Option<u64>,
    devices: &mut [Device],
    refused: &mut [Option<u64>],
) -> anyhow::Result<()> {
    lines.deliver(until_ns, |device, frame, bytes| {
        let d = &mut devices[device];
        let ok = d
            .master
            .as_mut()
            .is_some_and(|m| m.write_all(bytes).is_ok());
        if ok {
            d.summary.bytes += bytes.len() as u64;
        } else if refused[device] != Some(frame) {
            refused[device] = Some(frame);
            d.summary.blocked += 1;
        }
        ok
    })
}

/// Used by tests: the link path of a device under a link directory.
pub fn link_path(dir: &Path, class: DeviceClass) -> PathBuf {
    dir.join(class.name())
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_shm_schema::DvlVelocityV1;

    #[test]
    fn water_track_is_never_played_as_bottom_track() {
        let mut d = Device {
            class: DeviceClass::Dvl,
            protocol: Protocol::Pd0,
            master: None,
            slave: None,
            link: None,
            pauses: Vec::new(),
            unplugs: Vec::new(),
            counter: 0,
            kvh: KvhConfig {
                increments: false,
                degrees: false,
                rate_hz: 0.0,
                temperature_centi: false,
            },
            pd0_coordinates: Pd0Coordinates::Instrument,
            attitude: None,
            lbl_beacons: Vec::new(),
            summary: DeviceSummary::default(),
        };
        let bottom = DvlVelocityV1 {
            velocity_dvl_m_s: [1.0, 0.0, 0.0],
            validity: DvlVelocityV1::VALID_VELOCITY,
            ..Default::default()
        };
        let water = DvlVelocityV1 {
            validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::TRACK_WATER,
            ..bottom
        };
        for p in [Protocol::Pd0, Protocol::Wldvl, Protocol::Nortek] {
            d.protocol = p;
            assert!(d.encode(&LogMessage::Dvl(bottom)).is_some(), "{p:?}");
            assert!(d.encode(&LogMessage::Dvl(water)).is_none(), "{p:?}");
        }
        assert_eq!(d.summary.water_track_skipped, 3);
    }
}
