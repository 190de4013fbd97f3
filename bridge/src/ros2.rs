//! ROS 2 over Zenoh as `rmw_zenoh_cpp` speaks it, so that a ROS 2 graph running rmw_zenoh sees
//! auvnav's solution, IMU, DVL and health as ROS topics, with no ROS install on the vehicle.
//!
//! **The wire** (rmw_zenoh_cpp 0.2+, ROS 2 Jazzy and later, `docs/design.md` and
//! `liveliness_utils.cpp` of ros2/rmw_zenoh):
//! - data key expression `<domain_id>/<topic without leading and trailing slashes>/<DDS type
//!   name>/<type hash>`, e.g. `0/auvnav/odometry/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc9…`;
//! - payload: CDR, little-endian, with the 4-byte encapsulation header `00 01 00 00`;
//! - attachment: Zenoh's serialization of `"sequence_number"`, i64, `"source_timestamp"`, i64
//!   (ns since 1970), `"source_gid"`, 16 bytes;
//! - liveliness tokens `@ros2_lv/<domain>/<zid>/<nid>/<id>/<NN|MP>/<enclave>/<namespace>/<node>`
//!   and, for a publisher, `/<topic>/<type>/<hash>/<qos>`, with `/` in names written `%` and the
//!   QoS as rmw_zenoh's differences from its defaults (keep-last 42, reliable, transient-local);
//! - type hashes: REP-2011's RIHS01 (SHA-256 of the type description), checked in the tests
//!   against an independent implementation (the `rosbags` Python package).
//!
//! **Frames** (REP-103, REP-105): auvnav works in NED with FRD body axes; ROS in ENU with FLU
//! body axes. The conversion happens here, at the edge, and nowhere else: position
//! `(x, y, z)_ENU = (E, N, −D)` from the origin (the first aligned solution), attitude
//! `R_ENU←FLU = M · R_NED←FRD · F` with `M` swapping north and east and negating down and
//! `F = diag(1, −1, −1)`, body vectors `(x, −y, −z)`. `Odometry` is `map` → `base_link` with the
//! twist in `base_link`; `NavSatFix` carries latitude, longitude and ellipsoid height with the ENU
//! position covariance; `Imu` (`imu/data_raw`: no orientation, `orientation_covariance[0] = −1`)
//! and the DVL's `TwistWithCovarianceStamped` are in their devices' frames, FLU.
//!
//! Long on purpose: the last 60 lines are the unit tests, beside the code they test; the code is
//! 543 lines.

use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, NavMode, NavSolutionV1, ProcessHealthV1};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// `[ros2]` of the bridge's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Config {
    /// ROS domain id (`ROS_DOMAIN_ID`, 0..=232, default 0).
    pub domain_id: u32,
    /// Namespace of the node and its topics (default `/auvnav`).
    pub namespace: String,
    /// Node name (default `auvnav_bridge`).
    pub node: String,
    /// Frames (REP-105): the fixed ENU frame of `Odometry` (its origin is the first aligned
    /// solution), the vehicle's, the IMU's and the DVL's (default `map`, `base_link`,
    /// `imu_link`, `dvl_link`).
    pub map_frame: String,
    pub base_frame: String,
    pub imu_frame: String,
    pub dvl_frame: String,
    /// `odometry` and `fix` at most this often (Hz, 0.1..=1000, default 50).
    pub solution_rate_hz: f64,
    /// Publish `imu/data_raw`, `dvl/twist` and `/diagnostics` (default true each).
    pub imu: bool,
    pub dvl: bool,
    pub diagnostics: bool,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Ros2Config {
            domain_id: 0,
            namespace: "/auvnav".into(),
            node: "auvnav_bridge".into(),
            map_frame: "map".into(),
            base_frame: "base_link".into(),
            imu_frame: "imu_link".into(),
            dvl_frame: "dvl_link".into(),
            solution_rate_hz: 50.0,
            imu: true,
            dvl: true,
            diagnostics: true,
        }
    }
}

fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/')
        && !s.contains("//")
}

