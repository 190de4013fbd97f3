//! One device on a serial line: its protocol's stream decoder followed by the conversion to the
//! schema message the driver publishes. Pure (no I/O, no clock): the driver passes the host time
//! at read return; with the line's timing ([`DeviceDecoder::time_the_line`]) each frame is stamped
//! when its first byte arrived, and an IMU's samples with its own clock
//! ([`crate::line_time`]).

use crate::framing::DecoderStats;
use crate::gnss::{EpochGatherer, GnssSettings};
use crate::kvh::KvhDecoder;
use crate::line_time::{ArrivalClock, DeviceClock};
use crate::nmea::NmeaDecoder;
use crate::nortek::{NortekDecoder, NortekFrame};
use crate::pd0::Pd0Decoder;
pub use crate::seatrac::settings::{BeaconList, SeatracSettings};
use crate::seatrac::{SeatracDecoder, SeatracMessage};
use crate::to_schema::{self, KvhConfig};
use crate::ubx::{UbxDecoder, UbxFrame};
use crate::wldvl::json::{JsonDecoder, JsonFrame};
use crate::wldvl::{WlDecoder, WlFrame};
use crate::xsens::{XbusDecoder, XbusMessage};
use auvnav_shm_schema::{
    AcousticRangesV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1, UsblFixV1,
};
use serde::{Deserialize, Serialize};

/// A serial protocol the drivers speak.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    /// Teledyne RDI PD0 (binary ensembles).
    Pd0,
    /// Water Linked DVL serial protocol (`wrz` velocity reports).
    Wldvl,
    /// KVH 1750/1775 IMU binary messages (formats A and B).
    Kvh1750,
    /// Xsens MTi XBus MTData2.
    Xsens,
    /// Blueprint Subsea SeaTrac USBL (`CID_XCVR_FIX`, `CID_PING_RESP`).
    Seatrac,
    /// Nortek DVL1000/DVL500 binary records (bottom track, id 0x1B).
    Nortek,
    /// Water Linked DVL JSON reports from its TCP service (`[tcp]`, port 16171).
    #[serde(rename = "wldvl-json")]
    WldvlJson,
    /// NMEA 0183 from a GNSS receiver (GGA, RMC, VTG, GST, ZDA, HDT).
    Nmea,
    /// u-blox UBX (`NAV-PVT`).
    Ubx,
}

impl Protocol {
    pub const ALL: [Protocol; 9] = [
        Protocol::Pd0,
        Protocol::Wldvl,
        Protocol::Kvh1750,
        Protocol::Xsens,
        Protocol::Seatrac,
        Protocol::Nortek,
        Protocol::WldvlJson,
        Protocol::Nmea,
        Protocol::Ubx,
    ];

    /// The name used in configuration files and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Protocol::Pd0 => "pd0",
            Protocol::Wldvl => "wldvl",
            Protocol::Kvh1750 => "kvh1750",
            Protocol::Xsens => "xsens",
            Protocol::Seatrac => "seatrac",
            Protocol::Nortek => "nortek",
            Protocol::WldvlJson => "wldvl-json",
            Protocol::Nmea => "nmea",
            Protocol::Ubx => "ubx",
        }
    }

    pub fn from_name(name: &str) -> Option<Protocol> {
        Protocol::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Every protocol's name, in the order of [`Protocol::ALL`].
    pub const NAMES: [&'static str; 9] = {
        let mut names = [""; 9];
        let mut i = 0;
        while i < names.len() {
            names[i] = Protocol::ALL[i].name();
            i += 1;
        }
        names
    };

    /// The class of device that speaks it.
    /// Whether the device also sends the magnetic field (published on the magnetometer topic).
    pub fn carries_magnetic_field(self) -> bool {
        self == Protocol::Xsens
    }

    pub fn class(self) -> DeviceClass {
        match self {
            Protocol::Pd0 | Protocol::Wldvl | Protocol::Nortek | Protocol::WldvlJson => {
                DeviceClass::Dvl
            }
            Protocol::Kvh1750 | Protocol::Xsens => DeviceClass::Imu,
            Protocol::Seatrac => DeviceClass::Usbl,
            Protocol::Nmea | Protocol::Ubx => DeviceClass::Gnss,
        }
    }
}

