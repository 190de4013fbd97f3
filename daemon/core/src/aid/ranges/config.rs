//! The `[navigation.ranges]` configuration: where the acoustic receivers are, how a range was
//! measured, and its noise and error processes.

use crate::aid::usbl::UsblConfig;
use crate::ekf;
use serde::{Deserialize, Serialize};

/// Where the receivers' frame is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ArrayKind {
    /// Surveyed and still (LBL beacons on the seabed, a docking station's array): the frame's
    /// origin and yaw are configured.
    #[default]
    Fixed,
    /// Carried by a boat or a ship: the frame's pose comes from the `acoustic_array_pose` topic
    /// (the boat's GNSS and heading).
    Moving,
}

/// Who sends the ping of a two-way range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interrogator {
    /// The receiver pings, the vehicle's transponder replies (an underwater GPS, a ship ranging
    /// to a vehicle's transponder); the range's time is its arrival at the receiver.
    #[default]
    Array,
    /// The vehicle pings, the beacon replies (LBL); the range's time is the reply's arrival at
    /// the vehicle.
    Vehicle,
}

impl ArrayKind {
    pub const NAMES: &'static [&'static str] = &["fixed", "moving"];
}

impl std::str::FromStr for ArrayKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "fixed" => Ok(ArrayKind::Fixed),
            "moving" => Ok(ArrayKind::Moving),
            _ => Err(format!("unknown acoustic array {s:?} (fixed or moving)")),
        }
    }
}

/// The range aid's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RangesConfig {
    /// fixed (surveyed: LBL, a docking array) or moving (a boat's array, a ship's transducer).
    /// Default fixed.
    pub array: ArrayKind,
    /// Fixed array: its frame's origin (deg, deg, m above the ellipsoid) and the yaw of its x
    /// axis from north (deg).
    pub origin_latitude_deg: f64,
    pub origin_longitude_deg: f64,
    pub origin_height_m: f64,
    pub origin_yaw_deg: f64,
    /// Receiver (or beacon) k's position in the array frame (x, y, z down, m), k = 0..3 as the
    /// device numbers them: a beacon's offset from the origin, or a receiver's offset from the
    /// boat's GNSS antenna (x forward, y starboard). At least one.
    pub receivers_m: Vec<[f64; 3]>,
    /// Place the receivers where the device says they are: each ranges message that carries
    /// the receivers' positions (`receiver_position_m`, as a Water Linked Underwater GPS
    /// topside's `auvnav-ugps` driver publishes them) replaces them, in the same array frame;
    /// no range is fused before the first such message, and `receivers_m` is not used. Default
    /// false.
    pub receivers_from_device: bool,
    /// The vehicle's transducer in its body frame (m). Default 0.
    pub transducer_lever_arm_m: [f64; 3],
    /// Two-way travel (a ping and a reply; the range is half the path) or one-way (the vehicle's
    /// transmitter and the receivers share a clock). Default true.
    pub two_way: bool,
    /// array (the receiver pings) or vehicle (the vehicle pings, LBL). Default array.
    pub interrogator: Interrogator,
    /// The responder's turnaround delay the device removes (s): only where the sound was when
    /// (an error in it is a range bias, which the bias state takes). Default 0.
    pub turnaround_s: f64,
    /// The sound speed the device turns travel times into ranges with (m/s). Default 1500.
    pub device_sound_speed_m_s: f64,
    /// The water's sound speed (m/s): the ranges are scaled by its ratio to the device's.
    /// Default 1500.
    pub sound_speed_m_s: f64,
    /// Take the water's sound speed from the `sound_velocity` topic (a CTD) once it has one.
    /// Default false.
    pub sound_speed_from_topic: bool,
    /// One range's noise (m). Default 0.3.
    pub range_std_m: f64,
    /// The range bias (timing, turnaround): a Gauss–Markov state, as S-USBL's δR, shared by the
    /// receivers or one per receiver (`bias_per_receiver`); stationary one-sigma (m, 0 = off).
    /// Default 0.5.
    pub bias_std_m: f64,
    /// Its correlation time (s). Default 600.
    pub bias_correlation_s: f64,
    /// A bias state per receiver (its own detection delay, cable or electronics) instead of one
    /// shared by all. Default false.
    pub bias_per_receiver: bool,
    /// The sound-speed error as a range scale factor: a Gauss–Markov state; stationary
    /// one-sigma (dimensionless, 0 = off). Default 0.003 (4.5 m/s).
    pub scale_std: f64,
    /// Its correlation time (s). Default 3600.
    pub scale_correlation_s: f64,
    /// Moving array: its horizontal position's one-sigma when the pose does not give one (m).
    /// Default 1.
    pub array_position_std_m: f64,
    /// Moving array: its heading's one-sigma when the pose does not give one (deg). Default 1.
    pub array_heading_std_deg: f64,
    /// Moving array: the longest gap between poses a range is interpolated across (s).
    /// Default 2.
    pub array_pose_max_gap_s: f64,
    /// Gate on each range's squared normalised innovation (chi-square, 1 dof). Default 10.83.
    pub gate_chi2: f64,
    /// Consecutive rejected ranges of one receiver after which the position's covariance is
    /// reopened by the last innovation: that receiver's ranges agree with one another, not with
    /// the state (an outlier, or a linearisation from metres off, taken while the position was
    /// still uncertain left it where the other receivers' ranges hold it). Default 10.
    pub reopen_after: u32,
    /// Longest range accepted (m). Default 5000.
    pub max_range_m: f64,
    /// Take a docking station's fixes (the `usbl` topic) as ranges: the slant range as receiver
    /// 0's two-way range (the station's transducer) and the range differences ΔR13 and ΔR24 as
    /// one-way differences between receivers 1 and 3, and 2 and 4 (its hydrophones), each gated
    /// alone, at the fix's time of validity. `receivers_m` then lists five receivers, the array
    /// is fixed, and `[navigation.usbl]` is not configured ([`RangesConfig::docking_station`]
    /// builds this configuration from it). Default false.
    pub usbl_fixes: bool,
    /// A range difference's noise (m). Default 0.002.
    pub difference_std_m: f64,
    /// The error of each range difference (the array's orientation, phase calibration): a
    /// Gauss–Markov state per difference, as S-USBL's δΔR; stationary one-sigma (m, 0 = off).
    /// Default 0.01.
    pub difference_bias_std_m: f64,
    /// Its correlation time (s). Default 3600.
    pub difference_bias_correlation_s: f64,
    /// Oldest range accepted, by its time against the navigation state (s). Default 3.
    pub max_latency_s: f64,
}

