//! Voyages and their fixes: a log (or a time window of one) read into memory once, with the
//! sensor messages the dead reckoning uses (IMU, DVL, depth), the start state and the fixes that
//! score it. GNSS and USBL messages are never fed: fixes only score a candidate.

use crate::CalibrationError;
use crate::error::unusable;
use auvnav_core::earth::{self, Geodetic};
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::SessionConfig;
use auvnav_core::strapdown::{NavState, truth_position};
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::{DvlVelocityV1, GnssFixV1};
use serde::Serialize;
use std::path::PathBuf;

/// Where the fixes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FixSource {
    /// The GNSS channel (surface fixes, or continuous).
    Gnss,
    /// The truth / reference channel (simulated truth, or an imported reference solution).
    Truth,
}

impl std::str::FromStr for FixSource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "gnss" => Ok(FixSource::Gnss),
            "truth" | "reference" => Ok(FixSource::Truth),
            _ => Err(format!("unknown fix source {s:?}: expected gnss or truth")),
        }
    }
}

/// A voyage on the command line: `LOG` or `LOG@START..END` (seconds from the log's first message).
#[derive(Debug, Clone, PartialEq)]
pub struct VoyageSpec {
    pub path: PathBuf,
    pub window_s: Option<(f64, f64)>,
}

impl std::str::FromStr for VoyageSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let Some((path, window)) = s.rsplit_once('@') else {
            return Ok(VoyageSpec {
                path: s.into(),
                window_s: None,
            });
        };
        let (a, b) = window
            .split_once("..")
            .ok_or_else(|| format!("voyage {s:?}: the window must be START..END (seconds)"))?;
        let parse = |x: &str| {
            x.trim()
                .parse::<f64>()
                .map_err(|_| format!("voyage {s:?}: {x:?} is not a number of seconds"))
        };
        let (a, b) = (parse(a)?, parse(b)?);
        if !(a.is_finite() && b.is_finite() && a >= 0.0 && b > a) {
            return Err(format!(
                "voyage {s:?}: the window {a}..{b} must satisfy 0 <= START < END"
            ));
        }
        Ok(VoyageSpec {
            path: path.into(),
            window_s: Some((a, b)),
        })
    }
}

impl VoyageSpec {
    pub fn name(&self) -> String {
        let file = self
            .path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.path.display().to_string());
        match self.window_s {
            Some((a, b)) => format!("{file}@{a}..{b}"),
            None => file,
        }
    }
}

/// One position fix, with the distance travelled since the voyage's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fix {
    pub time_ns: u64,
    pub position: Geodetic,
    /// Horizontal one-sigma of the fix (m; 0 for a reference solution).
    pub std_m: f64,
    /// Distance travelled from the start to this fix (m).
    pub distance_m: f64,
}

/// How the distance travelled was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DistanceSource {
    /// Along the truth / reference track.
    Truth,
    /// Along the dead reckoning with the starting installation (the same for every candidate).
    StartingDeadReckoning,
}

/// A voyage in memory.
#[derive(Debug, Clone)]
pub struct Voyage {
    pub name: String,
    /// IMU, DVL and depth messages from the start on, in log order.
    pub inputs: Vec<SensorMessage>,
    pub start: NavState,
    pub start_source: &'static str,
    pub fixes: Vec<Fix>,
    pub distance_source: DistanceSource,
    /// Valid DVL velocities.
    pub dvl_valid: usize,
}

