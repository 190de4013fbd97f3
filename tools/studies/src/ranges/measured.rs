//! The range aid's model on measured ranges: each receiver's range against the one the model
//! predicts from the device's own fix (`auvnav_studies::ranges::measured_residuals`).

use auvnav_core::aid::ranges::RangesConfig;
use auvnav_core::earth::Geodetic;
use auvnav_log::LogMessage;
use serde::Serialize;

/// One receiver's ranges against the device's own fixes.
#[derive(Debug, Clone, Serialize)]
pub struct ReceiverResiduals {
    pub receiver: usize,
    /// Ranges compared (the update had a fix and the array a pose).
    pub ranges: usize,
    /// Robust standard deviation of the residuals (1.4826 × the median absolute deviation, m).
    pub robust_std_m: f64,
    /// Ranges beyond five robust standard deviations: outliers, left out of the mean and RMS;
    /// of them, longer than predicted (multipath).
    pub outliers: usize,
    pub outliers_long: usize,
    pub mean_m: f64,
    pub rms_m: f64,
}

/// The range aid's model checked on measured ranges with the device's own fixes as the vehicle's
/// position.
#[derive(Debug, Clone, Serialize)]
pub struct MeasuredResiduals {
    pub receivers: Vec<ReceiverResiduals>,
    /// Updates with a fix, and of them those without the array's pose around their time.
    pub fixes: usize,
    pub without_pose: usize,
    /// The device's fixes against the one-sigma it reports and against per-ping fixes from its
    /// own ranges at the configured receivers ([`crate::ranges::device_fix_model`]).
    pub device_fix: crate::ranges::DeviceFixModel,
}

/// Checks the range aid's measurement model (`cfg`: the receivers, the timing) against every
/// range of `messages` (a log with `acoustic_ranges` and `acoustic_array_pose`), with the
/// vehicle placed at the device's own fix turned through the array's pose at its time: the
/// residual per receiver, outliers beyond five robust standard deviations counted and left out
/// (as discovery counts them). There is no independent reference here: the fixes come from the
/// same ranges, so the residuals say whether the model and the receivers' places agree with the
/// device's solution, not where the vehicle was.
pub fn measured_residuals(messages: &[LogMessage], cfg: &RangesConfig) -> MeasuredResiduals {
    use auvnav_core::aid::pose_history::PoseHistory;
    use auvnav_core::aid::ranges::RangeAid;
    use auvnav_core::earth::offset_position;
    use auvnav_core::strapdown::initial_state;
    use auvnav_shm_schema::AcousticRangesV1;
    use nalgebra::{UnitQuaternion, Vector3};
    let mut kf = auvnav_core::ekf::ErrorFilter::new(&auvnav_core::ekf::StateVector::zeros());
    let mut aid = RangeAid::new(Some(cfg), &mut kf);
    let mut array = PoseHistory::new(60.0);
    let mut residuals = vec![Vec::new(); cfg.receivers_m.len()];
    let (mut fixes, mut without_pose) = (0, 0);
    for m in messages {
        match m {
            LogMessage::AcousticArrayPose(p) => {
                aid.on_array_pose(p);
                array.push(
                    p.host_time_ns as f64 * 1e-9,
                    Geodetic {
                        latitude_rad: p.latitude_rad,
                        longitude_rad: p.longitude_rad,
                        height_m: p.height_m,
                    },
                    UnitQuaternion::from_euler_angles(0.0, 0.0, p.euler_rad[2]),
                );
            }
            LogMessage::AcousticRanges(r) if r.validity & AcousticRangesV1::VALID_POSITION != 0 => {
                fixes += 1;
                let t = r.host_time_ns as f64 * 1e-9;
                let Some(pose) = array
                    .at(t)
                    .filter(|p| p.outside_s <= cfg.array_pose_max_gap_s)
                else {
                    without_pose += 1;
                    continue;
                };
                let vehicle = offset_position(
                    &pose.position,
                    &(pose.attitude * Vector3::from(r.position_array_m)),
                );
                let s = initial_state(t, vehicle, [0.0; 3], [0.0; 3]);
                aid.after_imu(&s);
                for (k, out) in residuals.iter_mut().enumerate() {
                    if let Some(p) = aid.predicted_range(&s, r, k, (0.0, 0.0)) {
                        out.push(r.range_m[k] - p);
                    }
                }
            }
            _ => {}
        }
    }
    let median = |v: &mut Vec<f64>| -> f64 {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let receivers = residuals
        .into_iter()
        .enumerate()
        .map(|(k, res)| {
            let centre = median(&mut res.clone());
            let robust_std_m =
                1.4826 * median(&mut res.iter().map(|x| (x - centre).abs()).collect());
            let limit = 5.0 * robust_std_m;
            let (inliers, outliers): (Vec<f64>, Vec<f64>) =
                res.iter().partition(|x| (*x - centre).abs() <= limit);
            let n = inliers.len().max(1) as f64;
            ReceiverResiduals {
                receiver: k,
                ranges: res.len(),
                robust_std_m,
                outliers: outliers.len(),
                outliers_long: outliers.iter().filter(|x| **x > centre).count(),
                mean_m: inliers.iter().sum::<f64>() / n,
                rms_m: (inliers.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
            }
        })
        .collect();
    MeasuredResiduals {
        receivers,
        fixes,
        without_pose,
        device_fix: crate::ranges::device_fix_model(messages, &cfg.receivers_m),
    }
}