impl std::str::FromStr for Protocol {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Protocol::from_name(s)
            .ok_or_else(|| format!("unknown protocol {s:?} ({})", Protocol::NAMES.join(", ")))
    }
}

/// What a device measures, and so which topic its driver publishes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceClass {
    Dvl,
    Imu,
    Usbl,
    Gnss,
}

impl DeviceClass {
    pub fn name(self) -> &'static str {
        match self {
            DeviceClass::Dvl => "dvl",
            DeviceClass::Imu => "imu",
            DeviceClass::Usbl => "usbl",
            DeviceClass::Gnss => "gnss",
        }
    }
}

/// Settings the byte stream does not carry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProtocolSettings {
    /// Time from validity to the frame's first byte on the line, for protocols that do not report
    /// it
    /// (PD0, SeaTrac, Nortek) (s, 0..10, default 0).
    pub latency_s: f64,
    /// Xsens output data rate: the integration interval of delta-q/delta-v is its inverse (Hz,
    /// default 400).
    pub xsens_rate_hz: f64,
    /// What one unit of the Xsens normalised magnetic field stands for (µT): the field strength
    /// at the site of the device's last magnetic calibration (default 50). A magnetometer
    /// calibration (`auvnav calibrate mag`) absorbs an error in it into the soft-iron scale.
    pub xsens_field_unit_ut: f64,
    /// KVH output configuration (=ROTFMT, =ROTUNITS, =TEMPUNITS, rate).
    pub kvh: KvhConfig,
    /// GNSS receiver settings (uncertainty without GST, leap seconds, the surface gate).
    pub gnss: GnssSettings,
    /// SeaTrac: the beacons ranged as LBL transponders.
    pub seatrac: SeatracSettings,
}

/// Default of [`ProtocolSettings::xsens_field_unit_ut`] (µT).
pub const XSENS_FIELD_UNIT_UT: f64 = 50.0;

impl Default for ProtocolSettings {
    fn default() -> Self {
        ProtocolSettings {
            latency_s: 0.0,
            xsens_rate_hz: 400.0,
            xsens_field_unit_ut: XSENS_FIELD_UNIT_UT,
            kvh: KvhConfig {
                increments: false,
                degrees: false,
                rate_hz: 1000.0,
                temperature_centi: false,
            },
            gnss: GnssSettings::default(),
            seatrac: SeatracSettings::default(),
        }
    }
}

/// A message for the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Output {
    Imu(ImuSampleV1),
    Dvl(DvlVelocityV1),
    Usbl(UsblFixV1),
    Magnetometer(MagnetometerV1),
    Gnss(GnssFixV1),
    /// A SeaTrac fix from a beacon ranged as a transponder.
    AcousticRanges(AcousticRangesV1),
}

impl Output {
    /// The message's host time stamp.
    pub fn host_time_ns(&self) -> u64 {
        match self {
            Output::Imu(m) => m.host_time_ns,
            Output::Dvl(m) => m.host_time_ns,
            Output::Usbl(m) => m.host_time_ns,
            Output::Magnetometer(m) => m.host_time_ns,
            Output::Gnss(m) => m.host_time_ns,
            Output::AcousticRanges(m) => m.host_time_ns,
        }
    }
}

enum Inner {
    Pd0(Pd0Decoder),
    Wldvl(WlDecoder),
    Kvh(KvhDecoder),
    Xsens(XbusDecoder),
    Seatrac(SeatracDecoder),
    Nortek(NortekDecoder),
    WldvlJson(JsonDecoder),
    Nmea(NmeaDecoder, Box<EpochGatherer>),
    Ubx(UbxDecoder),
}

/// Counters beyond the stream decoder's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct DeviceCounters {
    /// Good frames that carry nothing to publish (configuration replies, status, other reports).
    pub other_frames: u64,
    /// Samples the device numbered but that never arrived (gaps in its own counter).
    pub device_gaps: u64,
    /// Samples with a value outside the device's documented measurement range (published
    /// flagged invalid, so that nothing integrates them).
    pub out_of_range: u64,
    /// GNSS epochs without a usable position (no fix, a warning status, dead reckoning).
    pub no_fix: u64,
    /// Times the model of the device's clock started again: the clock stepped back or away from
    /// the host's (a device restart).
    pub clock_resets: u64,
}

