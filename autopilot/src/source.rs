//! The autopilot as a source (`[source]`): on a vehicle whose IMU and pressure sensor belong to
//! the autopilot, its `SCALED_IMU` (IMU and compass), a `SCALED_PRESSURE` instance (depth) and
//! optionally its `ATTITUDE` estimate become the bus's sensor messages, converted by
//! [`auvnav_protocols::autopilot`]. Their host time is the autopilot's clock placed on the host's
//! by the smallest receive delay since its boot ([`AutopilotClock`]), so the samples keep the
//! autopilot's spacing. The streams are asked for with `MAV_CMD_SET_MESSAGE_INTERVAL` once the
//! autopilot's heartbeat is seen.

use auvnav_protocols::autopilot::{
    AutopilotClock, AutopilotConversion, AutopilotReading, Converted, ImuMessage,
};
use mavlink::MessageData;
use mavlink::dialects::ardupilotmega as mav;
use serde::{Deserialize, Serialize};

/// `[source]`: which of the autopilot's sensors go onto the bus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// `SCALED_IMU` → `imu` (and `magnetometer`); default true.
    #[serde(default = "yes")]
    pub imu: bool,
    /// The IMU rate asked of the autopilot (Hz, 1..=400, default 50).
    #[serde(default = "default_imu_hz")]
    pub imu_hz: f64,
    /// `SCALED_PRESSURE{pressure_instance}` → `depth`; default true.
    #[serde(default = "yes")]
    pub depth: bool,
    /// 1, 2 (default: ArduSub's external pressure sensor) or 3.
    #[serde(default = "default_instance")]
    pub pressure_instance: u8,
    /// The pressure rate asked of the autopilot (Hz, 1..=50, default 10).
    #[serde(default = "default_depth_hz")]
    pub depth_hz: f64,
    /// Water density for depth (kg/m³, 990..=1050, default 1025).
    #[serde(default = "default_density")]
    pub water_density_kg_m3: f64,
    /// Absolute pressure at the surface (hPa); default: the first reading.
    #[serde(default)]
    pub surface_pressure_hpa: Option<f64>,
    /// `ATTITUDE` (the autopilot's own estimate) → `attitude`; default false.
    #[serde(default)]
    pub attitude: bool,
    /// `VISION_POSITION_DELTA` (a DVL extension's, e.g. Water Linked's on BlueOS: any component
    /// of the vehicle's system) → `dvl`, stamped at its arrival; default false.
    #[serde(default)]
    pub dvl: bool,
}

fn yes() -> bool {
    true
}
fn default_imu_hz() -> f64 {
    50.0
}
fn default_instance() -> u8 {
    2
}
fn default_depth_hz() -> f64 {
    10.0
}
fn default_density() -> f64 {
    1025.0
}

impl SourceConfig {
    /// The first value out of range: (key, value, expected).
    pub fn problem(&self) -> Option<(&'static str, String, &'static str)> {
        let within = |x: f64, lo: f64, hi: f64| x.is_finite() && (lo..=hi).contains(&x);
        if !within(self.imu_hz, 1.0, 400.0) {
            return Some(("source.imu_hz", self.imu_hz.to_string(), "1..=400 Hz"));
        }
        if !within(self.depth_hz, 1.0, 50.0) {
            return Some(("source.depth_hz", self.depth_hz.to_string(), "1..=50 Hz"));
        }
        if !(1..=3).contains(&self.pressure_instance) {
            let v = self.pressure_instance.to_string();
            return Some(("source.pressure_instance", v, "1, 2 or 3"));
        }
        if !within(self.water_density_kg_m3, 990.0, 1050.0) {
            let v = self.water_density_kg_m3.to_string();
            return Some(("source.water_density_kg_m3", v, "990..=1050 kg/m³"));
        }
        None
    }
}

/// Counts of what the source did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SourceCounters {
    pub imu: u64,
    pub magnetometer: u64,
    pub depth: u64,
    pub attitude: u64,
    pub dvl: u64,
    /// Sensor messages with a value that is not finite or out of range.
    pub implausible: u64,
    /// Readings stamped at or before the previous one of their channel (left out).
    pub out_of_order: u64,
}

/// The autopilot's messages into bus messages (pure: the caller gives the arrival times).
pub struct Source {
    cfg: SourceConfig,
    conversion: AutopilotConversion,
    clock: AutopilotClock,
    /// Per channel: the last host time and the next sequence number.
    last: [(u64, u64); 5],
    last_imu_device_ns: Option<u64>,
    pub counters: SourceCounters,
}