impl Default for RangesConfig {
    fn default() -> Self {
        RangesConfig {
            array: ArrayKind::Fixed,
            origin_latitude_deg: 0.0,
            origin_longitude_deg: 0.0,
            origin_height_m: 0.0,
            origin_yaw_deg: 0.0,
            receivers_m: vec![[0.0; 3]],
            receivers_from_device: false,
            transducer_lever_arm_m: [0.0; 3],
            two_way: true,
            interrogator: Interrogator::Array,
            turnaround_s: 0.0,
            device_sound_speed_m_s: 1500.0,
            sound_speed_m_s: 1500.0,
            sound_speed_from_topic: false,
            range_std_m: 0.3,
            bias_std_m: 0.5,
            bias_per_receiver: false,
            bias_correlation_s: 600.0,
            scale_std: 0.003,
            scale_correlation_s: 3600.0,
            array_position_std_m: 1.0,
            array_heading_std_deg: 1.0,
            array_pose_max_gap_s: 2.0,
            gate_chi2: 10.83,
            reopen_after: 10,
            max_range_m: 5000.0,
            max_latency_s: 3.0,
            usbl_fixes: false,
            difference_std_m: 0.002,
            difference_bias_std_m: 0.01,
            difference_bias_correlation_s: 3600.0,
        }
    }
}

