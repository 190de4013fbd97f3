//! A MAVLink telemetry log (`.tlog`, as pymavlink, QGroundControl and BlueOS write it): records of
//! an 8-byte big-endian Unix time in microseconds (when the ground station received the frame)
//! followed by one MAVLink 1 or 2 frame.
//!
//! What an ArduSub vehicle's telemetry carries of its sensors becomes auvnav's channels:
//! `SCALED_IMU` (else the first IMU's `RAW_IMU`, which ArduPilot sends in the same units) as the
//! IMU and magnetometer, `SCALED_PRESSURE2` (ArduSub's external pressure sensor; another instance
//! with `--pressure-instance`) as depth, `ATTITUDE` (the autopilot's own estimate) as the attitude
//! channel, `GPS_RAW_INT` as GNSS fixes and `VISION_POSITION_DELTA` (a DVL extension's) as DVL
//! velocities. Messages stamped by the autopilot's clock
//! (`time_boot_ms`, `time_usec` since boot) keep that clock as their device time and are placed
//! on the receive time base by the smallest receive delay seen (per boot of the autopilot), so
//! their spacing is the autopilot's, not the telemetry link's.

#[allow(unused_imports)]
use super::*;
use auvnav_protocols::autopilot::{AutopilotConversion, AutopilotReading, Converted, ImuMessage};
use auvnav_shm_schema::MagnetometerV1;
use frames::{Frame, frames};
use mavlink::Message;
use mavlink::dialects::ardupilotmega::MavMessage;

mod frames;
#[cfg(test)]
mod tests;

/// The autopilot's clock going back by more than this starts a new boot of the autopilot (s).
const CLOCK_RESET_S: f64 = 1.0;
/// A receive delay longer by more than this than the previous one also starts a new boot (a
/// reboot during a gap in the telemetry); shorter jumps are the link's and keep the boot (s).
const DELAY_JUMP_S: f64 = 10.0;
/// A record whose receive time is this far from both neighbours, which agree, has a damaged
/// time stamp (s).
const STAMP_JUMP_S: f64 = 3600.0;

/// Command-line arguments of `auvnav import tlog`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct TlogOptions {
    /// The MAVLink telemetry log (`.tlog`).
    pub input: PathBuf,
    /// Output log (written atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    /// Which SCALED_PRESSURE message is the water pressure sensor: 1 (SCALED_PRESSURE), 2
    /// (SCALED_PRESSURE2: ArduSub's external sensor) or 3.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 2))]
    pub pressure_instance: u8,
    /// Water density for depth from pressure (kg/m³; ArduSub's default is fresh water, 1000).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1025.0))]
    pub water_density: f64,
    /// Absolute pressure at the surface (hPa); by default the sensor's first reading, as ArduSub
    /// takes it at boot.
    #[cfg_attr(feature = "clap", arg(long))]
    pub surface_pressure_hpa: Option<f64>,
    /// Print the summary as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

impl TlogOptions {
    /// The options with their command-line defaults, for `input` and `out`.
    pub fn new(input: PathBuf, out: PathBuf) -> TlogOptions {
        TlogOptions {
            input,
            out,
            pressure_instance: 2,
            water_density: 1025.0,
            surface_pressure_hpa: None,
            json: false,
        }
    }
}

/// What `auvnav import tlog` read and wrote.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TlogSummary {
    pub file: String,
    /// MAVLink frames read (any message).
    pub frames: usize,
    /// Frames read, by message name (those the import knows).
    pub by_message: BTreeMap<String, usize>,
    /// Frames whose checksum did not match (left out).
    pub bad_checksum: usize,
    /// Frames of a message the dialect does not know, or whose payload did not parse.
    pub unknown: usize,
    /// Bytes skipped to find the next record (damage, a truncated end).
    pub bytes_skipped: usize,
    /// Messages left out for a value that is not finite or out of range.
    pub implausible: usize,
    /// Left out for their time: readings at or before the previous one of their channel (a
    /// repeated frame, a clock going back within a boot), and records whose receive time stands
    /// an hour away from both neighbours (a damaged time stamp).
    pub out_of_order: usize,
    /// Boots of the autopilot seen (its clock started again).
    pub autopilot_boots: usize,
    /// The IMU message used: "SCALED_IMU", "RAW_IMU", or empty.
    pub imu_source: String,
    pub imu: usize,
    pub magnetometer: usize,
    pub depth: usize,
    pub attitude: usize,
    pub gnss: usize,
    /// DVL velocities (VISION_POSITION_DELTA).
    pub dvl: usize,
    /// GPS_RAW_INT messages without a 3D fix (left out).
    pub gnss_without_fix: usize,
    /// The surface pressure depth was taken against (hPa).
    pub surface_pressure_hpa: f64,
    pub duration_s: f64,
    /// Unix time of the first record (s).
    pub start_unix_s: f64,
}

/// A sensor reading before its time is placed: receive time, the autopilot's clock (if the
/// message carries it) and the message with its host time still 0.
struct Reading {
    received_ns: u64,
    /// The host time given by [`place`].
    host_ns: u64,
    device_ns: Option<u64>,
    message: AutopilotReading,
}