impl Source {
    pub fn new(cfg: &SourceConfig) -> Source {
        Source {
            cfg: cfg.clone(),
            conversion: AutopilotConversion {
                imu: ImuMessage::ScaledImu,
                pressure_instance: cfg.pressure_instance,
                water_density_kg_m3: cfg.water_density_kg_m3,
                surface_pressure_hpa: cfg.surface_pressure_hpa,
            },
            clock: AutopilotClock::default(),
            last: [(0, 0); 5],
            last_imu_device_ns: None,
            counters: SourceCounters::default(),
        }
    }

    /// Boots of the autopilot seen (its clock started again).
    pub fn autopilot_boots(&self) -> u64 {
        self.clock.boots
    }

    /// The readings of `m`, which arrived at `arrival_ns` (host clock), ready to publish.
    pub fn on_message(&mut self, m: &mav::MavMessage, arrival_ns: u64) -> Vec<AutopilotReading> {
        let (device_ns, readings) = match self.conversion.convert(m) {
            Converted::Readings {
                device_ns,
                readings,
            } => (device_ns, readings),
            Converted::Implausible => {
                self.counters.implausible += 1;
                return Vec::new();
            }
            _ => return Vec::new(),
        };
        // The autopilot's clock where the message has it; the sender's own (a DVL extension's)
        // is not the autopilot's: such readings are placed at their arrival.
        let host_ns = match device_ns {
            Some(d) => self.clock.host_ns(d, arrival_ns),
            None => arrival_ns,
        };
        let mut out = Vec::new();
        for mut r in readings {
            let (channel, wanted) = match r {
                AutopilotReading::Imu(_) => (0, self.cfg.imu),
                AutopilotReading::Magnetometer(_) => (1, self.cfg.imu),
                AutopilotReading::Depth(_) => (2, self.cfg.depth),
                AutopilotReading::Attitude(_) => (3, self.cfg.attitude),
                AutopilotReading::Dvl(_) => (4, self.cfg.dvl),
                AutopilotReading::Gnss(_) => continue,
            };
            if !wanted {
                continue;
            }
            let (last_ns, sequence) = self.last[channel];
            if sequence > 0 && host_ns <= last_ns {
                self.counters.out_of_order += 1;
                continue;
            }
            self.last[channel] = (host_ns, sequence + 1);
            r.set_times(host_ns, device_ns, sequence);
            match &mut r {
                AutopilotReading::Imu(x) => {
                    let device_ns = device_ns.unwrap_or(host_ns);
                    // The interval since the previous sample by the autopilot's clock.
                    let nominal = 1.0 / self.cfg.imu_hz;
                    x.interval_s = self
                        .last_imu_device_ns
                        .map(|p| device_ns.saturating_sub(p) as f64 * 1e-9)
                        .filter(|dt| *dt > 0.0 && *dt < 1.0)
                        .unwrap_or(nominal);
                    self.last_imu_device_ns = Some(device_ns);
                    self.counters.imu += 1;
                }
                AutopilotReading::Magnetometer(_) => self.counters.magnetometer += 1,
                AutopilotReading::Depth(_) => self.counters.depth += 1,
                AutopilotReading::Attitude(_) => self.counters.attitude += 1,
                AutopilotReading::Dvl(_) => self.counters.dvl += 1,
                AutopilotReading::Gnss(_) => {}
            }
            out.push(r);
        }
        out
    }

