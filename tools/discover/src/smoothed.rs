//! `auvnav discover --reference smoothed`: the vehicle's own motion as the reference. Each log is
//! smoothed (`auvnav smooth`, the forward filter and the RTS pass over the same core) with the
//! DVL installation as filter states (mounting, scale, lever arm, time offset, with wide priors),
//! so that the smoothed motion is the IMU's, corrected by the DVL, depth and fixes wherever they
//! are consistent with it — not the DVL's own reading. Compared with that motion, an effect
//! describes the sensor against the IMU, which is what the navigator needs; an imported reference
//! (a post-processed solution taken at another point of the vehicle and time) can describe
//! itself instead. The IMU channels are not compared: the smoothed motion is the IMU's own.
//!
//! When the log also carries a reference (simulated truth or an imported solution), its velocity
//! is compared with the smoothed motion as if it were a DVL on the vehicle: the lever arm, lag,
//! mounting and scale that separate the two are the reference's own against the IMU.

use super::analysis::{DiscoverReport, discover, json_of};
use super::fit::Selection;
use super::{Channel, ChannelKind, Reference};
use crate::DiscoverError;
use auvnav_log::LogReader;
use auvnav_shm_schema::{NavMode, NavSolutionV1, TruthStateV1};
use auvnav_sim::effects::Effects;
use auvnav_smooth::{NAV_SOLUTION_SMOOTHED, SmoothOptions, smooth_log_with};
use std::path::Path;

/// Prior one-sigma of the DVL installation states in the smoothing run: wide, because discovery
/// does not know the installation (lever arm m, time offset s, mounting deg, scale).
pub const LEVER_ARM_STD_M: f64 = 2.0;
pub const TIME_OFFSET_STD_S: f64 = 1.0;
pub const MOUNTING_STD_DEG: f64 = 2.0;
pub const SCALE_STD: f64 = 0.02;

/// The smoothed motion of one log, and what the smoother estimated of the DVL installation.
pub struct Smoothed {
    pub motion: Vec<TruthStateV1>,
    /// The smoother's own installation estimate (JSON of `SmoothedParameters` at the start).
    pub installation: Option<serde_json::Value>,
    /// The smoother's standard deviations of the installation, as effects.
    pub effect_std: Vec<(String, Vec<f64>)>,
}

impl Smoothed {
    /// The smoothed motion as a discovery reference, with its installation uncertainty.
    pub fn reference(&self) -> Reference {
        let mut r = Reference::from_truth(&self.motion);
        r.effect_std = self.effect_std.clone();
        r
    }
}

/// Smooths `log` (outputs into `work`, a scratch folder) and returns its smoothed motion.
/// `depth_lever_arm_m` is the depth sensor's lever arm the smoother fuses its readings at (body
/// axes, m; zero: at the IMU).
pub fn smooth(
    log: &Path,
    work: &Path,
    depth_lever_arm_m: [f64; 3],
) -> Result<Smoothed, DiscoverError> {
    std::fs::create_dir_all(work).map_err(|e| auvnav_smooth::SmoothError::Output {
        path: work.to_path_buf(),
        source: e.into(),
    })?;
    let args = SmoothOptions {
        json: true,
        ..SmoothOptions::new(vec![log.to_path_buf()], work)
    };
    let r = smooth_log_with(&args, log, None, &|cfg| {
        let n = &mut cfg.navigation;
        n.depth_lever_arm_m = depth_lever_arm_m;
        n.estimate_dvl_lever_arm = true;
        n.initial_dvl_lever_arm_std_m = LEVER_ARM_STD_M;
        n.estimate_dvl_time_offset = true;
        n.initial_dvl_time_offset_std_s = TIME_OFFSET_STD_S;
        n.estimate_dvl_mounting = true;
        n.initial_dvl_mounting_std_deg = MOUNTING_STD_DEG;
        n.initial_dvl_mounting_axis_std_deg = None;
        n.estimate_dvl_scale = true;
        n.initial_dvl_scale_std = SCALE_STD;
    })?;
    let path = Path::new(&r.outputs.mcap);
    let mut reader = LogReader::open(path).map_err(|e| DiscoverError::read(path, e))?;
    let mut motion = Vec::new();
    let mut heading_std_deg = Vec::new();
    while let Some(raw) = reader
        .next_message()
        .map_err(|e| DiscoverError::read(path, e))?
    {
        if &*raw.topic != NAV_SOLUTION_SMOOTHED {
            continue;
        }
        let s: NavSolutionV1 = raw.decode().map_err(|e| DiscoverError::read(path, e))?;
        if !matches!(s.nav_mode(), Ok(NavMode::Navigating | NavMode::Degraded)) {
            continue;
        }
        if s.attitude_std_rad[2].is_finite() {
            heading_std_deg.push(s.attitude_std_rad[2].to_degrees());
        }
        motion.push(TruthStateV1 {
            host_time_ns: s.host_time_ns,
            sequence: s.sequence,
            latitude_rad: s.latitude_rad,
            longitude_rad: s.longitude_rad,
            height_m: s.height_m,
            velocity_ned_m_s: s.velocity_ned_m_s,
            quaternion_body_to_ned: s.quaternion_body_to_ned,
            euler_rad: s.euler_rad,
            // From the attitude (Reference::from_truth), and no specific force.
            angular_rate_rad_s: [f64::NAN; 3],
            specific_force_m_s2: [f64::NAN; 3],
        });
    }
    let installation = r
        .parameters
        .as_ref()
        .and_then(|p| serde_json::to_value(&p.first).ok());
    let mut effect_std = Vec::new();
    if let Some(p) = r.parameters.as_ref().map(|p| &p.first) {
        if let Some(m) = p.dvl_mount_deg {
            for (name, v) in ["dvl.mount_roll", "dvl.mount_pitch", "dvl.mount_yaw"]
                .iter()
                .zip(m)
            {
                effect_std.push((name.to_string(), vec![v.std]));
            }
        }
        if let Some(v) = p.dvl_scale_factor {
            effect_std.push(("dvl.scale_factor".into(), vec![v.std]));
        }
        if let Some(l) = p.dvl_lever_arm_m {
            effect_std.push(("dvl.lever_arm".into(), l.iter().map(|v| v.std).collect()));
        }
        if let Some(v) = p.dvl_time_offset_s {
            effect_std.push(("dvl.time_offset".into(), vec![v.std]));
        }
    }
    // A magnetometer's heading against the smoothed heading: no surer than the smoothed heading
    // (its median standard deviation over the voyage).
    heading_std_deg.sort_by(f64::total_cmp);
    if let Some(h) = heading_std_deg.get(heading_std_deg.len() / 2) {
        effect_std.push(("mag.declination".into(), vec![*h]));
    }
    Ok(Smoothed {
        motion,
        installation,
        effect_std,
    })
}

