//! Message types exchanged between the auvnav processes through iceoryx2 shared memory, and
//! written to the logs.
//!
//! Long on purpose: every message type of the bus in one file, so the schema that the
//! processes and the logs share is read, versioned and reviewed as one; the bus, QoS, topics and
//! clocks are in their own modules.
//!
//! Every type is `#[repr(C)]`, made of fixed-size fields only, free of padding (checked at compile
//! time by `bytemuck::Pod`) and carries a versioned iceoryx2 type name (`auvnav/<Type>/v<N>`).
//! Because the layout has no padding and every field sits at an offset that is a multiple of its
//! own size, the bytes of a value are also its little-endian CDR encoding (XCDR1: primitives aligned
//! to their size, fixed arrays without a length prefix). The log format relies on this: a log
//! message is the 4-byte CDR encapsulation header followed by the struct bytes, and the channel's
//! schema is the `ros2msg` text produced by [`Message::ros2msg_definition`], so third-party MCAP
//! readers decode our logs without our code.
//!
//! Conventions: SI units and radians; navigation frame NED, body frame FRD (x forward, y starboard,
//! z down); rotations are named source_to_target. Validity is carried as bit flags, never as
//! sentinel values: a field whose validity bit is clear holds zero and must not be used.
//! Two clock domains exist and are never mixed: host time (`CLOCK_MONOTONIC` of the machine the
//! process runs on, or simulated time in a simulated log) and device time (the sensor's own clock).
//!
//! The bus ([`bus`]) and the on-board processes' logging ([`logging`]) are behind the `bus`
//! feature, which the processes turn on; without it the crate links neither iceoryx2 nor
//! tracing-subscriber, and the log, the navigation core, the protocol decoders and the offline
//! tools use the message types alone.
//!
//! With the `bus` feature, the zero-copy derive of iceoryx2 emits `unsafe impl`, so the crate
//! cannot forbid unsafe code; its one hand-written `unsafe` sets SIGHUP to be ignored
//! (`logging::ignore_hangup`). Without the feature, unsafe code is forbidden. The host clock is
//! read through `nix` (safe wrappers).
#![cfg_attr(not(feature = "bus"), forbid(unsafe_code))]

#[cfg(feature = "bus")]
pub mod bus;
pub mod clock;
#[cfg(feature = "bus")]
pub mod logging;
pub mod qos;
pub mod sensor;
pub mod stage_times;
#[cfg(feature = "bus")]
pub mod supervisor;
pub mod topic;

pub use bytemuck::{Pod, Zeroable};
#[cfg(feature = "bus")]
use iceoryx2::prelude::ZeroCopySend;

/// What a message type needs to travel through the bus: iceoryx2's zero-copy marker with the
/// `bus` feature, nothing without it.
#[cfg(feature = "bus")]
pub trait BusPayload: ZeroCopySend {}
#[cfg(feature = "bus")]
impl<T: ZeroCopySend> BusPayload for T {}
/// What a message type needs to travel through the bus: iceoryx2's zero-copy marker with the
/// `bus` feature, nothing without it.
#[cfg(not(feature = "bus"))]
pub trait BusPayload {}
#[cfg(not(feature = "bus"))]
impl<T> BusPayload for T {}

/// A time in the host clock domain: nanoseconds of `CLOCK_MONOTONIC` (or simulated time).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct HostTime(pub u64);

/// A time in a device's own clock domain, in nanoseconds since the device's epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct DeviceTime(pub u64);

impl HostTime {
    /// Seconds as `f64` (for arithmetic in the navigation core).
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }
    /// From seconds; negative or non-finite input saturates to 0.
    pub fn from_secs_f64(s: f64) -> Self {
        if s.is_finite() && s > 0.0 {
            HostTime((s * 1e9).round() as u64)
        } else {
            HostTime(0)
        }
    }
}

/// What a message type needs so the bus can number it (every message carries a `sequence`).
pub trait Sequenced {
    fn set_sequence(&mut self, sequence: u64);
    fn sequence(&self) -> u64;
}

/// A message type that can travel through shared memory and be written to a log.
pub trait Message: Pod + BusPayload + Default + std::fmt::Debug {
    /// iceoryx2 type name, versioned (`auvnav/ImuSample/v1`).
    const TYPE_NAME: &'static str;
    /// Schema name in the log (`auvnav_msgs/msg/ImuSampleV1`).
    const SCHEMA_NAME: &'static str;
    /// The `ros2msg` schema text describing the CDR layout of this type (with field docs as
    /// comments).
    fn ros2msg_definition() -> String;
    /// The host-clock time stamp of the message, used as the log time.
    fn host_time(&self) -> HostTime;
    /// Every field in declaration order, by name, as a slice of its values (one value for a
    /// scalar, N for an array): the table view of a message (log readers, exports).
    fn for_each_field(&self, f: &mut dyn FnMut(&'static str, FieldValues<'_>));
}