impl Voyage {
    /// Reads a voyage. The start state is the first truth record in the window, otherwise the
    /// configuration's `[initial]` state, otherwise (a recording of a vehicle that aligned on
    /// board) the daemon's first recorded solution in mode *navigating*.
    // Long on purpose: reads one voyage: window, start state (truth, `[initial]` or the recorded
    // solution), fixes and distances, each missing piece with its error.
    pub fn load(
        spec: &VoyageSpec,
        fixes: FixSource,
        cfg: &SessionConfig,
    ) -> Result<Voyage, CalibrationError> {
        let name = spec.name();
        let failed = |e: auvnav_log::LogError| CalibrationError::Read {
            path: spec.path.clone(),
            source: format!("voyage {name}: {e}").into(),
        };
        let mut reader = LogReader::open(&spec.path).map_err(failed)?;
        reader.read_header().map_err(failed)?;
        let mut first_ns: Option<u64> = None;
        let mut inputs = Vec::new();
        let mut truth = Vec::new();
        let mut gnss: Vec<GnssFixV1> = Vec::new();
        let mut first_navigating: Option<auvnav_shm_schema::NavSolutionV1> = None;
        let mut dvl_any = 0usize;
        let mut dvl_valid = 0usize;
        while let Some(raw) = reader.next_message().map_err(failed)? {
            let Ok(m) = raw.decode_any() else { continue };
            let t_ns = match m {
                LogMessage::Truth(x) => x.host_time_ns,
                LogMessage::NavSolution(x) => {
                    // Counted from the first sensor message, like everything else in the window.
                    if first_navigating.is_none()
                        && x.mode == auvnav_shm_schema::NavMode::Navigating as u32
                        && first_ns.is_some_and(|f| {
                            let rel = x.host_time_ns.saturating_sub(f) as f64 * 1e-9;
                            spec.window_s.is_none_or(|(a, b)| rel >= a && rel <= b)
                        })
                    {
                        first_navigating = Some(x);
                    }
                    continue;
                }
                other => match other.sensor() {
                    Some(s) => s.host_time_ns(),
                    None => continue,
                },
            };
            let first = *first_ns.get_or_insert(t_ns);
            let rel = t_ns.saturating_sub(first) as f64 * 1e-9;
            if let Some((a, b)) = spec.window_s {
                if rel < a {
                    continue;
                }
                if rel > b {
                    break;
                }
            }
            match m {
                LogMessage::Truth(x) => truth.push(x),
                LogMessage::Gnss(x) => gnss.push(x),
                LogMessage::Usbl(_) => {}
                other => {
                    if let LogMessage::Dvl(d) = other {
                        dvl_any += 1;
                        if d.validity & DvlVelocityV1::VALID_VELOCITY != 0 {
                            dvl_valid += 1;
                        }
                    }
                    if let Some(s) = other.sensor() {
                        inputs.push(s);
                    }
                }
            }
        }
        if dvl_any == 0 {
            unusable!("voyage {name}: the log has no DVL messages; nothing to calibrate");
        }
        if dvl_valid == 0 {
            unusable!("voyage {name}: none of its {dvl_any} DVL messages carries a valid velocity");
        }
        let (start, start_source) = match (truth.first(), &cfg.initial, &first_navigating) {
            (Some(t), _, _) => (NavState::from_truth(t), "first truth record of the voyage"),
            (None, Some(init), _) => {
                let t0 = inputs
                    .first()
                    .map(|m| m.host_time_ns() as f64 * 1e-9)
                    .unwrap_or(0.0);
                (init.state(t0), "the configuration's [initial] state")
            }
            (None, None, Some(s)) => (
                auvnav_core::strapdown::initial_state(
                    s.host_time_ns as f64 * 1e-9,
                    Geodetic {
                        latitude_rad: s.latitude_rad,
                        longitude_rad: s.longitude_rad,
                        height_m: s.height_m,
                    },
                    s.velocity_ned_m_s,
                    s.euler_rad,
                ),
                "the recorded navigation's first solution after alignment",
            ),
            (None, None, None) => unusable!(
                "voyage {name}: no start state (the log has no truth channel and no recorded \
                 solution in mode navigating; give --config with an [initial] table)"
            ),
        };
        let start_ns = (start.time_s * 1e9).round() as u64;
        inputs.retain(|m| m.host_time_ns() >= start_ns);

        let (mut fix_list, distance_source) = match fixes {
            FixSource::Truth => {
                if truth.is_empty() {
                    unusable!("voyage {name}: --fixes truth, but the log has no truth channel");
                }
                let f = truth
                    .iter()
                    .map(|t| Fix {
                        time_ns: t.host_time_ns,
                        position: truth_position(t),
                        std_m: 0.0,
                        distance_m: 0.0,
                    })
                    .collect::<Vec<_>>();
                (f, DistanceSource::Truth)
            }
            FixSource::Gnss => {
                let f = gnss
                    .iter()
                    .filter(|g| {
                        g.validity & GnssFixV1::VALID_POSITION != 0
                            && g.latitude_rad.is_finite()
                            && g.longitude_rad.is_finite()
                    })
                    .map(|g| Fix {
                        time_ns: g.host_time_ns,
                        position: Geodetic {
                            latitude_rad: g.latitude_rad,
                            longitude_rad: g.longitude_rad,
                            height_m: g.height_m,
                        },
                        std_m: g.horizontal_std_m,
                        distance_m: 0.0,
                    })
                    .collect::<Vec<_>>();
                let source = if truth.len() >= 2 {
                    DistanceSource::Truth
                } else {
                    DistanceSource::StartingDeadReckoning
                };
                (f, source)
            }
        };
        fix_list.retain(|f| f.time_ns >= start_ns);
        if fix_list.is_empty() {
            unusable!(
                "voyage {name}: no {} fixes after the start; fixes score the calibration",
                match fixes {
                    FixSource::Gnss => "GNSS",
                    FixSource::Truth => "truth",
                }
            );
        }
        fix_list.sort_by_key(|f| f.time_ns);
        if distance_source == DistanceSource::Truth {
            let track: Vec<(u64, Geodetic)> = truth
                .iter()
                .filter(|t| t.host_time_ns >= start_ns)
                .map(|t| (t.host_time_ns, truth_position(t)))
                .collect();
            set_distances(&mut fix_list, &track);
        }
        Ok(Voyage {
            name,
            inputs,
            start,
            start_source,
            fixes: fix_list,
            distance_source,
            dvl_valid,
        })
    }