/// The decoder and conversion of one device.
pub struct DeviceDecoder {
    protocol: Protocol,
    settings: ProtocolSettings,
    inner: Inner,
    last_counter: Option<u16>,
    counters: DeviceCounters,
    /// A second message from the last frame (an Xsens packet with both inertial data and the
    /// magnetic field), returned by the next call.
    pending: Option<Output>,
    /// The line's timing: each frame stamped at its first byte's arrival.
    arrival: Option<ArrivalClock>,
    /// The IMU's own clock translated to host time (with the line's timing).
    device_clock: Option<DeviceClock>,
}

/// The wrap-around of an IMU's clock (ns): KVH's 32-bit microseconds, Xsens's 32-bit
/// SampleTimeFine at 10 kHz.
fn imu_clock_modulus_ns(protocol: Protocol) -> Option<u64> {
    match protocol {
        Protocol::Kvh1750 => Some((1u64 << 32) * 1_000),
        Protocol::Xsens => Some((1u64 << 32) * 100_000),
        _ => None,
    }
}

/// A frame's time: its first byte's arrival when the line is timed
/// ([`ArrivalClock::frame_ns`]), else the read's return.
fn frame_time(arrival: &mut Option<ArrivalClock>, frame_start: u64, read_ns: u64) -> u64 {
    arrival
        .as_mut()
        .and_then(|a| a.frame_ns(frame_start))
        .unwrap_or(read_ns)
}

impl DeviceDecoder {
    pub fn new(protocol: Protocol, settings: ProtocolSettings) -> Self {
        let inner = match protocol {
            Protocol::Pd0 => Inner::Pd0(Pd0Decoder::new()),
            Protocol::Wldvl => Inner::Wldvl(WlDecoder::new()),
            Protocol::Kvh1750 => Inner::Kvh(KvhDecoder::new()),
            Protocol::Xsens => Inner::Xsens(XbusDecoder::new()),
            Protocol::Seatrac => Inner::Seatrac(SeatracDecoder::new()),
            Protocol::Nortek => Inner::Nortek(NortekDecoder::new()),
            Protocol::WldvlJson => Inner::WldvlJson(JsonDecoder::new()),
            Protocol::Nmea => Inner::Nmea(NmeaDecoder::new(), Box::default()),
            Protocol::Ubx => Inner::Ubx(UbxDecoder::new()),
        };
        DeviceDecoder {
            protocol,
            settings,
            inner,
            last_counter: None,
            counters: DeviceCounters::default(),
            pending: None,
            arrival: None,
            device_clock: None,
        }
    }

    /// Stamps each frame at its first byte's arrival on a line carrying one character every
    /// `character_ns` ([`crate::line_time::character_time_ns`]; 0 for a link without a line
    /// rate), and an IMU's samples that carry the device's clock with that clock translated to
    /// host time. Bytes must then come in through [`DeviceDecoder::push_read`].
    pub fn time_the_line(&mut self, character_ns: f64) {
        self.arrival = Some(ArrivalClock::new(character_ns));
        self.device_clock = (self.protocol.class() == DeviceClass::Imu)
            .then(|| DeviceClock::new(imu_clock_modulus_ns(self.protocol)));
    }

    /// Appends `bytes` of a read that returned at `host_ns`.
    pub fn push_read(&mut self, bytes: &[u8], host_ns: u64) {
        if let Some(a) = self.arrival.as_mut() {
            a.read(bytes.len(), host_ns);
        }
        self.push(bytes);
    }

    /// The port was reopened: the bytes before came over another connection, and the device may
    /// have restarted its clock.
    pub fn restart_line(&mut self) {
        if let Some(a) = self.arrival.as_mut() {
            a.restart();
        }
        if let Some(c) = self.device_clock.as_mut() {
            c.restart();
        }
    }

    /// The IMU clock's rate against the host's (host s per device s), once the model has it.
    pub fn device_clock_rate(&self) -> Option<f64> {
        self.device_clock.as_ref().and_then(DeviceClock::rate)
    }

    /// An IMU sample's host time from the device's clock, when it carries it and the line is
    /// timed.
    fn imu_time(&mut self, m: &mut ImuSampleV1) {
        if let Some(c) = self.device_clock.as_mut()
            && m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0
        {
            m.host_time_ns = c.stamp(m.device_time_ns, m.host_time_ns);
        }
    }