/// The readings of the frames, by the options; counts into `s`.
fn readings(frames: &[Frame], o: &TlogOptions, s: &mut TlogSummary) -> Vec<Reading> {
    let t0_us = frames.first().map_or(0, |f| f.received_us);
    let scaled_imu = frames
        .iter()
        .any(|f| matches!(f.message, MavMessage::SCALED_IMU(_)));
    s.imu_source = if scaled_imu { "SCALED_IMU" } else { "RAW_IMU" }.into();
    let mut conversion = AutopilotConversion {
        imu: if scaled_imu {
            ImuMessage::ScaledImu
        } else {
            ImuMessage::RawImu
        },
        pressure_instance: o.pressure_instance,
        water_density_kg_m3: o.water_density,
        surface_pressure_hpa: o.surface_pressure_hpa,
    };
    let mut out = Vec::new();
    for f in frames {
        *s.by_message
            .entry(f.message.message_name().to_string())
            .or_default() += 1;
        let received_ns = f.received_us.saturating_sub(t0_us).saturating_mul(1000);
        match conversion.convert(&f.message) {
            Converted::Readings {
                device_ns,
                readings,
            } => out.extend(readings.into_iter().map(|message| Reading {
                received_ns,
                host_ns: 0,
                device_ns,
                message,
            })),
            Converted::Implausible => s.implausible += 1,
            Converted::NoFix => s.gnss_without_fix += 1,
            Converted::NotTaken => {}
        }
    }
    s.surface_pressure_hpa = conversion.surface_pressure_hpa.unwrap_or(f64::NAN);
    out
}

/// Host times: a reading with the autopilot's clock at that clock plus the smallest receive delay
/// of its boot; the others at their receive time. Sorted by host time, with the sequence numbers,
/// the IMU intervals, and the counts and duration in `s`.
fn place(mut readings: Vec<Reading>, s: &mut TlogSummary) -> Vec<(&'static str, LogMessage)> {
    // Boots: the autopilot's clock going back by CLOCK_RESET_S, or the receive delay jumping by
    // DELAY_JUMP_S, starts a new one.
    let reset_ns = (CLOCK_RESET_S * 1e9) as i128;
    let jump_ns = (DELAY_JUMP_S * 1e9) as i128;
    let mut boot = vec![0usize; readings.len()];
    let mut offsets: Vec<i128> = Vec::new();
    let mut last: Option<(u64, i128)> = None;
    for (i, r) in readings.iter().enumerate() {
        let Some(dev) = r.device_ns else { continue };
        let delay = i128::from(r.received_ns) - i128::from(dev);
        let new_boot = match last {
            None => true,
            Some((prev_dev, prev_delay)) => {
                (dev as i128) < prev_dev as i128 - reset_ns || (delay - prev_delay).abs() > jump_ns
            }
        };
        if new_boot {
            offsets.push(delay);
        }
        let b = offsets.len() - 1;
        offsets[b] = offsets[b].min(delay);
        boot[i] = b;
        last = Some((dev, delay));
    }
    s.autopilot_boots = offsets.len();
    for (r, b) in readings.iter_mut().zip(&boot) {
        r.host_ns = match r.device_ns {
            Some(dev) => (i128::from(dev) + offsets[*b]).max(0) as u64,
            None => r.received_ns,
        };
    }
    readings.sort_by_key(|r| r.host_ns);
    // Two readings of one channel at the same time (a repeated frame) or going back: left out.
    // The rest are counted by kind, and each IMU sample's interval is the time since the
    // previous one (the first takes the second's).
    let mut last: BTreeMap<&'static str, (u64, u64)> = BTreeMap::new();
    let (mut first_imu, mut last_imu_ns, mut first_ns) = (None, None, None);
    let mut out = Vec::with_capacity(readings.len());
    for mut r in readings {
        let (t, topic) = (r.host_ns, r.message.topic());
        let (last_ns, sequence) = last.get(topic).copied().unwrap_or((0, 0));
        if sequence > 0 && t <= last_ns {
            s.out_of_order += 1;
            continue;
        }
        last.insert(topic, (t, sequence + 1));
        r.message.set_times(t, r.device_ns, sequence);
        match &mut r.message {
            AutopilotReading::Imu(x) => {
                s.imu += 1;
                match last_imu_ns {
                    Some(p) => {
                        x.interval_s = (t - p) as f64 * 1e-9;
                        if let Some((_, LogMessage::Imu(y))) =
                            first_imu.take().and_then(|f: usize| out.get_mut(f))
                        {
                            y.interval_s = x.interval_s;
                        }
                    }
                    None => first_imu = Some(out.len()),
                }
                last_imu_ns = Some(t);
            }
            AutopilotReading::Magnetometer(_) => s.magnetometer += 1,
            AutopilotReading::Depth(_) => s.depth += 1,
            AutopilotReading::Attitude(_) => s.attitude += 1,
            AutopilotReading::Gnss(_) => s.gnss += 1,
            AutopilotReading::Dvl(_) => s.dvl += 1,
        }
        // Sorted by host time: the duration runs from the first kept reading to this one.
        let first = *first_ns.get_or_insert(t);
        s.duration_s = (t - first) as f64 * 1e-9;
        out.push((topic, log_message(r.message)));
    }
    out
}