impl Ros2Config {
    /// Range and name checks; the message names the key.
    pub fn check(&self) -> Result<(), String> {
        if self.domain_id > 232 {
            return Err(format!(
                "ros2.domain_id = {}: expected 0..=232",
                self.domain_id
            ));
        }
        if !(self.namespace.starts_with('/') && valid_name(&self.namespace)) {
            return Err(format!(
                "ros2.namespace = {:?}: expected an absolute ROS namespace such as \"/auvnav\"",
                self.namespace
            ));
        }
        for (key, v) in [
            ("ros2.node", &self.node),
            ("ros2.map_frame", &self.map_frame),
            ("ros2.base_frame", &self.base_frame),
            ("ros2.imu_frame", &self.imu_frame),
            ("ros2.dvl_frame", &self.dvl_frame),
        ] {
            if !valid_name(v) || v.contains('/') {
                return Err(format!("{key} = {v:?}: expected letters, digits and '_'"));
            }
        }
        if !(self.solution_rate_hz.is_finite() && (0.1..=1000.0).contains(&self.solution_rate_hz)) {
            return Err(format!(
                "ros2.solution_rate_hz = {}: expected 0.1..=1000 Hz",
                self.solution_rate_hz
            ));
        }
        Ok(())
    }

    /// A topic of the node's namespace (`odometry` → `/auvnav/odometry`).
    pub fn topic(&self, name: &str) -> String {
        if name.starts_with('/') {
            name.to_string()
        } else {
            format!("{}/{name}", self.namespace.trim_end_matches('/'))
        }
    }
}

/// A ROS message type: its name, the DDS name rmw_zenoh uses in key expressions, and its
/// RIHS01 type hash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RosType {
    pub name: &'static str,
    pub dds_name: &'static str,
    pub hash: &'static str,
}

pub const ODOMETRY: RosType = RosType {
    name: "nav_msgs/msg/Odometry",
    dds_name: "nav_msgs::msg::dds_::Odometry_",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
};
pub const NAV_SAT_FIX: RosType = RosType {
    name: "sensor_msgs/msg/NavSatFix",
    dds_name: "sensor_msgs::msg::dds_::NavSatFix_",
    hash: "RIHS01_62223ab3fe210a15976021da7afddc9e200dc9ec75231c1b6a557fc598a65404",
};
pub const IMU: RosType = RosType {
    name: "sensor_msgs/msg/Imu",
    dds_name: "sensor_msgs::msg::dds_::Imu_",
    hash: "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
};
pub const TWIST_WITH_COVARIANCE_STAMPED: RosType = RosType {
    name: "geometry_msgs/msg/TwistWithCovarianceStamped",
    dds_name: "geometry_msgs::msg::dds_::TwistWithCovarianceStamped_",
    hash: "RIHS01_77b67434531e6529b7a0091357b186b6ebdb17fd9ffd3e0c7ce9d3fb11a44563",
};
pub const DIAGNOSTIC_ARRAY: RosType = RosType {
    name: "diagnostic_msgs/msg/DiagnosticArray",
    dds_name: "diagnostic_msgs::msg::dds_::DiagnosticArray_",
    hash: "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
};

pub const ALL_TYPES: [RosType; 5] = [
    ODOMETRY,
    NAV_SAT_FIX,
    IMU,
    TWIST_WITH_COVARIANCE_STAMPED,
    DIAGNOSTIC_ARRAY,
];

/// The data key expression of `topic` (a fully qualified ROS name).
pub fn data_key(domain_id: u32, topic: &str, t: &RosType) -> String {
    format!(
        "{domain_id}/{}/{}/{}",
        topic.trim_matches('/'),
        t.dds_name,
        t.hash
    )
}

/// `/` written `%` (rmw_zenoh's name mangling in liveliness tokens).
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// The QoS part of a publisher's liveliness token: keep-last `depth`, reliable, volatile, the
/// rest at rmw_zenoh's defaults (which are keep-last 42, reliable, transient-local).
pub fn qos_key(depth: u32) -> String {
    format!(
        ":2:,{}:,:,:,,",
        if depth == 42 {
            String::new()
        } else {
            depth.to_string()
        }
    )
}

/// The node's liveliness token (`NN`).
pub fn node_token(cfg: &Ros2Config, zid: &str, node_id: u32) -> String {
    format!(
        "@ros2_lv/{}/{zid}/{node_id}/{node_id}/NN/%/{}/{}",
        cfg.domain_id,
        mangle(&cfg.namespace),
        mangle(&cfg.node)
    )
}

/// A publisher's liveliness token (`MP`).
pub fn publisher_token(
    cfg: &Ros2Config,
    zid: &str,
    node_id: u32,
    id: u32,
    topic: &str,
    t: &RosType,
    depth: u32,
) -> String {
    format!(
        "@ros2_lv/{}/{zid}/{node_id}/{id}/MP/%/{}/{}/{}/{}/{}/{}",
        cfg.domain_id,
        mangle(&cfg.namespace),
        mangle(&cfg.node),
        mangle(topic),
        mangle(t.dds_name),
        t.hash,
        qos_key(depth)
    )
}