    pub fn protocol(&self) -> Protocol {
        self.protocol
    }

    /// Appends bytes read from the line.
    pub fn push(&mut self, bytes: &[u8]) {
        match &mut self.inner {
            Inner::Pd0(d) => d.push(bytes),
            Inner::Wldvl(d) => d.push(bytes),
            Inner::Kvh(d) => d.push(bytes),
            Inner::Xsens(d) => d.push(bytes),
            Inner::Seatrac(d) => d.push(bytes),
            Inner::Nortek(d) => d.push(bytes),
            Inner::WldvlJson(d) => d.push(bytes),
            Inner::Nmea(d, _) => d.push(bytes),
            Inner::Ubx(d) => d.push(bytes),
        }
    }

    /// The stream decoder's counters.
    pub fn stats(&self) -> DecoderStats {
        *match &self.inner {
            Inner::Pd0(d) => d.stats(),
            Inner::Wldvl(d) => d.stats(),
            Inner::Kvh(d) => d.stats(),
            Inner::Xsens(d) => d.stats(),
            Inner::Seatrac(d) => d.stats(),
            Inner::Nortek(d) => d.stats(),
            Inner::WldvlJson(d) => d.stats(),
            Inner::Nmea(d, _) => d.stats(),
            Inner::Ubx(d) => d.stats(),
        }
    }

    pub fn counters(&self) -> DeviceCounters {
        DeviceCounters {
            clock_resets: self.device_clock.as_ref().map_or(0, DeviceClock::resets),
            ..self.counters
        }
    }

    /// Counts a gap in a device counter that wraps at `modulus`. A counter at or beyond the
    /// modulus cannot come from the device (a corrupted value under a valid checksum): counted
    /// out of range, and the next sample starts the count again.
    fn device_counter(&mut self, counter: u16, modulus: u32) {
        if u32::from(counter) >= modulus {
            self.counters.out_of_range += 1;
            self.last_counter = None;
            return;
        }
        if let Some(last) = self.last_counter {
            let step = (u32::from(counter) + modulus - u32::from(last)) % modulus;
            if step > 1 {
                self.counters.device_gaps += u64::from(step - 1);
            }
        }
        self.last_counter = Some(counter);
    }