    /// `MAV_CMD_SET_MESSAGE_INTERVAL` for each stream the source takes, to the autopilot
    /// (`target_system`, `target_component`).
    pub fn stream_requests(&self, target_system: u8, target_component: u8) -> Vec<mav::MavMessage> {
        let mut wanted = Vec::new();
        if self.cfg.imu {
            wanted.push((mav::SCALED_IMU_DATA::ID, self.cfg.imu_hz));
        }
        if self.cfg.depth {
            let id = match self.cfg.pressure_instance {
                1 => mav::SCALED_PRESSURE_DATA::ID,
                3 => mav::SCALED_PRESSURE3_DATA::ID,
                _ => mav::SCALED_PRESSURE2_DATA::ID,
            };
            wanted.push((id, self.cfg.depth_hz));
        }
        if self.cfg.attitude {
            wanted.push((mav::ATTITUDE_DATA::ID, self.cfg.depth_hz));
        }
        wanted
            .into_iter()
            .map(|(id, hz)| {
                mav::MavMessage::COMMAND_LONG(mav::COMMAND_LONG_DATA {
                    target_system,
                    target_component,
                    command: mav::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                    param1: id as f32,
                    // The interval in microseconds.
                    param2: (1e6 / hz) as f32,
                    ..Default::default()
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> SourceConfig {
        toml::from_str("").expect("defaults")
    }

    fn imu(boot_ms: u32) -> mav::MavMessage {
        mav::MavMessage::SCALED_IMU(mav::SCALED_IMU_DATA {
            time_boot_ms: boot_ms,
            zacc: -1000,
            zmag: 400,
            ..Default::default()
        })
    }

    #[test]
    fn the_autopilots_samples_keep_its_spacing_through_a_jittery_link() {
        let mut s = Source::new(&cfg());
        let mut imu_times = Vec::new();
        for k in 0..500u32 {
            // 50 Hz by the autopilot; read in batches every 25 ms, 2–30 ms late.
            let device_ms = 10_000 + 20 * k;
            let arrival = u64::from(device_ms) * 1_000_000
                + 5_000_000_000
                + 2_000_000
                + u64::from(k * 7919 % 29) * 1_000_000;
            for r in s.on_message(&imu(device_ms), arrival) {
                if let AutopilotReading::Imu(x) = r {
                    assert!(x.host_time_ns <= arrival);
                    imu_times.push((x.host_time_ns, x.interval_s, x.sequence));
                }
            }
        }
        assert_eq!(s.counters.imu, 500);
        assert_eq!(s.counters.magnetometer, 500);
        // Once the smallest delay has been seen (2 ms, at k = 0), every sample 20 ms apart.
        for w in imu_times.windows(2) {
            assert_eq!(w[1].0 - w[0].0, 20_000_000);
            assert!((w[1].1 - 0.02).abs() < 1e-12);
            assert_eq!(w[1].2, w[0].2 + 1);
        }
        // A reboot: the clock starts again, the samples go on without going back.
        let after = s.on_message(&imu(300), 26_000_000_000);
        assert_eq!(s.autopilot_boots(), 2);
        assert!(matches!(after[0], AutopilotReading::Imu(x) if x.host_time_ns == 26_000_000_000));
    }

    #[test]
    fn streams_are_asked_for_and_switched_off_sensors_left_out() {
        let mut c = cfg();
        c.attitude = true;
        c.imu = false;
        let mut s = Source::new(&c);
        assert!(s.on_message(&imu(1000), 2_000_000_000).is_empty());
        let requests = s.stream_requests(1, 1);
        let asked: Vec<(f32, f32)> = requests
            .iter()
            .filter_map(|m| match m {
                mav::MavMessage::COMMAND_LONG(c) => Some((c.param1, c.param2)),
                _ => None,
            })
            .collect();
        assert_eq!(asked, vec![(137.0, 100_000.0), (30.0, 100_000.0)]);
        let depth = mav::MavMessage::SCALED_PRESSURE2(mav::SCALED_PRESSURE2_DATA {
            time_boot_ms: 1000,
            press_abs: f32::NAN,
            ..Default::default()
        });
        assert!(s.on_message(&depth, 2_000_000_000).is_empty());
        assert_eq!(s.counters.implausible, 1);
        let mut bad = cfg();
        bad.imu_hz = 0.0;
        assert_eq!(bad.problem().map(|p| p.0), Some("source.imu_hz"));
        assert_eq!(cfg().problem(), None);
    }

    #[test]
    fn a_dvl_extensions_velocity_is_taken_when_asked_at_its_arrival() {
        let delta = |confidence: f32, forward_m: f32| {
            mav::MavMessage::VISION_POSITION_DELTA(mav::VISION_POSITION_DELTA_DATA {
                time_usec: 1_733_436_754_000_000,
                time_delta_usec: 200_000,
                position_delta: [forward_m, -0.02, 0.0],
                confidence,
                ..Default::default()
            })
        };
        // Off by default.
        let mut off = Source::new(&cfg());
        assert!(off.on_message(&delta(90.0, 0.1), 5_000_000_000).is_empty());
        let mut c = cfg();
        c.dvl = true;
        let mut s = Source::new(&c);
        let got = s.on_message(&delta(90.0, 0.1), 5_000_000_000);
        let [AutopilotReading::Dvl(v)] = got.as_slice() else {
            panic!("one DVL reading: {got:?}");
        };
        // 0.1 m ahead and 2 cm to port in 0.2 s; the confidence back to the figure of merit.
        assert!(
            (v.velocity_dvl_m_s[0] - 0.5).abs() < 1e-6
                && (v.velocity_dvl_m_s[1] + 0.1).abs() < 1e-6
        );
        assert!((v.figure_of_merit_m_s - 0.04).abs() < 1e-6);
        assert_eq!(
            (v.host_time_ns, v.validity_time_ns),
            (5_000_000_000, 5_000_000_000)
        );
        assert_eq!(s.counters.dvl, 1);
        // A confidence out of range, or 30 m in 0.2 s: counted, not published.
        assert!(s.on_message(&delta(150.0, 0.1), 5_200_000_000).is_empty());
        assert!(s.on_message(&delta(90.0, 30.0), 5_400_000_000).is_empty());
        assert_eq!((s.counters.dvl, s.counters.implausible), (1, 2));
    }
}