/// The values of one message field: a scalar is a slice of one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FieldValues<'a> {
    F64(&'a [f64]),
    F32(&'a [f32]),
    U64(&'a [u64]),
    U32(&'a [u32]),
    U16(&'a [u16]),
    /// Bytes: a NUL-padded text (a process name) or a raw frame.
    U8(&'a [u8]),
}

/// A field type's values as [`FieldValues`].
pub trait AsFieldValues {
    fn field_values(&self) -> FieldValues<'_>;
}

macro_rules! as_field_values {
    ($($t:ty => $v:ident),* $(,)?) => {
        $(
            impl AsFieldValues for $t {
                fn field_values(&self) -> FieldValues<'_> {
                    FieldValues::$v(std::slice::from_ref(self))
                }
            }
            impl<const N: usize> AsFieldValues for [$t; N] {
                fn field_values(&self) -> FieldValues<'_> {
                    FieldValues::$v(self)
                }
            }
        )*
    };
}
as_field_values!(f64 => F64, f32 => F32, u64 => U64, u32 => U32, u16 => U16, u8 => U8);

/// The `ros2msg` name of a field type.
pub trait RosField {
    fn ros_type() -> String;
}

macro_rules! ros_field {
    ($($t:ty => $n:literal),* $(,)?) => {
        $(impl RosField for $t { fn ros_type() -> String { $n.to_string() } })*
    };
}
ros_field!(f64 => "float64", f32 => "float32", u64 => "uint64", u32 => "uint32", u16 => "uint16",
    u8 => "uint8", i64 => "int64", i32 => "int32", i16 => "int16", i8 => "int8");

impl<T: RosField, const N: usize> RosField for [T; N] {
    fn ros_type() -> String {
        format!("{}[{}]", T::ros_type(), N)
    }
}

macro_rules! message {
    (
        $(#[doc = $doc:literal])*
        #[type_name($tn:literal)]
        #[schema_name($sn:literal)]
        pub struct $name:ident {
            $(
                $(#[doc = $fdoc:literal])*
                pub $field:ident : $ty:ty,
            )*
        }
    ) => {
        $(#[doc = $doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
        #[cfg_attr(feature = "bus", derive(ZeroCopySend), type_name($tn))]
        #[repr(C)]
        pub struct $name {
            $( $(#[doc = $fdoc])* pub $field: $ty, )*
        }

        impl Default for $name {
            fn default() -> Self {
                Zeroable::zeroed()
            }
        }

        impl Message for $name {
            const TYPE_NAME: &'static str = $tn;
            const SCHEMA_NAME: &'static str = $sn;
            fn ros2msg_definition() -> String {
                let mut s = String::new();
                $( s.push('#'); s.push_str($doc); s.push('\n'); )*
                $(
                    $( s.push('#'); s.push_str($fdoc); s.push('\n'); )*
                    s.push_str(&<$ty as RosField>::ros_type());
                    s.push(' ');
                    s.push_str(stringify!($field));
                    s.push('\n');
                )*
                s
            }
            fn host_time(&self) -> HostTime {
                HostTime(self.host_time_ns)
            }
            fn for_each_field(&self, f: &mut dyn FnMut(&'static str, FieldValues<'_>)) {
                $( f(stringify!($field), AsFieldValues::field_values(&self.$field)); )*
            }
        }

        impl crate::Sequenced for $name {
            fn set_sequence(&mut self, sequence: u64) {
                self.sequence = sequence;
            }
            fn sequence(&self) -> u64 {
                self.sequence
            }
        }
    };
}

message! {
    /// One inertial measurement: angular rate and specific force (rate mode) or their increments
    /// over `interval_s` (increment mode, status bit `INCREMENTS`), in the IMU body frame (FRD).
    #[type_name("auvnav/ImuSample/v1")]
    #[schema_name("auvnav_msgs/msg/ImuSampleV1")]
    pub struct ImuSampleV1 {
        /// Host time (ns, CLOCK_MONOTONIC; simulated time in simulated logs) the frame's first byte arrived, or the device's clock translated to it; also the time of validity.
        pub host_time_ns: u64,
        /// Device clock at the sample (ns); valid with status bit DEVICE_TIME_VALID.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher, +1 per sample; gaps mean lost samples.
        pub sequence: u64,
        /// Angular rate of the body w.r.t. inertial space (rad/s, body FRD, |x| < 35 rad/s), or its increment (rad) in increment mode.
        pub angular: [f64; 3],
        /// Specific force (m/s^2, body FRD, |x| < 500 m/s^2), or its increment, delta-velocity (m/s), in increment mode.
        pub specific: [f64; 3],
        /// Sample interval; the integration interval of the increments in increment mode (s, 0 < x < 1).
        pub interval_s: f64,
        /// Sensor temperature (degC, -60..120); valid with status bit TEMPERATURE_VALID.
        pub temperature_c: f32,
        /// Status bit flags (ImuSampleV1::STATUS_*).
        pub status: u32,
    }
}

impl ImuSampleV1 {
    /// `angular`/`specific` hold increments (rad, m/s) over `interval_s` rather than rates.
    pub const STATUS_INCREMENTS: u32 = 1 << 0;
    pub const STATUS_GYRO_VALID: u32 = 1 << 1;
    pub const STATUS_ACCEL_VALID: u32 = 1 << 2;
    pub const STATUS_TEMPERATURE_VALID: u32 = 1 << 3;
    pub const STATUS_DEVICE_TIME_VALID: u32 = 1 << 4;
    pub const STATUS_GYRO_SATURATED: u32 = 1 << 5;
    pub const STATUS_ACCEL_SATURATED: u32 = 1 << 6;
    /// The device's built-in test reports a failure.
    pub const STATUS_BUILT_IN_TEST_FAIL: u32 = 1 << 7;

    /// The angular rate (rad/s): the rate as given, or the increment over `interval_s`. None when
    /// the gyro is not valid, an increment has no positive interval, or a value is not finite.
    pub fn angular_rate(&self) -> Option<[f64; 3]> {
        self.per_second(self.angular, Self::STATUS_GYRO_VALID)
    }

    /// The specific force (m/s²), as [`ImuSampleV1::angular_rate`] for the accelerometer.
    pub fn specific_force(&self) -> Option<[f64; 3]> {
        self.per_second(self.specific, Self::STATUS_ACCEL_VALID)
    }

    fn per_second(&self, v: [f64; 3], valid: u32) -> Option<[f64; 3]> {
        if self.status & valid == 0 {
            return None;
        }
        let v = if self.status & Self::STATUS_INCREMENTS != 0 {
            if self.interval_s.is_nan() || self.interval_s <= 0.0 {
                return None;
            }
            v.map(|x| x / self.interval_s)
        } else {
            v
        };
        v.iter().all(|x| x.is_finite()).then_some(v)
    }
}

message! {
    /// One Doppler velocity log ping: vehicle velocity in the DVL instrument frame, per-beam
    /// velocity and range, altitude.
    #[type_name("auvnav/DvlVelocity/v1")]
    #[schema_name("auvnav_msgs/msg/DvlVelocityV1")]
    pub struct DvlVelocityV1 {
        /// Host time (ns, CLOCK_MONOTONIC; simulated time in simulated logs) the frame's first byte arrived.
        pub host_time_ns: u64,
        /// Device clock at the ping (ns); valid with DEVICE_TIME_VALID.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Time of validity of the velocity in the host clock (ns); the driver derives it from the read time and the device's reported latency.
        pub validity_time_ns: u64,
        /// Velocity of the vehicle relative to the bottom (or water) in the DVL frame (m/s, DVL x forward, y starboard, z down, |x| < 20 m/s); valid with VELOCITY_VALID.
        pub velocity_dvl_m_s: [f64; 3],
        /// One-sigma velocity uncertainty per DVL axis (m/s, 0..10); valid with STD_VALID.
        pub velocity_std_m_s: [f64; 3],
        /// Radial velocity along each beam, positive towards the transducer (m/s, |x| < 20); beam i valid with BEAM_VELOCITY_VALID << i.
        pub beam_velocity_m_s: [f64; 4],
        /// Slant range to the bottom along each beam (m, 0..1000); beam i valid with BEAM_RANGE_VALID << i.
        pub beam_range_m: [f64; 4],
        /// Altitude above the bottom (m, 0..1000); valid with ALTITUDE_VALID.
        pub altitude_m: f64,
        /// Figure of merit / error velocity reported by the device (m/s, 0..10); valid with FOM_VALID.
        pub figure_of_merit_m_s: f64,
        /// Sound speed used by the device for the velocity (m/s, 1375..1650); valid with SOUND_SPEED_VALID.
        pub sound_speed_m_s: f64,
        /// Validity and mode bit flags (DvlVelocityV1::VALID_*, TRACK_*).
        pub validity: u32,
        /// Number of beams that contributed to the velocity (0..4).
        pub beams_used: u32,
    }
}

impl DvlVelocityV1 {
    pub const VALID_VELOCITY: u32 = 1 << 0;
    pub const VALID_ALTITUDE: u32 = 1 << 1;
    pub const VALID_STD: u32 = 1 << 2;
    pub const VALID_FOM: u32 = 1 << 3;
    pub const VALID_SOUND_SPEED: u32 = 1 << 4;
    pub const VALID_DEVICE_TIME: u32 = 1 << 5;
    /// The velocity is relative to the water (water track); clear means bottom track.
    pub const TRACK_WATER: u32 = 1 << 6;
    /// Beam i velocity valid: `VALID_BEAM_VELOCITY << i`, i in 0..4.
    pub const VALID_BEAM_VELOCITY: u32 = 1 << 8;
    /// Beam i range valid: `VALID_BEAM_RANGE << i`, i in 0..4.
    pub const VALID_BEAM_RANGE: u32 = 1 << 12;

    /// A water-track velocity: relative to the water, not to the bottom.
    pub fn is_water_track(&self) -> bool {
        self.validity & Self::TRACK_WATER != 0
    }
}

message! {
    /// One USBL acoustic fix between the docking-station array and the vehicle's responder: slant
    /// range, range differences across the hydrophone baselines, angles and the device's own fix.
    #[type_name("auvnav/UsblFix/v1")]
    #[schema_name("auvnav_msgs/msg/UsblFixV1")]
    pub struct UsblFixV1 {
        /// Host time (ns, CLOCK_MONOTONIC; simulated time in simulated logs) the frame's first byte arrived.
        pub host_time_ns: u64,
        /// Device clock at the fix (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Time of validity (signal reception at the array) in the host clock (ns).
        pub validity_time_ns: u64,
        /// Slant range from the central transducer to the responder (m, 0..10000); valid with VALID_RANGE.
        pub slant_range_m: f64,
        /// One-way acoustic travel time (s, 0..10); valid with VALID_RANGE.
        pub travel_time_s: f64,
        /// Range differences R1-R3 and R2-R4 between opposite hydrophones (m, |x| < baseline); valid with VALID_RANGE_DIFFERENCES.
        pub range_difference_m: [f64; 2],
        /// Azimuth of the responder in the array frame, from array x towards y (rad, -pi..pi); valid with VALID_ANGLES.
        pub azimuth_rad: f64,
        /// Elevation of the responder in the array frame, positive towards array -z (rad, -pi/2..pi/2); valid with VALID_ANGLES.
        pub elevation_rad: f64,
        /// Responder position computed by the device in the array frame (m, array x, y, z down, |x| < 10000); valid with VALID_POSITION.
        pub position_array_m: [f64; 3],
        /// Sound speed used by the device (m/s, 1375..1650); valid with VALID_SOUND_SPEED.
        pub sound_speed_m_s: f64,
        /// Received signal strength per hydrophone channel 1..4 (dB re device reference, -200..200); valid with VALID_RSSI.
        pub rssi_db: [f32; 4],
        /// Fit error of the direction solution reported by the device (m, 0..1000); valid with VALID_FIT_ERROR.
        pub fit_error_m: f32,
        /// Validity bit flags (UsblFixV1::VALID_*).
        pub validity: u32,
        /// Identifier of the beacon/responder (0..65535).
        pub beacon_id: u32,
        /// Reserved, zero.
        pub reserved: u32,
    }
}

impl UsblFixV1 {
    pub const VALID_RANGE: u32 = 1 << 0;
    pub const VALID_RANGE_DIFFERENCES: u32 = 1 << 1;
    pub const VALID_ANGLES: u32 = 1 << 2;
    pub const VALID_POSITION: u32 = 1 << 3;
    pub const VALID_SOUND_SPEED: u32 = 1 << 4;
    pub const VALID_RSSI: u32 = 1 << 5;
    pub const VALID_FIT_ERROR: u32 = 1 << 6;
    pub const VALID_DEVICE_TIME: u32 = 1 << 7;
}

message! {
    /// Depth from a pressure sensor.
    #[type_name("auvnav/Depth/v1")]
    #[schema_name("auvnav_msgs/msg/DepthV1")]
    pub struct DepthV1 {
        /// Host time the reading arrived (ns, CLOCK_MONOTONIC; simulated time in simulated logs): a serial frame's first byte, else the read's return.
        pub host_time_ns: u64,
        /// Device clock (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Depth of the sensor below the surface (m, positive down, -10..11000); valid with VALID_DEPTH.
        pub depth_m: f64,
        /// Gauge pressure, absolute minus atmospheric (Pa, -1e5..1.2e8); valid with VALID_PRESSURE.
        pub pressure_pa: f64,
        /// Water density assumed to convert pressure to depth (kg/m^3, 990..1050).
        pub water_density_kg_m3: f64,
        /// Water temperature (degC, -5..50); valid with VALID_TEMPERATURE.
        pub temperature_c: f32,
        /// Validity bit flags (DepthV1::VALID_*).
        pub validity: u32,
    }
}

impl DepthV1 {
    pub const VALID_DEPTH: u32 = 1 << 0;
    pub const VALID_PRESSURE: u32 = 1 << 1;
    pub const VALID_TEMPERATURE: u32 = 1 << 2;
    pub const VALID_DEVICE_TIME: u32 = 1 << 3;
}

message! {
    /// Ranges from each receiver (hydrophone) of an acoustic positioning array to the responder,
    /// with the device's own position fix: what a long- or short-baseline system such as an
    /// underwater GPS reports per acoustic update.
    #[type_name("auvnav/AcousticRanges/v1")]
    #[schema_name("auvnav_msgs/msg/AcousticRangesV1")]
    pub struct AcousticRangesV1 {
        /// Host time the reading arrived (ns, CLOCK_MONOTONIC; simulated time in simulated logs): a serial frame's first byte, else the read's return.
        pub host_time_ns: u64,
        /// Device clock (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Range from receiver i to the responder (m, 0..10000); valid with `VALID_RANGE << i`.
        pub range_m: [f64; 4],
        /// Receiver positions the device is configured with (array frame: x, y, z down, m, per receiver); valid with VALID_RECEIVER_POSITIONS.
        pub receiver_position_m: [f64; 12],
        /// The device's responder position fix in the array frame (x, y, z down, m); valid with VALID_POSITION.
        pub position_array_m: [f64; 3],
        /// One-sigma the device gives its fix (m); valid with VALID_POSITION_STD.
        pub position_std_m: f32,
        /// Noise level per receiver (dB re device reference); valid with VALID_SIGNAL.
        pub noise_db: [f32; 4],
        /// Received signal strength per receiver (dB re device reference); valid with VALID_SIGNAL.
        pub rssi_db: [f32; 4],
        /// Validity bit flags (AcousticRangesV1::VALID_*).
        pub validity: u32,
        /// Reserved, zero.
        pub reserved: [u32; 2],
    }
}

message! {
    /// Where an acoustic array is while it listens: the pose of a moving array's frame (a boat's
    /// hull with the receivers of an underwater GPS hung from it, or the transducer of a ship
    /// ranging to a single beacon) from the boat's GNSS and heading. The receivers' offsets in
    /// that frame come from the navigator's configuration or from `AcousticRangesV1`.
    #[type_name("auvnav/AcousticArrayPose/v1")]
    #[schema_name("auvnav_msgs/msg/AcousticArrayPoseV1")]
    pub struct AcousticArrayPoseV1 {
        /// Host time the reading arrived (ns, CLOCK_MONOTONIC; simulated time in simulated logs).
        pub host_time_ns: u64,
        /// Device clock (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Geodetic latitude of the array frame's origin, WGS-84 (rad, -pi/2..pi/2); valid with VALID_POSITION.
        pub latitude_rad: f64,
        /// Longitude of the array frame's origin, WGS-84 (rad, -pi..pi); valid with VALID_POSITION.
        pub longitude_rad: f64,
        /// Height of the origin above the WGS-84 ellipsoid (m, -1000..10000); valid with VALID_HEIGHT (else the surface: 0).
        pub height_m: f64,
        /// Roll, pitch, heading of the array frame w.r.t. north-east-down (rad, ZYX Euler angles; heading -pi..2pi); heading valid with VALID_HEADING, roll and pitch with VALID_TILT (else level).
        pub euler_rad: [f64; 3],
        /// One-sigma horizontal position uncertainty (m, 0..1000); valid with VALID_STD.
        pub horizontal_std_m: f32,
        /// One-sigma heading uncertainty (rad, 0..pi); valid with VALID_STD.
        pub heading_std_rad: f32,
        /// Validity bit flags (AcousticArrayPoseV1::VALID_*).
        pub validity: u32,
        /// Reserved, zero.
        pub reserved: u32,
    }
}

impl AcousticArrayPoseV1 {
    pub const VALID_POSITION: u32 = 1 << 0;
    pub const VALID_HEIGHT: u32 = 1 << 1;
    pub const VALID_HEADING: u32 = 1 << 2;
    pub const VALID_TILT: u32 = 1 << 3;
    pub const VALID_STD: u32 = 1 << 4;
    pub const VALID_DEVICE_TIME: u32 = 1 << 5;
}

impl AcousticRangesV1 {
    /// Range of receiver i valid: `VALID_RANGE << i`, i in 0..4.
    pub const VALID_RANGE: u32 = 1 << 0;
    pub const VALID_POSITION: u32 = 1 << 4;
    pub const VALID_POSITION_STD: u32 = 1 << 5;
    pub const VALID_SIGNAL: u32 = 1 << 6;
    pub const VALID_RECEIVER_POSITIONS: u32 = 1 << 7;
    pub const VALID_DEVICE_TIME: u32 = 1 << 8;

    /// Whether receiver `i`'s range is valid.
    pub fn range_valid(&self, i: usize) -> bool {
        i < 4 && self.validity & (Self::VALID_RANGE << i) != 0
    }
}

message! {
    /// Magnetic flux density measured by a three-axis magnetometer.
    #[type_name("auvnav/Magnetometer/v1")]
    #[schema_name("auvnav_msgs/msg/MagnetometerV1")]
    pub struct MagnetometerV1 {
        /// Host time (ns, CLOCK_MONOTONIC; simulated time in simulated logs) the frame's first byte arrived.
        pub host_time_ns: u64,
        /// Device clock (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Magnetic flux density in the sensor frame, uncalibrated (T, body FRD, |x| < 1e-3); valid with VALID_FIELD.
        pub field_t: [f64; 3],
        /// Sensor temperature (degC, -60..120); valid with VALID_TEMPERATURE.
        pub temperature_c: f32,
        /// Validity bit flags (MagnetometerV1::VALID_*).
        pub validity: u32,
    }
}

impl MagnetometerV1 {
    pub const VALID_FIELD: u32 = 1 << 0;
    pub const VALID_TEMPERATURE: u32 = 1 << 1;
    pub const VALID_DEVICE_TIME: u32 = 1 << 2;
}

message! {
    /// Heading, pitch and roll from a compass or an AHRS (no IMU samples): what a boat's ADCP, a
    /// small vehicle without an inertial unit, or an autopilot reports as its attitude.
    #[type_name("auvnav/Attitude/v1")]
    #[schema_name("auvnav_msgs/msg/AttitudeV1")]
    pub struct AttitudeV1 {
        /// Host time the reading arrived (ns, CLOCK_MONOTONIC; simulated time in simulated logs): a serial frame's first byte, else the read's return.
        pub host_time_ns: u64,
        /// Device clock (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Roll, pitch, heading of the body w.r.t. north-east-down (rad, ZYX Euler angles; heading -pi..2pi); valid with VALID_ATTITUDE.
        pub euler_rad: [f64; 3],
        /// Declination the device added to its magnetic heading (rad, east positive, -pi..pi); valid with HEADING_TRUE.
        pub declination_rad: f64,
        /// One-sigma heading uncertainty (rad, 0..pi); valid with VALID_STD.
        pub heading_std_rad: f64,
        /// Validity bit flags (AttitudeV1::VALID_*, HEADING_*).
        pub validity: u32,
        /// Padding (0).
        pub reserved: u32,
    }
}

impl AttitudeV1 {
    pub const VALID_ATTITUDE: u32 = 1 << 0;
    pub const VALID_STD: u32 = 1 << 1;
    pub const VALID_DEVICE_TIME: u32 = 1 << 2;
    /// The heading is referred to true north (the device added `declination_rad` to a magnetic
    /// heading, or measured true heading); clear: magnetic.
    pub const HEADING_TRUE: u32 = 1 << 3;
}

message! {
    /// The speed of sound in the water from a CTD or sound-velocity probe.
    #[type_name("auvnav/SoundVelocity/v1")]
    #[schema_name("auvnav_msgs/msg/SoundVelocityV1")]
    pub struct SoundVelocityV1 {
        /// Host time the reading arrived (ns, CLOCK_MONOTONIC; simulated time in simulated logs): a serial frame's first byte, else the read's return.
        pub host_time_ns: u64,
        /// Device clock (ns); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Speed of sound (m/s, 1375..1650); valid with VALID_SOUND_SPEED.
        pub sound_speed_m_s: f64,
        /// Practical salinity (PSU, 0..45); valid with VALID_SALINITY.
        pub salinity_psu: f64,
        /// Gauge pressure (Pa, -1e5..1.2e8); valid with VALID_PRESSURE.
        pub pressure_pa: f64,
        /// Water temperature (degC, -5..50); valid with VALID_TEMPERATURE.
        pub temperature_c: f32,
        /// Validity bit flags (SoundVelocityV1::VALID_*).
        pub validity: u32,
    }
}

impl SoundVelocityV1 {
    pub const VALID_SOUND_SPEED: u32 = 1 << 0;
    pub const VALID_SALINITY: u32 = 1 << 1;
    pub const VALID_PRESSURE: u32 = 1 << 2;
    pub const VALID_TEMPERATURE: u32 = 1 << 3;
    pub const VALID_DEVICE_TIME: u32 = 1 << 4;
}

message! {
    /// A GNSS position fix (available at the surface only).
    #[type_name("auvnav/GnssFix/v1")]
    #[schema_name("auvnav_msgs/msg/GnssFixV1")]
    pub struct GnssFixV1 {
        /// Host time (ns, CLOCK_MONOTONIC; simulated time in simulated logs) the frame's first byte arrived.
        pub host_time_ns: u64,
        /// GNSS time of the fix (ns since the GPS epoch); valid with VALID_DEVICE_TIME.
        pub device_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Geodetic latitude, WGS-84 (rad, -pi/2..pi/2); valid with VALID_POSITION.
        pub latitude_rad: f64,
        /// Longitude, WGS-84 (rad, -pi..pi); valid with VALID_POSITION.
        pub longitude_rad: f64,
        /// Height above the WGS-84 ellipsoid (m, -1000..10000); valid with VALID_HEIGHT.
        pub height_m: f64,
        /// Velocity (m/s, NED, |x| < 100); valid with VALID_VELOCITY.
        pub velocity_ned_m_s: [f64; 3],
        /// One-sigma horizontal position uncertainty (m, 0..1000).
        pub horizontal_std_m: f64,
        /// One-sigma vertical position uncertainty (m, 0..1000).
        pub vertical_std_m: f64,
        /// Number of satellites used (0..255).
        pub satellites: u32,
        /// Validity bit flags (GnssFixV1::VALID_*).
        pub validity: u32,
    }
}

impl GnssFixV1 {
    pub const VALID_POSITION: u32 = 1 << 0;
    pub const VALID_HEIGHT: u32 = 1 << 1;
    pub const VALID_VELOCITY: u32 = 1 << 2;
    pub const VALID_DEVICE_TIME: u32 = 1 << 3;
    /// The fix is differentially corrected (DGNSS or RTK).
    pub const DIFFERENTIAL: u32 = 1 << 4;
}

/// True when every value in `groups` is finite; without a branch per value, for checks that run
/// at the IMU rate.
pub fn all_finite(groups: &[&[f64]]) -> bool {
    groups
        .iter()
        .fold(true, |ok, g| g.iter().fold(ok, |ok, x| ok & x.is_finite()))
}

/// The operating mode of the navigation solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum NavMode {
    /// Waiting for the first sensor data; the solution is not usable.
    Initialising = 0,
    /// Initial alignment in progress; attitude (heading) not yet converged.
    Aligning = 1,
    /// Aligned and aided.
    Navigating = 2,
    /// Aligned, but an aiding source it relies on is lost: pure inertial or partly aided.
    Degraded = 3,
    /// The filter refused a state or covariance that was not finite or not a covariance: this
    /// solution is the last sound state coasted to now, and the filter restarts from it with its
    /// covariance grown (do not use the solution to steer by; the next ones say how good they are).
    Invalid = 4,
    /// The horizontal position standard deviation exceeds the configured limit
    /// (`navigation.position_unknown_std_m`): after a restart without a usable checkpoint, a long
    /// IMU gap or a reinitialisation, until a position aid (USBL, GNSS) fixes it.
    PositionUnknown = 5,
}

impl TryFrom<u32> for NavMode {
    type Error = u32;
    fn try_from(v: u32) -> Result<Self, u32> {
        match v {
            0 => Ok(NavMode::Initialising),
            1 => Ok(NavMode::Aligning),
            2 => Ok(NavMode::Navigating),
            3 => Ok(NavMode::Degraded),
            4 => Ok(NavMode::Invalid),
            5 => Ok(NavMode::PositionUnknown),
            other => Err(other),
        }
    }
}

message! {
    /// The navigation solution of the fusion core: position, velocity, attitude of the body (IMU)
    /// frame, their uncertainties, estimated sensor biases, mode and sensor health.
    #[type_name("auvnav/NavSolution/v1")]
    #[schema_name("auvnav_msgs/msg/NavSolutionV1")]
    pub struct NavSolutionV1 {
        /// Time of validity in the host clock (ns).
        pub host_time_ns: u64,
        /// Sequence number of the solution.
        pub sequence: u64,
        /// Geodetic latitude, WGS-84 (rad, -pi/2..pi/2).
        pub latitude_rad: f64,
        /// Longitude, WGS-84 (rad, -pi..pi).
        pub longitude_rad: f64,
        /// Height above the WGS-84 ellipsoid (m, -11000..10000); depth is approximately -height.
        pub height_m: f64,
        /// Velocity w.r.t. the Earth (m/s, NED, |x| < 100).
        pub velocity_ned_m_s: [f64; 3],
        /// Attitude quaternion rotating body FRD to NED, scalar first (w, x, y, z), unit norm.
        pub quaternion_body_to_ned: [f64; 4],
        /// Roll, pitch, yaw (ZYX Euler angles) of body FRD w.r.t. NED (rad; roll, yaw -pi..pi, pitch -pi/2..pi/2).
        pub euler_rad: [f64; 3],
        /// One-sigma position uncertainty north, east, down (m, >= 0).
        pub position_std_ned_m: [f64; 3],
        /// One-sigma velocity uncertainty (m/s, NED, >= 0).
        pub velocity_std_ned_m_s: [f64; 3],
        /// One-sigma attitude uncertainty, small-angle tilt about N, E and D (rad, >= 0).
        pub attitude_std_rad: [f64; 3],
        /// Estimated gyro bias (rad/s, body FRD).
        pub gyro_bias_rad_s: [f64; 3],
        /// Estimated accelerometer bias (m/s^2, body FRD).
        pub accel_bias_m_s2: [f64; 3],
        /// Mode (NavMode: 0 initialising, 1 aligning, 2 navigating, 3 degraded, 4 invalid (reinitialising), 5 position unknown).
        pub mode: u32,
        /// Sensor health bit flags (NavSolutionV1::HEALTH_*): set = the sensor delivers and is fused.
        pub sensor_health: u32,
    }
}

impl NavSolutionV1 {
    pub const HEALTH_IMU: u32 = 1 << 0;
    pub const HEALTH_DVL: u32 = 1 << 1;
    pub const HEALTH_USBL: u32 = 1 << 2;
    pub const HEALTH_DEPTH: u32 = 1 << 3;
    pub const HEALTH_MAGNETOMETER: u32 = 1 << 4;
    pub const HEALTH_GNSS: u32 = 1 << 5;

    /// True when every floating-point field is finite (what a consumer may steer by).
    pub fn all_finite(&self) -> bool {
        all_finite(&[
            &[self.latitude_rad, self.longitude_rad, self.height_m],
            &self.velocity_ned_m_s,
            &self.quaternion_body_to_ned,
            &self.euler_rad,
            &self.position_std_ned_m,
            &self.velocity_std_ned_m_s,
            &self.attitude_std_rad,
            &self.gyro_bias_rad_s,
            &self.accel_bias_m_s2,
        ])
    }

    /// The mode field as a [`NavMode`], or the raw value when it is out of range.
    pub fn nav_mode(&self) -> Result<NavMode, u32> {
        NavMode::try_from(self.mode)
    }
}

/// The aiding source a diagnostics message reports on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum AidSource {
    DvlVelocity = 1,
    Depth = 2,
    GnssPosition = 3,
    UsblPosition = 4,
    UsblSlantRange = 5,
    ZeroVelocity = 6,
    Magnetometer = 7,
    /// One range of an acoustic system (LBL beacon, a receiver of a moving array, a single beacon).
    AcousticRange = 8,
    /// One range difference between two receivers of an acoustic array (a docking station's
    /// hydrophones, fused by the range aid).
    AcousticRangeDifference = 9,
}

impl TryFrom<u32> for AidSource {
    type Error = u32;
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            1 => AidSource::DvlVelocity,
            2 => AidSource::Depth,
            3 => AidSource::GnssPosition,
            4 => AidSource::UsblPosition,
            5 => AidSource::UsblSlantRange,
            6 => AidSource::ZeroVelocity,
            7 => AidSource::Magnetometer,
            8 => AidSource::AcousticRange,
            9 => AidSource::AcousticRangeDifference,
            other => return Err(other),
        })
    }
}

message! {
    /// What the filter did with one measurement of one aiding source (up to 3 components).
    #[type_name("auvnav/AidDiagnostics/v1")]
    #[schema_name("auvnav_msgs/msg/AidDiagnosticsV1")]
    pub struct AidDiagnosticsV1 {
        /// Time of validity of the measurement in the host clock (ns).
        pub host_time_ns: u64,
        /// Sequence number of the diagnostics message.
        pub sequence: u64,
        /// Observation components (unit of the source: m/s for velocity, m for range/position/depth); first `dimension` used.
        pub observation: [f64; 3],
        /// Observation noise variance per component (unit^2, > 0).
        pub observation_variance: [f64; 3],
        /// Innovation, observation minus prediction, per component (unit of the source).
        pub innovation: [f64; 3],
        /// Innovation variance per component, diagonal of H P H^T + R (unit^2, > 0).
        pub innovation_variance: [f64; 3],
        /// Normalised innovation squared divided by the gate (dimensionless, >= 0; > 1 means rejected by the gate).
        pub test_ratio: f64,
        /// Aid source (AidSource: 1 DVL velocity, 2 depth, 3 GNSS, 4 USBL position, 5 USBL slant range, 6 zero velocity, 7 magnetometer).
        pub source: u32,
        /// Number of components used (1..3).
        pub dimension: u32,
        /// Flags (AidDiagnosticsV1::FLAG_*).
        pub flags: u32,
        /// Reserved, zero.
        pub reserved: u32,
    }
}

impl AidDiagnosticsV1 {
    /// The measurement was rejected (gate, invalid data or a numerical failure).
    pub const FLAG_REJECTED: u32 = 1 << 0;
    /// The measurement was fused into the state.
    pub const FLAG_FUSED: u32 = 1 << 1;
    /// The aid had been rejected for too long: the covariance of the states it observes was
    /// re-opened before this measurement was fused.
    pub const FLAG_RESET: u32 = 1 << 2;
    /// The DVL velocity was corrected from the sound speed the DVL assumed to the true one
    /// (`dvl_sound_speed_source`); the observation is the corrected velocity.
    pub const FLAG_SOUND_SPEED_CORRECTED: u32 = 1 << 3;
    /// A DVL water-track velocity (relative to the water), fused with the water-current states.
    pub const FLAG_WATER_TRACK: u32 = 1 << 4;
    /// A DVL reading fused from its beam (radial) velocities, each gated alone (`dimension`
    /// beams accepted).
    pub const FLAG_BEAMS: u32 = 1 << 5;
}

/// The state of a process as reported in its health message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ProcessState {
    Starting = 0,
    Running = 1,
    /// The device is absent or silent; the process is trying to reconnect.
    Reconnecting = 2,
    Stopping = 3,
}

message! {
    /// Health counters of one process (driver, daemon or recorder), published periodically.
    #[type_name("auvnav/ProcessHealth/v1")]
    #[schema_name("auvnav_msgs/msg/ProcessHealthV1")]
    pub struct ProcessHealthV1 {
        /// Host time of the report (ns, CLOCK_MONOTONIC).
        pub host_time_ns: u64,
        /// Sequence number of the report.
        pub sequence: u64,
        /// Frames decoded and published since start (count).
        pub frames: u64,
        /// Frames dropped for a checksum mismatch (count).
        pub checksum_errors: u64,
        /// Resynchronisations of the byte stream (count).
        pub resyncs: u64,
        /// Bytes skipped while searching for a frame start (count).
        pub bytes_skipped: u64,
        /// Read timeouts / missed deadlines (count).
        pub timeouts: u64,
        /// Reconnections to the device (count).
        pub reconnects: u64,
        /// Messages dropped: sequence gaps, full buffers, late messages (count).
        pub drops: u64,
        /// Frames or messages rejected as malformed or out of range (count).
        pub invalid: u64,
        /// Process name, UTF-8, zero padded.
        pub name: [u8; 32],
        /// Process id (0..2^32).
        pub pid: u32,
        /// State (ProcessState: 0 starting, 1 running, 2 reconnecting, 3 stopping).
        pub state: u32,
    }
}

impl ProcessHealthV1 {
    /// Copies `name` into the fixed field, truncated at a character boundary to 32 bytes.
    pub fn set_name(&mut self, name: &str) {
        self.name = [0; 32];
        let mut end = name.len().min(32);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        self.name[..end].copy_from_slice(&name.as_bytes()[..end]);
    }
    /// The process name (up to the first zero byte; invalid UTF-8 is replaced).
    pub fn name(&self) -> String {
        let end = self.name.iter().position(|&b| b == 0).unwrap_or(32);
        String::from_utf8_lossy(&self.name[..end]).into_owned()
    }
}

message! {
    /// The true vehicle state of a simulated voyage (log channel only; never published on board).
    #[type_name("auvnav/TruthState/v1")]
    #[schema_name("auvnav_msgs/msg/TruthStateV1")]
    pub struct TruthStateV1 {
        /// Simulated time (ns).
        pub host_time_ns: u64,
        /// Sequence number.
        pub sequence: u64,
        /// Geodetic latitude of the body (IMU) origin, WGS-84 (rad).
        pub latitude_rad: f64,
        /// Longitude, WGS-84 (rad).
        pub longitude_rad: f64,
        /// Height above the WGS-84 ellipsoid (m).
        pub height_m: f64,
        /// Velocity w.r.t. the Earth (m/s, NED).
        pub velocity_ned_m_s: [f64; 3],
        /// Attitude quaternion body FRD to NED, scalar first.
        pub quaternion_body_to_ned: [f64; 4],
        /// Roll, pitch, yaw (ZYX Euler) (rad).
        pub euler_rad: [f64; 3],
        /// True angular rate of the body w.r.t. inertial space (rad/s, body FRD).
        pub angular_rate_rad_s: [f64; 3],
        /// True specific force (m/s^2, body FRD).
        pub specific_force_m_s2: [f64; 3],
    }
}

message! {
    /// An aid message the fusion daemon applied late: it arrived after the IMU stream had passed
    /// its time stamp + the aid delay, and was applied just before the next IMU sample instead.
    /// Recorded so that a replay of the log applies it at the same point of the IMU stream.
    #[type_name("auvnav/LateAid/v1")]
    #[schema_name("auvnav_msgs/msg/LateAidV1")]
    pub struct LateAidV1 {
        /// Host time of the IMU sample before which the aid was applied (ns, CLOCK_MONOTONIC).
        pub host_time_ns: u64,
        /// Sequence number of this record.
        pub sequence: u64,
        /// Sequence number of that IMU sample.
        pub imu_sequence: u64,
        /// Host time stamp of the aid message (ns).
        pub aid_host_time_ns: u64,
        /// Sequence number of the aid message (assigned by its publisher).
        pub aid_sequence: u64,
        /// The aid's topic (LateAidV1::TOPIC_*: 1 DVL, 2 depth, 3 GNSS, 4 USBL, 5 magnetometer, 6 sound velocity, 7 acoustic ranges, 8 acoustic array pose).
        pub aid_topic: u32,
        /// Reserved, zero.
        pub reserved: u32,
    }
}

impl LateAidV1 {
    pub const TOPIC_DVL: u32 = 1;
    pub const TOPIC_DEPTH: u32 = 2;
    pub const TOPIC_GNSS: u32 = 3;
    pub const TOPIC_USBL: u32 = 4;
    pub const TOPIC_MAGNETOMETER: u32 = 5;
    pub const TOPIC_SOUND_VELOCITY: u32 = 6;
    pub const TOPIC_ACOUSTIC_RANGES: u32 = 7;
    pub const TOPIC_ACOUSTIC_ARRAY_POSE: u32 = 8;
}

message! {
    /// A moment of the fusion daemon's session that a replay must know to reproduce it: where a
    /// daemon process started its session (from the configuration, or continued from a
    /// checkpoint after a restart), and each checkpoint it took. Recorded so that a replay of a
    /// recording that spans a restart starts a new session where the daemon did, from the same
    /// checkpoint.
    #[type_name("auvnav/SessionEvent/v1")]
    #[schema_name("auvnav_msgs/msg/SessionEventV1")]
    pub struct SessionEventV1 {
        /// Host time of the IMU sample it happened at (ns, CLOCK_MONOTONIC): the session's first
        /// sample for a start, the last sample in the state for a checkpoint.
        pub host_time_ns: u64,
        /// Sequence number of this record.
        pub sequence: u64,
        /// What happened (SessionEventV1::KIND_*: 1 started from the configuration, 2 continued
        /// from a checkpoint, 3 checkpoint taken).
        pub kind: u32,
        /// Reserved, zero.
        pub reserved: u32,
        /// For a continued start: the host time of the checkpoint's last IMU sample (ns).
        pub checkpoint_time_ns: u64,
        /// For a continued start: how long before the start the checkpoint was written (s), over
        /// which its covariance was grown.
        pub elapsed_s: f64,
        /// For a continued start: the drift the covariance was grown by (m/s).
        pub drift_m_s: f64,
        /// For a start: the initial position's standard deviation the session used (m; the
        /// configuration's, or the wider one of a start with the position unknown).
        pub initial_position_std_m: f64,
    }
}

impl SessionEventV1 {
    pub const KIND_STARTED: u32 = 1;
    pub const KIND_CONTINUED: u32 = 2;
    pub const KIND_CHECKPOINT: u32 = 3;
}

/// Bytes per [`RawBytesV1`] message.
pub const RAW_CHUNK: usize = 1024;

message! {
    /// A chunk of the bytes a driver read from its device, exactly as read, for the recorder
    /// (raw capture). A read longer than the chunk size is split into consecutive messages with the
    /// same host time.
    #[type_name("auvnav/RawBytes/v1")]
    #[schema_name("auvnav_msgs/msg/RawBytesV1")]
    pub struct RawBytesV1 {
        /// Host time at read return (ns, CLOCK_MONOTONIC).
        pub host_time_ns: u64,
        /// Sequence number assigned by the publisher.
        pub sequence: u64,
        /// Number of valid bytes in `data` (0..1024).
        pub length: u32,
        /// Reserved, zero.
        pub reserved: u32,
        /// The bytes; only the first `length` are valid.
        pub data: [u8; 1024],
    }
}

impl RawBytesV1 {
    /// The valid bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.data[..(self.length as usize).min(RAW_CHUNK)]
    }
}

/// Every message type with its log schema, for tools that list or validate schemas.
pub fn all_schemas() -> Vec<(&'static str, &'static str, String)> {
    fn entry<T: Message>() -> (&'static str, &'static str, String) {
        (T::TYPE_NAME, T::SCHEMA_NAME, T::ros2msg_definition())
    }
    vec![
        entry::<ImuSampleV1>(),
        entry::<DvlVelocityV1>(),
        entry::<UsblFixV1>(),
        entry::<DepthV1>(),
        entry::<MagnetometerV1>(),
        entry::<AcousticRangesV1>(),
        entry::<AcousticArrayPoseV1>(),
        entry::<GnssFixV1>(),
        entry::<NavSolutionV1>(),
        entry::<SoundVelocityV1>(),
        entry::<AttitudeV1>(),
        entry::<AidDiagnosticsV1>(),
        entry::<ProcessHealthV1>(),
        entry::<LateAidV1>(),
        entry::<SessionEventV1>(),
        entry::<TruthStateV1>(),
        entry::<RawBytesV1>(),
    ]
}

#[cfg(test)]
mod tests {
    use super::ImuSampleV1;

    /// Increments are divided by their interval, rates taken as they are; an invalid triad, an
    /// increment over no interval and a value that is not finite give nothing.
    #[test]
    fn imu_rates_from_rates_or_increments() {
        let valid = ImuSampleV1::STATUS_GYRO_VALID | ImuSampleV1::STATUS_ACCEL_VALID;
        let rates = ImuSampleV1 {
            angular: [0.1, -0.2, 0.3],
            specific: [0.0, 0.0, -9.8],
            interval_s: 0.01,
            status: valid,
            ..Default::default()
        };
        assert_eq!(rates.angular_rate(), Some([0.1, -0.2, 0.3]));
        assert_eq!(rates.specific_force(), Some([0.0, 0.0, -9.8]));
        let increments = ImuSampleV1 {
            angular: [0.001, -0.002, 0.003],
            specific: [0.0, 0.0, -0.098],
            status: valid | ImuSampleV1::STATUS_INCREMENTS,
            ..rates
        };
        let w = increments.angular_rate().expect("rate");
        let f = increments.specific_force().expect("force");
        assert!((w[1] + 0.2).abs() < 1e-12 && (f[2] + 9.8).abs() < 1e-12);
        let no_interval = ImuSampleV1 {
            interval_s: 0.0,
            ..increments
        };
        assert_eq!(no_interval.angular_rate(), None);
        let gyro_invalid = ImuSampleV1 {
            status: ImuSampleV1::STATUS_ACCEL_VALID,
            ..rates
        };
        assert_eq!(gyro_invalid.angular_rate(), None);
        assert!(gyro_invalid.specific_force().is_some());
        let not_finite = ImuSampleV1 {
            specific: [f64::NAN, 0.0, -9.8],
            ..rates
        };
        assert_eq!(not_finite.specific_force(), None);
    }
}