    /// The next message to publish from the bytes pushed so far, stamped `host_time_ns` (the
    /// time the read that completed it returned), or, with the line timed, at its first byte's
    /// arrival (an IMU sample with its device's clock: that clock in host time). The sequence
    /// number is left 0: the publisher assigns it.
    // Long on purpose: one arm per protocol, each the decoder's frame to its schema message.
    pub fn next_output(&mut self, host_time_ns: u64) -> Option<Output> {
        let s = self.settings;
        if let Some(out) = self.pending.take() {
            return Some(out);
        }
        loop {
            match &mut self.inner {
                Inner::Pd0(d) => match d.next_ensemble()? {
                    Ok(e) => {
                        let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                        if let Some(m) = to_schema::pd0_velocity(&e, t, s.latency_s, 0) {
                            // The water-mass reference layer of the same ping, next.
                            self.pending =
                                to_schema::pd0_water_track(&e, t, s.latency_s, 0).map(Output::Dvl);
                            return Some(Output::Dvl(m));
                        }
                        self.counters.other_frames += 1;
                    }
                    Err(_) => continue,
                },
                Inner::Wldvl(d) => match d.next_frame()? {
                    Ok(WlFrame::Velocity(v)) => {
                        let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                        return Some(Output::Dvl(to_schema::water_linked_velocity(&v, t, 0)));
                    }
                    Ok(_) => self.counters.other_frames += 1,
                    Err(_) => continue,
                },
                Inner::Kvh(d) => {
                    let sample = d.next_sample()?;
                    let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                    self.device_counter(u16::from(sample.sequence), 128);
                    let mut m = to_schema::kvh_sample(&sample, &s.kvh, t, 0);
                    if !to_schema::KVH_RANGE.check(&mut m) {
                        self.counters.out_of_range += 1;
                    }
                    self.imu_time(&mut m);
                    return Some(Output::Imu(m));
                }
                Inner::Xsens(d) => match d.next_message()? {
                    XbusMessage::MtData2(m) => {
                        let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                        if let Some(c) = m.packet_counter {
                            self.device_counter(c, 1 << 16);
                        }
                        let mut imu = to_schema::xsens_sample(&m, s.xsens_rate_hz, t, 0);
                        if let Some(i) = imu.as_mut() {
                            if !to_schema::XSENS_RANGE.check(i) {
                                self.counters.out_of_range += 1;
                            }
                            self.imu_time(i);
                        }
                        // The field of the same packet, at the same time as its inertial data.
                        let t = imu.map_or(t, |i| i.host_time_ns);
                        let mag = to_schema::xsens_magnetometer(&m, s.xsens_field_unit_ut, t, 0)
                            .map(Output::Magnetometer);
                        match (imu.map(Output::Imu), mag) {
                            (Some(i), m) => {
                                self.pending = m;
                                return Some(i);
                            }
                            (None, Some(m)) => return Some(m),
                            (None, None) => self.counters.other_frames += 1,
                        }
                    }
                    XbusMessage::Other(_) => self.counters.other_frames += 1,
                },
                Inner::Nortek(d) => match d.next_frame()? {
                    Ok(NortekFrame::BottomTrack(bt)) => {
                        let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                        return Some(Output::Dvl(to_schema::nortek_velocity(
                            &bt,
                            t,
                            s.latency_s,
                            0,
                        )));
                    }
                    Ok(NortekFrame::Other(_)) => self.counters.other_frames += 1,
                    Err(_) => continue,
                },
                Inner::WldvlJson(d) => match d.next_frame()? {
                    Ok(JsonFrame::Velocity { velocity, .. }) => {
                        let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                        return Some(Output::Dvl(to_schema::water_linked_velocity(
                            &velocity, t, 0,
                        )));
                    }
                    Ok(_) => self.counters.other_frames += 1,
                    Err(_) => continue,
                },
                Inner::Nmea(d, epochs) => {
                    if let Some(e) = epochs.pop() {
                        match crate::gnss::fix_from_epoch(&e, &s.gnss, s.latency_s) {
                            Some(f) => return Some(Output::Gnss(f)),
                            None => {
                                self.counters.no_fix += 1;
                                continue;
                            }
                        }
                    }
                    match d.next_sentence()? {
                        Ok(sentence) => {
                            if matches!(sentence, crate::nmea::NmeaSentence::Other { .. }) {
                                self.counters.other_frames += 1;
                            }
                            let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                            epochs.push(sentence, t);
                        }
                        Err(_) => continue,
                    }
                }
                Inner::Ubx(d) => match d.next_frame()? {
                    Ok(UbxFrame::NavPvt(p)) => {
                        let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                        match crate::gnss::fix_from_nav_pvt(&p, t, &s.gnss, s.latency_s) {
                            Some(f) => return Some(Output::Gnss(f)),
                            None => self.counters.no_fix += 1,
                        }
                    }
                    Ok(_) => self.counters.other_frames += 1,
                    Err(_) => continue,
                },
                Inner::Seatrac(d) => match d.next_frame()? {
                    Ok(f) => match f.message {
                        SeatracMessage::Fix { fix, .. } if f.from_beacon => {
                            let t = frame_time(&mut self.arrival, d.frame_start(), host_time_ns);
                            if let Some(k) = s.seatrac.range_beacons.slot(fix.source_id) {
                                match to_schema::seatrac_range(&fix, k, t, s.latency_s) {
                                    Some(m) => return Some(Output::AcousticRanges(m)),
                                    None => {
                                        self.counters.out_of_range += 1;
                                        continue;
                                    }
                                }
                            }
                            return Some(Output::Usbl(to_schema::seatrac_fix(
                                &fix,
                                t,
                                s.latency_s,
                                0,
                            )));
                        }
                        _ => self.counters.other_frames += 1,
                    },
                    Err(_) => continue,
                },
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The list of names, each protocol's own name and its configuration spelling agree.
    #[test]
    fn protocol_names_agree_everywhere() {
        for (p, name) in Protocol::ALL.into_iter().zip(Protocol::NAMES) {
            assert_eq!(p.name(), name);
            assert_eq!(name.parse::<Protocol>(), Ok(p));
            let spelled: String =
                serde_json::from_value(serde_json::to_value(p).expect("serialise"))
                    .expect("a string");
            assert_eq!(spelled, name);
        }
        assert!("rs232".parse::<Protocol>().is_err());
    }
}