impl RangesConfig {
    /// Every value that makes no sense, as `ranges.key = value: expected …`.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut range = |key: &str, v: f64, lo: f64, hi: f64| {
            if !(v.is_finite() && v >= lo && v <= hi) {
                out.push(format!("ranges.{key} = {v}: expected {lo}..={hi}"));
            }
        };
        range("origin_latitude_deg", self.origin_latitude_deg, -89.9, 89.9);
        range(
            "origin_longitude_deg",
            self.origin_longitude_deg,
            -180.0,
            180.0,
        );
        range("origin_height_m", self.origin_height_m, -12000.0, 10000.0);
        range("origin_yaw_deg", self.origin_yaw_deg, -360.0, 360.0);
        for (k, r) in self.receivers_m.iter().enumerate() {
            for (i, x) in r.iter().enumerate() {
                range(&format!("receivers_m[{k}][{i}]"), *x, -20000.0, 20000.0);
            }
        }
        for (i, x) in self.transducer_lever_arm_m.iter().enumerate() {
            range(&format!("transducer_lever_arm_m[{i}]"), *x, -50.0, 50.0);
        }
        range("turnaround_s", self.turnaround_s, 0.0, 10.0);
        range(
            "device_sound_speed_m_s",
            self.device_sound_speed_m_s,
            1375.0,
            1650.0,
        );
        range("sound_speed_m_s", self.sound_speed_m_s, 1375.0, 1650.0);
        range("range_std_m", self.range_std_m, 1e-4, 1000.0);
        range("bias_std_m", self.bias_std_m, 0.0, 1000.0);
        range("bias_correlation_s", self.bias_correlation_s, 1.0, 1e6);
        range("scale_std", self.scale_std, 0.0, 0.1);
        range("scale_correlation_s", self.scale_correlation_s, 1.0, 1e6);
        range(
            "array_position_std_m",
            self.array_position_std_m,
            0.0,
            1000.0,
        );
        range(
            "array_heading_std_deg",
            self.array_heading_std_deg,
            0.0,
            180.0,
        );
        range(
            "array_pose_max_gap_s",
            self.array_pose_max_gap_s,
            0.01,
            60.0,
        );
        range("gate_chi2", self.gate_chi2, 0.1, 1e6);
        range("max_range_m", self.max_range_m, 1.0, 100_000.0);
        range("max_latency_s", self.max_latency_s, 0.0, 30.0);
        range("difference_std_m", self.difference_std_m, 1e-5, 100.0);
        range(
            "difference_bias_std_m",
            self.difference_bias_std_m,
            0.0,
            100.0,
        );
        range(
            "difference_bias_correlation_s",
            self.difference_bias_correlation_s,
            1.0,
            1e6,
        );
        if self.reopen_after == 0 {
            out.push("ranges.reopen_after = 0: expected 1 or more".into());
        }
        let n = self.receivers_m.len();
        if self.usbl_fixes {
            if n != 5 {
                out.push(format!(
                    "ranges.receivers_m: {n} receivers; usbl_fixes needs five (the station's \
                     transducer, then hydrophones 1 to 4)"
                ));
            }
            if self.array != ArrayKind::Fixed || self.receivers_from_device {
                out.push(
                    "ranges.usbl_fixes: a docking station's array is fixed and configured \
                     (array = \"fixed\", receivers_from_device = false)"
                        .into(),
                );
            }
        } else if !(1..=4).contains(&n) {
            out.push(format!(
                "ranges.receivers_m: {n} receivers; expected 1 to 4 (the ranges message carries four)"
            ));
        }
        let states = ErrorStates::of(self);
        if states.count > ekf::ACOUSTIC_SLOTS {
            out.push(format!(
                "ranges: {} error states (biases, differences' errors, scale); the filter has {} \
                 acoustic slots: share the bias (bias_per_receiver = false), or switch off the \
                 scale (scale_std = 0) or the differences' errors (difference_bias_std_m = 0)",
                states.count,
                ekf::ACOUSTIC_SLOTS
            ));
        }
        out
    }

    /// The range aid configured as a docking station's tight USBL (`[navigation.usbl]`,
    /// S-USBL): its slant range and range differences fused one by one through the same
    /// geometry and error processes (the station's array, hydrophone offsets, the responder's
    /// lever arm, the noise and the Gauss–Markov errors δR, δΔR13, δΔR24), by the range aid's
    /// linearised update with its gate instead of the adaptive unscented one.
    pub fn docking_station(u: &UsblConfig) -> RangesConfig {
        let a = u.array();
        let mut receivers = vec![[0.0; 3]];
        receivers.extend(a.hydrophones.iter().map(|h| [h.x, h.y, h.z]));
        RangesConfig {
            array: ArrayKind::Fixed,
            origin_latitude_deg: u.array_latitude_deg,
            origin_longitude_deg: u.array_longitude_deg,
            origin_height_m: u.array_height_m,
            origin_yaw_deg: u.array_yaw_deg,
            receivers_m: receivers,
            transducer_lever_arm_m: u.responder_lever_arm_m,
            range_std_m: u.range_std_m,
            bias_std_m: u.range_error_std_m,
            bias_correlation_s: u.range_error_correlation_s,
            scale_std: 0.0,
            difference_std_m: u.range_difference_std_m,
            difference_bias_std_m: u.range_difference_error_std_m,
            difference_bias_correlation_s: u.range_difference_error_correlation_s,
            gate_chi2: u.gate_chi2,
            reopen_after: u.reopen_after,
            max_range_m: u.max_range_m,
            max_latency_s: u.max_latency_s,
            usbl_fixes: true,
            ..RangesConfig::default()
        }
    }
}

/// Which acoustic error slot (0..[`ekf::ACOUSTIC_SLOTS`], from [`ekf::USBL`]) each error state
/// of a configuration takes: the range bias (shared: every receiver the same), each range
/// difference's error, the scale. The shared bias and the scale keep the first two.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ErrorStates {
    pub bias: [Option<usize>; 5],
    pub difference: [Option<usize>; 2],
    pub scale: Option<usize>,
    /// Slots asked for (more than the filter has when the configuration is refused).
    pub count: usize,
}

impl ErrorStates {
    pub fn of(c: &RangesConfig) -> ErrorStates {
        fn next(s: &mut ErrorStates) -> Option<usize> {
            s.count += 1;
            (s.count <= ekf::ACOUSTIC_SLOTS).then_some(s.count - 1)
        }
        let mut s = ErrorStates::default();
        if c.bias_std_m > 0.0 {
            if c.bias_per_receiver {
                // Receivers the device places: as many as a ranges message carries.
                let n = if c.receivers_from_device {
                    4
                } else {
                    c.receivers_m.len().min(5)
                };
                for k in 0..n {
                    s.bias[k] = next(&mut s);
                }
            } else {
                let slot = next(&mut s);
                s.bias = [slot; 5];
            }
        }
        let scale = (c.scale_std > 0.0).then(|| next(&mut s)).flatten();
        // The shared bias and the scale stay in the slots they always had (0 and 1).
        if c.usbl_fixes && c.difference_bias_std_m > 0.0 {
            let first = next(&mut s);
            let second = next(&mut s);
            s.difference = [first, second];
        }
        s.scale = scale;
        s
    }
}