    /// Sets the fixes' distances from a dead-reckoned track (when the log has no truth).
    pub fn set_distances_from_track(&mut self, track: &[(u64, Geodetic)]) {
        set_distances(&mut self.fixes, track);
    }

    /// Seconds from the start to the last fix.
    pub fn duration_s(&self) -> f64 {
        self.fixes
            .last()
            .map(|f| f.time_ns as f64 * 1e-9 - self.start.time_s)
            .unwrap_or(0.0)
    }

    /// Distance travelled to the last fix (m).
    pub fn distance_m(&self) -> f64 {
        self.fixes.last().map(|f| f.distance_m).unwrap_or(0.0)
    }
}

/// Horizontal distance along `track` (time-ordered) up to each fix's time.
fn set_distances(fixes: &mut [Fix], track: &[(u64, Geodetic)]) {
    let mut cumulative = Vec::with_capacity(track.len());
    let mut d = 0.0;
    for (i, (t, p)) in track.iter().enumerate() {
        if i > 0 {
            let o = earth::ned_offset(&track[i - 1].1, p);
            d += o.x.hypot(o.y);
        }
        cumulative.push((*t, d));
    }
    for f in fixes.iter_mut() {
        let k = cumulative.partition_point(|(t, _)| *t <= f.time_ns);
        f.distance_m = match (k.checked_sub(1).map(|i| cumulative[i]), cumulative.get(k)) {
            (Some((t0, d0)), Some((t1, d1))) if t1 > &t0 => {
                d0 + (d1 - d0) * (f.time_ns - t0) as f64 / (*t1 - t0) as f64
            }
            (Some((_, d0)), _) => d0,
            (None, _) => 0.0,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voyage_specs_parse_windows_and_reject_bad_ones() {
        let v: VoyageSpec = "a/b.mcap@10..400.5".parse().expect("window");
        assert_eq!(v.window_s, Some((10.0, 400.5)));
        assert_eq!(v.name(), "b.mcap@10..400.5");
        let v: VoyageSpec = "b.mcap".parse().expect("plain");
        assert_eq!(v.window_s, None);
        for bad in ["b.mcap@10", "b.mcap@x..3", "b.mcap@5..2", "b.mcap@-1..2"] {
            let err = bad.parse::<VoyageSpec>().expect_err(bad);
            assert!(err.contains(bad), "{err}");
        }
    }
}