pub use super::findings::ReferenceAgainstImu;

/// The reference's velocity in body axes as a DVL channel (one reading per `spacing_s`),
/// compared with the smoothed motion by the DVL's own model.
pub fn reference_against_imu(
    log: &str,
    reference: &Reference,
    smoothed: &Reference,
    installation: Option<serde_json::Value>,
) -> ReferenceAgainstImu {
    const SPACING_S: f64 = 1.0;
    let mut ch = Channel::new(ChannelKind::Dvl);
    if let Some((t0, t1)) = reference.span() {
        let mut t = t0;
        while t <= t1 {
            if let Some(s) = reference.at(t) {
                let v = s.c_body_to_ned.transpose() * s.velocity_ned;
                ch.push(t, [v.x, v.y, v.z]);
            }
            t += SPACING_S;
        }
    }
    let r: DiscoverReport = discover(
        &[ch],
        smoothed,
        &Effects::default(),
        0.7,
        &Selection::default(),
    );
    ReferenceAgainstImu {
        log: log.into(),
        effects: r
            .effects
            .iter()
            .map(|e| (e.name.clone(), e.value.clone(), e.std.clone()))
            .collect(),
        smoothed_installation: installation,
    }
}

/// The text of a [`ReferenceAgainstImu`] for the notes.
pub fn describe(x: &ReferenceAgainstImu) -> String {
    let found: Vec<String> = x
        .effects
        .iter()
        .map(|(n, v, s)| format!("{n} {v} ± {s}"))
        .collect();
    format!(
        "{}: the log's reference against the smoothed (IMU) motion, read as a DVL on the \
         vehicle: {}{}",
        x.log,
        if found.is_empty() {
            "no difference named".into()
        } else {
            found.join("; ")
        },
        x.smoothed_installation
            .as_ref()
            .map(|i| format!("; the smoother's DVL installation: {}", compact(i)))
            .unwrap_or_default()
    )
}

fn compact(v: &serde_json::Value) -> String {
    // Values to 4 significant digits.
    match v {
        serde_json::Value::Number(n) => n
            .as_f64()
            .map(|x| json_of(&[(x * 1e4).round() / 1e4]).to_string())
            .unwrap_or_else(|| n.to_string()),
        serde_json::Value::Array(a) => {
            format!("[{}]", a.iter().map(compact).collect::<Vec<_>>().join(", "))
        }
        serde_json::Value::Object(o) => format!(
            "{{{}}}",
            o.iter()
                .filter(|(_, v)| !v.is_null())
                .map(|(k, v)| format!("{k}: {}", compact(v)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        other => other.to_string(),
    }
}