/// The 16-byte id of a publisher, from its liveliness token (rmw_zenoh hashes the token too).
pub fn gid(token: &str) -> [u8; 16] {
    use std::hash::{Hash, Hasher};
    let mut out = [0u8; 16];
    for (k, half) in out.chunks_mut(8).enumerate() {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (k, token).hash(&mut h);
        half.copy_from_slice(&h.finish().to_le_bytes());
    }
    out
}

/// The attachment of a sample (Zenoh's serialization: a string is its LEB128 length and bytes,
/// an i64 8 bytes little-endian, a fixed array its elements).
pub fn attachment(sequence: i64, source_timestamp_ns: i64, gid: &[u8; 16]) -> Vec<u8> {
    fn string(out: &mut Vec<u8>, s: &str) {
        let mut n = s.len();
        loop {
            let byte = (n & 0x7f) as u8;
            n >>= 7;
            if n == 0 {
                out.push(byte);
                break;
            }
            out.push(byte | 0x80);
        }
        out.extend_from_slice(s.as_bytes());
    }
    let mut out = Vec::with_capacity(64);
    string(&mut out, "sequence_number");
    out.extend_from_slice(&sequence.to_le_bytes());
    string(&mut out, "source_timestamp");
    out.extend_from_slice(&source_timestamp_ns.to_le_bytes());
    string(&mut out, "source_gid");
    out.extend_from_slice(gid);
    out
}

/// A little-endian CDR writer (XCDR1, as ROS 2 uses it): alignment is counted from the end of
/// the encapsulation header.
pub struct Cdr {
    buf: Vec<u8>,
}

impl Default for Cdr {
    fn default() -> Self {
        Self::new()
    }
}

impl Cdr {
    pub fn new() -> Cdr {
        Cdr {
            buf: vec![0x00, 0x01, 0x00, 0x00],
        }
    }
    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }
    pub fn i8(&mut self, v: i8) -> &mut Self {
        self.buf.push(v as u8);
        self
    }
    pub fn u16(&mut self, v: u16) -> &mut Self {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for x in v {
            self.f64(*x);
        }
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }
    /// `std_msgs/Header`.
    pub fn header(&mut self, stamp_ns: i64, frame_id: &str) -> &mut Self {
        self.i32(stamp_ns.div_euclid(1_000_000_000) as i32)
            .u32(stamp_ns.rem_euclid(1_000_000_000) as u32)
            .string(frame_id)
    }
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// North, east, down of `(lat, lon, height)` from `origin` (rad, rad, m) on the WGS-84
/// ellipsoid's local radii: exact enough over the tens of kilometres of a dive.
pub fn ned_offset(origin: [f64; 3], p: [f64; 3]) -> [f64; 3] {
    const A: f64 = 6_378_137.0;
    const E2: f64 = 6.694_379_990_14e-3;
    let [lat0, lon0, h0] = origin;
    let s = lat0.sin();
    let w = (1.0 - E2 * s * s).sqrt();
    let meridian = A * (1.0 - E2) / (w * w * w);
    let prime = A / w;
    [
        (p[0] - lat0) * (meridian + h0),
        (p[1] - lon0) * (prime + h0) * lat0.cos(),
        -(p[2] - h0),
    ]
}

/// `R_ENU←NED`: north and east swapped, down negated.
fn m_enu_ned() -> Matrix3<f64> {
    Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
}

/// `F`: FRD → FLU (and back).
fn f_flu_frd() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
}

/// A vector of FRD axes in FLU axes.
pub fn flu(v: [f64; 3]) -> [f64; 3] {
    [v[0], -v[1], -v[2]]
}

/// The body-to-NED quaternion (w, x, y, z) of a solution as the FLU-to-ENU one (x, y, z, w as
/// `geometry_msgs/Quaternion` orders them).
pub fn orientation_enu_flu(q_ned_frd: [f64; 4]) -> [f64; 4] {
    let [w, x, y, z] = q_ned_frd;
    let r = *UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
        .to_rotation_matrix()
        .matrix();
    let r_enu_flu = m_enu_ned() * r * f_flu_frd();
    let q = UnitQuaternion::from_matrix(&r_enu_flu);
    [q.i, q.j, q.k, q.w]
}

