//! Surface runs: logs with a DVL, a compass (or an AHRS) on the attitude channel and GNSS fixes
//! throughout, and no IMU — a boat's ADCP, a vehicle on the surface. They navigate by dead
//! reckoning ([`auvnav_core::dead_reckoning`]) through the configured DVL installation, and the
//! GNSS, which does not come from the DVL, scores them: `auvnav replay` reports the dead
//! reckoning's error at every fix, `auvnav calibrate dvl` calibrates the installation on them.

use crate::ReplayError;
use auvnav_core::config::DvlInstallation;
use auvnav_core::dead_reckoning::{
    AttitudeSample, AttitudeSeries, DvlReading, Track, dead_reckon, without_deviation,
};
use auvnav_core::earth::{self, Geodetic};
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::{DvlVelocityV1, GnssFixV1};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::Path;

/// The longest attitude gap interpolated (s), and the DVL gap counted as long (s).
pub const ATTITUDE_GAP_S: f64 = 5.0;
pub const DVL_GAP_S: f64 = 5.0;

/// A GNSS fix of a surface run: time (s), north and east (m) from the run's first fix.
pub type Fix = (f64, f64, f64);

/// A surface run in memory: DVL readings, compass attitude and GNSS fixes (north, east from the
/// run's first fix).
#[derive(Debug, Clone)]
pub struct SurfaceRun {
    pub name: String,
    pub dvl: Vec<DvlReading>,
    pub attitude: Vec<AttitudeSample>,
    pub fixes: Vec<Fix>,
    pub origin: Geodetic,
}

/// Whether the log at `path` is a surface run: DVL and attitude, GNSS fixes, and no IMU sample.
pub fn is_surface_run(path: &Path) -> Result<bool, ReplayError> {
    let (imu, attitude) = channels(path, false)?;
    Ok(attitude && !imu)
}

/// Whether the log at `path` has IMU samples, and whether it has attitude samples. The read
/// stops at the first IMU sample unless `attitude_beside_imu` asks whether an attitude channel
/// is there too (a whole recording is not read for an answer already known).
pub fn channels(path: &Path, attitude_beside_imu: bool) -> Result<(bool, bool), ReplayError> {
    let mut r = open(path)?;
    let (mut imu, mut attitude) = (false, false);
    while let Some(raw) = r.next_message().map_err(read_error(path))? {
        match raw.decode_any() {
            Ok(LogMessage::Imu(_)) => imu = true,
            Ok(LogMessage::Attitude(_)) => attitude = true,
            _ => {}
        }
        if imu && (attitude || !attitude_beside_imu) {
            break;
        }
    }
    Ok((imu, attitude))
}

fn open(path: &Path) -> Result<LogReader<std::io::BufReader<std::fs::File>>, ReplayError> {
    let mut r = LogReader::open(path).map_err(read_error(path))?;
    r.read_header().map_err(read_error(path))?;
    Ok(r)
}

fn read_error(path: &Path) -> impl Fn(auvnav_log::LogError) -> ReplayError + '_ {
    move |e| ReplayError::Log {
        path: path.to_path_buf(),
        source: e.into(),
    }
}

/// Reads the surface run at `path` named `name`, within `window_s` (seconds from the log's first
/// message) when given.
pub fn read_surface_run(
    path: &Path,
    name: &str,
    window_s: Option<(f64, f64)>,
) -> Result<SurfaceRun, ReplayError> {
    let mut r = open(path)?;
    let mut first_ns: Option<u64> = None;
    let mut dvl = Vec::new();
    let mut attitude = Vec::new();
    let mut gnss: Vec<GnssFixV1> = Vec::new();
    while let Some(raw) = r.next_message().map_err(read_error(path))? {
        let Ok(m) = raw.decode_any() else { continue };
        let t_ns = match &m {
            LogMessage::Dvl(d) => d.validity_time_ns,
            LogMessage::Attitude(a) => a.host_time_ns,
            LogMessage::Gnss(g) => g.host_time_ns,
            _ => continue,
        };
        let first = *first_ns.get_or_insert(t_ns);
        let t = (t_ns as f64 - first as f64) * 1e-9;
        if let Some((a, b)) = window_s
            && !(a..=b).contains(&t)
        {
            continue;
        }
        match m {
            LogMessage::Dvl(d)
                if d.validity & DvlVelocityV1::VALID_VELOCITY != 0 && !d.is_water_track() =>
            {
                let v = Vector3::from(d.velocity_dvl_m_s);
                if v.iter().all(|x| x.is_finite()) {
                    dvl.push(DvlReading {
                        t_s: t,
                        velocity_dvl: v,
                    });
                }
            }
            LogMessage::Attitude(a)
                if a.validity & auvnav_shm_schema::AttitudeV1::VALID_ATTITUDE != 0
                    && a.euler_rad.iter().all(|x| x.is_finite()) =>
            {
                attitude.push(AttitudeSample::from_euler(t, a.euler_rad));
            }
            LogMessage::Gnss(g) if g.validity & GnssFixV1::VALID_POSITION != 0 => {
                let mut g = g;
                g.host_time_ns = (t * 1e9).max(0.0) as u64;
                gnss.push(g);
            }
            _ => {}
        }
    }
    if dvl.len() < 2 || attitude.len() < 2 || gnss.len() < 2 {
        return Err(ReplayError::Input(format!(
            "surface run {name}: {} DVL readings, {} attitude samples, {} GNSS fixes (at least 2 of each)",
            dvl.len(),
            attitude.len(),
            gnss.len()
        )));
    }
    dvl.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    attitude.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    gnss.sort_by_key(|g| g.host_time_ns);
    let origin = Geodetic {
        latitude_rad: gnss[0].latitude_rad,
        longitude_rad: gnss[0].longitude_rad,
        height_m: 0.0,
    };
    let fixes = gnss
        .iter()
        .map(|g| {
            let p = Geodetic {
                latitude_rad: g.latitude_rad,
                longitude_rad: g.longitude_rad,
                height_m: 0.0,
            };
            let o = earth::ned_offset(&origin, &p);
            (g.host_time_ns as f64 * 1e-9, o.x, o.y)
        })
        .collect();
    Ok(SurfaceRun {
        name: name.to_string(),
        dvl,
        attitude,
        fixes,
        origin,
    })
}