/// The log's message of a reading.
fn log_message(r: AutopilotReading) -> LogMessage {
    match r {
        AutopilotReading::Imu(x) => LogMessage::Imu(x),
        AutopilotReading::Magnetometer(x) => LogMessage::Magnetometer(x),
        AutopilotReading::Depth(x) => LogMessage::Depth(x),
        AutopilotReading::Attitude(x) => LogMessage::Attitude(x),
        AutopilotReading::Gnss(x) => LogMessage::Gnss(x),
        AutopilotReading::Dvl(x) => LogMessage::Dvl(x),
    }
}

/// The messages of a tlog (time 0 = its first record) and the summary.
pub fn tlog_messages(o: &TlogOptions) -> Result<(Vec<(&'static str, LogMessage)>, TlogSummary)> {
    if !(1..=3).contains(&o.pressure_instance) {
        bad_option!("--pressure-instance {}: 1, 2 or 3", o.pressure_instance);
    }
    if !(990.0..=1050.0).contains(&o.water_density) {
        bad_option!("--water-density {}: 990..1050 kg/m³", o.water_density);
    }
    let bytes =
        std::fs::read(&o.input).read_context(|| format!("reading {}", o.input.display()))?;
    let mut s = TlogSummary {
        file: o.input.display().to_string(),
        ..Default::default()
    };
    let frames = frames(&bytes, &mut s);
    if frames.is_empty() {
        malformed!(
            "{}: no MAVLink frame in {} bytes ({} with a bad checksum)",
            o.input.display(),
            bytes.len(),
            s.bad_checksum
        );
    }
    s.start_unix_s = frames[0].received_us as f64 * 1e-6;
    let readings = readings(&frames, o, &mut s);
    let messages = place(readings, &mut s);
    if messages.is_empty() {
        malformed!(
            "{}: {} MAVLink frames, none with a sensor reading auvnav takes (SCALED_IMU or RAW_IMU, SCALED_PRESSURE{}, ATTITUDE, GPS_RAW_INT, VISION_POSITION_DELTA)",
            o.input.display(),
            s.frames,
            if o.pressure_instance == 1 {
                String::new()
            } else {
                o.pressure_instance.to_string()
            }
        );
    }
    Ok((messages, s))
}

/// Imports a MAVLink telemetry log into a log at `o.out` (written atomically).
pub fn tlog(o: &TlogOptions) -> Result<TlogSummary> {
    let (messages, summary) = tlog_messages(o)?;
    let header = import_header(
        "auvnav import tlog",
        summary.file.clone(),
        format!(
            "MAVLink telemetry log: the autopilot's IMU ({}) and magnetometer, pressure sensor \
             (SCALED_PRESSURE instance {}, depth at {} kg/m³ against {:.2} hPa at the surface), \
             attitude estimate (ATTITUDE), GPS (GPS_RAW_INT, 3D fixes) and DVL \
             (VISION_POSITION_DELTA, at reception); autopilot-clock \
             messages placed by the smallest receive delay; time 0 = Unix time {:.3}",
            summary.imu_source,
            o.pressure_instance,
            o.water_density,
            summary.surface_pressure_hpa,
            summary.start_unix_s
        ),
        &summary,
    );
    write_log_atomically(&o.out, &header, |w: &mut LogWriter<_>| {
        let source = |s: &str| note(&[("source", s)]);
        w.declare::<ImuSampleV1>(
            topic::IMU,
            &source("the autopilot's IMU (mG, mrad/s → SI), device time = its boot clock"),
        )?;
        w.declare::<MagnetometerV1>(topic::MAGNETOMETER, &source("the autopilot's compass"))?;
        w.declare::<DepthV1>(topic::DEPTH, &source("SCALED_PRESSURE: absolute pressure"))?;
        w.declare::<AttitudeV1>(
            topic::ATTITUDE,
            &source("ATTITUDE: the autopilot's own estimate, not a sensor"),
        )?;
        w.declare::<GnssFixV1>(topic::GNSS, &source("GPS_RAW_INT, 3D fixes"))?;
        w.declare::<DvlVelocityV1>(
            topic::DVL,
            &source("VISION_POSITION_DELTA: a DVL extension's position change over its interval"),
        )?;
        for (t, m) in &messages {
            match m {
                LogMessage::Imu(x) => w.write(t, x)?,
                LogMessage::Magnetometer(x) => w.write(t, x)?,
                LogMessage::Depth(x) => w.write(t, x)?,
                LogMessage::Attitude(x) => w.write(t, x)?,
                LogMessage::Gnss(x) => w.write(t, x)?,
                LogMessage::Dvl(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .map_err(crate::error::output(&o.out))?;
    Ok(summary)
}