/// A 6×6 covariance with `diag` on the diagonal, row-major.
fn diagonal6(diag: [f64; 6]) -> [f64; 36] {
    let mut c = [0.0; 36];
    for (i, d) in diag.iter().enumerate() {
        c[i * 7] = *d;
    }
    c
}

/// `nav_msgs/Odometry` of a solution, positions east/north/up of `origin` (a solution's NED
/// offset from the origin, metres) and the time stamp `stamp_ns` (ns since 1970).
pub fn odometry(
    cfg: &Ros2Config,
    s: &NavSolutionV1,
    ned_from_origin: [f64; 3],
    stamp_ns: i64,
) -> Vec<u8> {
    let [n, e, d] = ned_from_origin;
    let [qx, qy, qz, qw] = orientation_enu_flu(s.quaternion_body_to_ned);
    let [w, x, y, z] = s.quaternion_body_to_ned;
    let c_nb = *UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
        .to_rotation_matrix()
        .matrix();
    let v_frd = c_nb.transpose() * Vector3::from(s.velocity_ned_m_s);
    let v_flu = flu(v_frd.into());
    let [sn, se, sd] = s.position_std_ned_m;
    let [sr, sp, sy] = s.attitude_std_rad;
    // Pose covariance in map (ENU): x east, y north, z up; rotations about x, y, z taken as the
    // roll, pitch and yaw deviations (small roll and pitch).
    let pose_cov = diagonal6([se * se, sn * sn, sd * sd, sr * sr, sp * sp, sy * sy]);
    // Twist covariance in base_link (FLU): the NED velocity covariance rotated into the body
    // frame; angular rates unknown (a large variance).
    let p_ned = Matrix3::from_diagonal(&Vector3::from(s.velocity_std_ned_m_s).map(|v| v * v));
    let f = f_flu_frd();
    let p_flu = f * c_nb.transpose() * p_ned * c_nb * f;
    let mut twist_cov = [0.0; 36];
    for i in 0..3 {
        for j in 0..3 {
            twist_cov[i * 6 + j] = p_flu[(i, j)];
        }
        twist_cov[(i + 3) * 7] = 1e6;
    }
    let mut c = Cdr::new();
    c.header(stamp_ns, &cfg.map_frame)
        .string(&cfg.base_frame)
        .f64s(&[e, n, -d])
        .f64s(&[qx, qy, qz, qw])
        .f64s(&pose_cov)
        .f64s(&v_flu)
        .f64s(&[0.0, 0.0, 0.0])
        .f64s(&twist_cov);
    c.finish()
}

/// `sensor_msgs/NavSatFix` of a solution: status fix while aligned (navigating or degraded),
/// no fix otherwise; the ENU position covariance, diagonal known.
pub fn nav_sat_fix(cfg: &Ros2Config, s: &NavSolutionV1, stamp_ns: i64) -> Vec<u8> {
    let aligned = matches!(
        NavMode::try_from(s.mode),
        Ok(NavMode::Navigating | NavMode::Degraded)
    );
    let [sn, se, sd] = s.position_std_ned_m;
    let mut c = Cdr::new();
    c.header(stamp_ns, &cfg.base_frame)
        .i8(if aligned { 0 } else { -1 })
        .u16(0)
        .f64(s.latitude_rad.to_degrees())
        .f64(s.longitude_rad.to_degrees())
        .f64(s.height_m)
        .f64s(&[se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, sd * sd])
        .u8(2);
    c.finish()
}

/// `sensor_msgs/Imu` of a sample (rates: increments over their interval), FLU, without
/// orientation.
pub fn imu(cfg: &Ros2Config, m: &ImuSampleV1, stamp_ns: i64) -> Vec<u8> {
    let per_s = if m.status & ImuSampleV1::STATUS_INCREMENTS != 0 && m.interval_s > 0.0 {
        1.0 / m.interval_s
    } else {
        1.0
    };
    let rate = flu(m.angular.map(|v| v * per_s));
    let accel = flu(m.specific.map(|v| v * per_s));
    let mut c = Cdr::new();
    let mut unknown = [0.0; 9];
    unknown[0] = -1.0;
    c.header(stamp_ns, &cfg.imu_frame)
        .f64s(&[0.0, 0.0, 0.0, 1.0])
        .f64s(&unknown)
        .f64s(&rate)
        .f64s(&[0.0; 9])
        .f64s(&accel)
        .f64s(&[0.0; 9]);
    c.finish()
}