impl SurfaceRun {
    /// The dead reckoning of the run with `installation` and the compass's deviation card
    /// (`deviation_deg`, [`auvnav_core::dead_reckoning::compass_deviation_rad`]), from the
    /// origin (its first fix) at its first reading.
    pub fn dead_reckon(&self, installation: &DvlInstallation, deviation_deg: &[f64; 5]) -> Track {
        let p = auvnav_core::aid::dvl::DvlParameters::new(
            installation.mount_deg,
            installation.scale_factor,
            installation.lever_arm_m,
            installation.time_offset_s,
        );
        let attitude = without_deviation(&self.attitude, deviation_deg);
        let series = AttitudeSeries::new(&attitude, ATTITUDE_GAP_S);
        dead_reckon(&self.dvl, &series, &p, [0.0, 0.0], DVL_GAP_S)
    }

    /// The dead reckoning (as [`SurfaceRun::dead_reckon`]) started at the first fix it covers (its position), scored at every
    /// later fix.
    pub fn accuracy(
        &self,
        installation: &DvlInstallation,
        deviation_deg: &[f64; 5],
    ) -> Option<DeadReckoningAccuracy> {
        let track = self.dead_reckon(installation, deviation_deg);
        let covered: Vec<(&Fix, [f64; 2])> = self
            .fixes
            .iter()
            .filter_map(|f| Some((f, track.at(f.0)?)))
            .collect();
        let (first, p0) = *covered.first()?;
        let mut errors = Vec::with_capacity(covered.len());
        let mut distance = 0.0;
        let mut last = first;
        for (f, p) in &covered {
            let n = p[0] - p0[0] + first.1;
            let e = p[1] - p0[1] + first.2;
            errors.push((n - f.1).hypot(e - f.2));
            if f.0 - last.0 >= 1.0 {
                distance += (f.1 - last.1).hypot(f.2 - last.2);
                last = f;
            }
        }
        let n = errors.len();
        let final_m = *errors.last()?;
        let max_m = errors.iter().copied().fold(0.0, f64::max);
        let rms_m = (errors.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
        let mut sorted = errors.clone();
        sorted.sort_by(f64::total_cmp);
        Some(DeadReckoningAccuracy {
            fixes_compared: n as u64,
            duration_s: covered.last()?.0.0 - first.0,
            distance_travelled_m: distance,
            horizontal_error_final_m: final_m,
            horizontal_error_max_m: max_m,
            horizontal_error_rms_m: rms_m,
            horizontal_error_cep50_m: sorted[n / 2],
            final_error_per_distance_percent: if distance > 0.0 {
                100.0 * final_m / distance
            } else {
                f64::NAN
            },
            readings_without_attitude: track.without_attitude,
            long_dvl_gaps: track.long_gaps,
        })
    }
}

/// A dead reckoning against the GNSS fixes of a surface run.
#[derive(Debug, Clone, Serialize)]
pub struct DeadReckoningAccuracy {
    pub fixes_compared: u64,
    pub duration_s: f64,
    /// Along the GNSS track (fixes a second apart).
    pub distance_travelled_m: f64,
    pub horizontal_error_final_m: f64,
    pub horizontal_error_max_m: f64,
    pub horizontal_error_rms_m: f64,
    pub horizontal_error_cep50_m: f64,
    pub final_error_per_distance_percent: f64,
    /// DVL readings without an attitude around their moment, and gaps between readings longer
    /// than [`DVL_GAP_S`].
    pub readings_without_attitude: u64,
    pub long_dvl_gaps: u64,
}