/// `geometry_msgs/TwistWithCovarianceStamped` of a DVL velocity, FLU, with its reported
/// standard deviations (or the figure of merit on every axis); angular velocity unknown.
pub fn dvl_twist(cfg: &Ros2Config, m: &DvlVelocityV1, stamp_ns: i64) -> Vec<u8> {
    let std = if m.validity & DvlVelocityV1::VALID_STD != 0 {
        m.velocity_std_m_s
    } else if m.validity & DvlVelocityV1::VALID_FOM != 0 {
        [m.figure_of_merit_m_s; 3]
    } else {
        [1e3; 3]
    };
    let v = flu(m.velocity_dvl_m_s);
    let cov = diagonal6([
        std[0] * std[0],
        std[1] * std[1],
        std[2] * std[2],
        1e6,
        1e6,
        1e6,
    ]);
    let mut c = Cdr::new();
    c.header(stamp_ns, &cfg.dvl_frame)
        .f64s(&v)
        .f64s(&[0.0, 0.0, 0.0])
        .f64s(&cov);
    c.finish()
}

/// `diagnostic_msgs/DiagnosticArray` with the status of one process: OK while running,
/// WARN while reconnecting to its device, STALE while starting or stopping; its counters as
/// key-value pairs.
pub fn diagnostics(h: &ProcessHealthV1, stamp_ns: i64) -> Vec<u8> {
    let (level, message) = match h.state {
        1 => (0u8, "running"),
        2 => (1, "reconnecting"),
        0 => (3, "starting"),
        3 => (3, "stopping"),
        _ => (2, "unknown state"),
    };
    let values = [
        ("frames", h.frames),
        ("checksum_errors", h.checksum_errors),
        ("resyncs", h.resyncs),
        ("bytes_skipped", h.bytes_skipped),
        ("timeouts", h.timeouts),
        ("reconnects", h.reconnects),
        ("drops", h.drops),
        ("invalid", h.invalid),
        ("pid", u64::from(h.pid)),
    ];
    let mut c = Cdr::new();
    c.header(stamp_ns, "")
        .u32(1)
        .u8(level)
        .string(&format!("auvnav: {}", h.name()))
        .string(message)
        .string("")
        .u32(values.len() as u32);
    for (k, v) in values {
        c.string(k).string(&v.to_string());
    }
    c.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_expressions_and_tokens_follow_rmw_zenoh() {
        let cfg = Ros2Config::default();
        assert_eq!(
            data_key(0, &cfg.topic("odometry"), &ODOMETRY),
            "0/auvnav/odometry/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
        );
        assert_eq!(
            node_token(&cfg, "1a2b", 0),
            "@ros2_lv/0/1a2b/0/0/NN/%/%auvnav/auvnav_bridge"
        );
        let t = publisher_token(&cfg, "1a2b", 0, 3, "/diagnostics", &DIAGNOSTIC_ARRAY, 10);
        assert_eq!(
            t,
            "@ros2_lv/0/1a2b/0/3/MP/%/%auvnav/auvnav_bridge/%diagnostics/diagnostic_msgs::msg::dds_::DiagnosticArray_/RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e/:2:,10:,:,:,,"
        );
    }

    #[test]
    fn ned_frd_becomes_enu_flu() {
        // Heading east, level: the FLU body's x points east, y north, z up.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let [x, y, z, w] = orientation_enu_flu([q.w, q.i, q.j, q.k]);
        let r = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        let body_x = r * Vector3::x();
        let body_y = r * Vector3::y();
        assert!(
            (body_x - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12,
            "{body_x}"
        );
        assert!(
            (body_y - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12,
            "{body_y}"
        );
        // Heading north: identity in ENU/FLU is heading east, so a 90 deg yaw.
        let [x, y, z, w] = orientation_enu_flu([1.0, 0.0, 0.0, 0.0]);
        let yaw = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
            .euler_angles()
            .2;
        assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn cdr_aligns_from_the_end_of_the_encapsulation_header() {
        let mut c = Cdr::new();
        c.u8(1).f64(2.0).string("ab").u16(3);
        let b = c.finish();
        assert_eq!(&b[..4], &[0, 1, 0, 0]);
        assert_eq!(b[4], 1);
        assert_eq!(&b[12..20], &2.0f64.to_le_bytes());
        assert_eq!(&b[20..24], &3u32.to_le_bytes());
        assert_eq!(&b[24..27], b"ab\0");
        assert_eq!(&b[28..30], &3u16.to_le_bytes());
    }
}
