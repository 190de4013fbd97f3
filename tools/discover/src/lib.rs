//! Model discovery: where the simulator's sensor models disagree with measured data, which named
//! effect explains it, and what is left.
//!
//! Each sensor channel's readings are compared with what the simulator's own sensor model
//! ([`auvnav_sim::sensors`]) predicts from the reference motion (the simulated truth, or another
//! reference) under a set of effects. The candidates are the simulator's named effects
//! (`auvnav sim --list-effects`), in their units and sign conventions; [`fit`] estimates them,
//! selects them greedily by time-block cross-validation and checks which ones the motion can
//! separate; [`describe`] characterises what is left (whiteness, spectrum, correlation with the
//! motion). [`command`] is `auvnav discover` as a function: options in, a typed report (and the
//! files it asks for) out; the library never prints. With the `clap` feature the option structs
//! are also the command line's.
//!
//! Long on purpose: the reference motion and the channel model (each channel's prediction under the
//! effects) that every module of discovery uses: one table of channels.
#![forbid(unsafe_code)]

pub mod analysis;
pub mod command;
mod error;
pub mod findings;
pub mod fit;
pub mod gnss;
pub mod gnss_evidence;
mod gnss_written;
pub mod hidden_effects;
pub mod imu;
pub mod navigation;
pub mod noise;
pub mod outputs;
pub mod periodic;
mod reference_noise;
pub mod report;
pub mod residuals;
pub mod smoothed;
mod spline;
pub mod surface_trials;
pub mod trials;
pub mod voyages;

pub use error::{DiscoverError, Source};

use auvnav_core::earth;
use auvnav_shm_schema::TruthStateV1;
use auvnav_sim::effects::Effects;
use auvnav_sim::sensors::{
    DEG_PER_H, DepthModel, DvlInstallation, ImuModel, MICRO_G, MagnetometerModel,
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::Serialize;

/// The reference motion at one time.
#[derive(Debug, Clone, Copy)]
pub struct RefState {
    pub t_s: f64,
    pub c_body_to_ned: Matrix3<f64>,
    pub velocity_ned: Vector3<f64>,
    /// Angular rate w.r.t. the Earth (body axes, rad/s).
    pub omega_eb_body: Vector3<f64>,
    pub height_m: f64,
    pub latitude_rad: f64,
    pub specific_force_body: Vector3<f64>,
}

/// The reference motion: samples in time order, interpolated linearly (attitude by slerp), its
/// velocity optionally smoothed ([`Reference::with_smoothed_velocity`]).
#[derive(Debug, Clone, Default)]
pub struct Reference {
    samples: Vec<(f64, UnitQuaternion<f64>, RefState)>,
    /// The velocity from the cubic B-spline on the four samples around a time rather than the
    /// line between two ([`crate::spline`]): for a reference whose samples carry noise of their
    /// own ([`crate::reference_noise`]).
    smooth_velocity: bool,
    /// The longest gap between samples [`Reference::at`] interpolates across (s): 1 s, or 1.5
    /// times the median interval of a reference sampled more slowly (a surface run's GPS
    /// reference at each 1 s ping).
    max_gap_s: f64,
    /// The reference's own uncertainty in the vocabulary, per effect and component: a motion
    /// estimated with the DVL installation as filter states (`--reference smoothed`) is only as
    /// sure of the DVL's mounting, scale, lever arm and lag as the filter was, so an effect
    /// fitted against it is never more certain than that (added in quadrature to its deviation).
    pub effect_std: Vec<(String, Vec<f64>)>,
}

impl Reference {
    /// From truth messages (any order; repeated times keep the first). Samples without a finite
    /// attitude, velocity or position are left out. A reference without angular rates (an
    /// imported reference solution) gets them from its attitude: the rotation between
    /// neighbouring samples; a missing specific force is zero (it only serves as a regressor).
    pub fn from_truth(truth: &[TruthStateV1]) -> Reference {
        let mut samples: Vec<_> = truth
            .iter()
            .filter(|m| {
                m.quaternion_body_to_ned.iter().all(|x| x.is_finite())
                    && m.velocity_ned_m_s.iter().all(|x| x.is_finite())
                    && m.height_m.is_finite()
                    && m.latitude_rad.is_finite()
            })
            .map(|m| {
                let q = m.quaternion_body_to_ned;
                let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    q[0], q[1], q[2], q[3],
                ));
                let c = q.to_rotation_matrix().into_inner();
                let w_ie = c.transpose() * earth::earth_rate_ned(m.latitude_rad);
                let t_s = m.host_time_ns as f64 * 1e-9;
                let rate = Vector3::from(m.angular_rate_rad_s);
                let force = Vector3::from(m.specific_force_m_s2);
                (
                    t_s,
                    q,
                    RefState {
                        t_s,
                        c_body_to_ned: c,
                        velocity_ned: Vector3::from(m.velocity_ned_m_s),
                        // NaN marks "derive from the attitude" below.
                        omega_eb_body: if rate.iter().all(|x| x.is_finite()) {
                            rate - w_ie
                        } else {
                            Vector3::repeat(f64::NAN)
                        },
                        height_m: m.height_m,
                        latitude_rad: m.latitude_rad,
                        specific_force_body: if force.iter().all(|x| x.is_finite()) {
                            force
                        } else {
                            Vector3::zeros()
                        },
                    },
                )
            })
            .collect();
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        samples.dedup_by(|a, b| a.0 == b.0);
        // Rates from the attitude (central differences; one-sided at the ends), w.r.t. the
        // Earth: the reference attitude is relative to the local level frame.
        let n = samples.len();
        for i in 0..n {
            if samples[i].2.omega_eb_body.iter().all(|x| x.is_finite()) {
                continue;
            }
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
            let dt = samples[b].0 - samples[a].0;
            samples[i].2.omega_eb_body = if a != b && dt > 0.0 && dt <= 2.0 {
                // Body rate: q_b = q_a · exp(ω dt / 2) in body axes.
                (samples[a].1.inverse() * samples[b].1).scaled_axis() / dt
            } else {
                Vector3::zeros()
            };
        }
        let mut intervals: Vec<f64> = samples
            .windows(2)
            .map(|w| w[1].0 - w[0].0)
            .filter(|d| *d > 0.0)
            .collect();
        intervals.sort_by(f64::total_cmp);
        let median = intervals.get(intervals.len() / 2).copied().unwrap_or(0.0);
        Reference {
            samples,
            smooth_velocity: false,
            max_gap_s: (1.5 * median).max(1.0),
            effect_std: Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The sample times (s), in order.
    pub fn times(&self) -> Vec<f64> {
        self.samples.iter().map(|s| s.0).collect()
    }

    /// Time span covered (s).
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((self.samples.first()?.0, self.samples.last()?.0))
    }

    /// The state at `t_s`, or None outside the reference or across a gap longer than 1 s (or
    /// 1.5 sample intervals of a reference sampled more slowly than once a second). A reference
    /// at each 1 s ping has intervals of 1 s ± a nanosecond of stamp rounding: a fixed 1 s limit
    /// refused half of them, and a time offset's fit, moving the prediction between samples,
    /// lost those readings (0.30 s found for 0.4 s hidden on a lake run).
    pub fn at(&self, t_s: f64) -> Option<RefState> {
        let s = &self.samples;
        let i = s.partition_point(|x| x.0 <= t_s);
        if i == 0 {
            return None;
        }
        let (t0, q0, a) = &s[i - 1];
        if *t0 == t_s {
            if self.smooth_velocity {
                return Some(RefState {
                    velocity_ned: self.smoothed_velocity(t_s)?,
                    ..*a
                });
            }
            return Some(*a);
        }
        let (t1, q1, b) = s.get(i)?;
        if t1 - t0 > self.max_gap_s {
            return None;
        }
        let f = (t_s - t0) / (t1 - t0);
        let lerp = |x: &Vector3<f64>, y: &Vector3<f64>| x + (y - x) * f;
        let velocity_ned = if self.smooth_velocity {
            self.smoothed_velocity(t_s)?
        } else {
            lerp(&a.velocity_ned, &b.velocity_ned)
        };
        Some(RefState {
            t_s,
            c_body_to_ned: q0.slerp(q1, f).to_rotation_matrix().into_inner(),
            velocity_ned,
            omega_eb_body: lerp(&a.omega_eb_body, &b.omega_eb_body),
            height_m: a.height_m + (b.height_m - a.height_m) * f,
            latitude_rad: a.latitude_rad + (b.latitude_rad - a.latitude_rad) * f,
            specific_force_body: lerp(&a.specific_force_body, &b.specific_force_body),
        })
    }

    /// The same reference with its velocity evaluated by the cubic B-spline on the four samples
    /// around each time ([`crate::spline`]), whose noise gain varies little and smoothly, rather
    /// than by the line between two samples, whose noise gain halves half-way and kinks at each
    /// sample: for a reference whose samples carry noise of their own
    /// ([`crate::reference_noise`]). What the spline still varies by is given back to the fit
    /// ([`Reference::interpolation_loss`]).
    pub fn with_smoothed_velocity(&self) -> Reference {
        Reference {
            smooth_velocity: true,
            ..self.clone()
        }
    }

    /// Whether the velocity is smoothed ([`Reference::with_smoothed_velocity`]).
    pub fn smooths_velocity(&self) -> bool {
        self.smooth_velocity
    }

    /// Where the spline takes `t_s` from: the index of the first of the four samples (the one
    /// before the interval holding `t_s`), the fraction of that interval and its length; None
    /// where the four samples are not there, or not within the gap limit of each other.
    fn spline_at(&self, t_s: f64) -> Option<(usize, f64, f64)> {
        let s = &self.samples;
        let j = s.partition_point(|x| x.0 <= t_s).checked_sub(1)?;
        let first = j.checked_sub(1)?;
        let four = s.get(first..first + 4)?;
        if four
            .windows(2)
            .any(|w| !(w[1].0 - w[0].0 > 0.0 && w[1].0 - w[0].0 <= self.max_gap_s))
        {
            return None;
        }
        let h = s[j + 1].0 - s[j].0;
        Some((first, (t_s - s[j].0) / h, h))
    }

    fn smoothed_velocity(&self, t_s: f64) -> Option<Vector3<f64>> {
        let (first, f, _) = self.spline_at(t_s)?;
        let (w, _) = spline::weights(f);
        Some(
            (0..4)
                .map(|k| self.samples[first + k].2.velocity_ned * w[k])
                .sum(),
        )
    }
}

/// A sensor channel discovery compares with the reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelKind {
    /// DVL velocity in the DVL frame (m/s, 3 components).
    Dvl,
    /// Depth (m).
    Depth,
    /// Magnetometer field in the sensor frame (µT, 3 components).
    Magnetometer,
    /// The magnetometer without a reference attitude: the calibrated field's magnitude against
    /// `mag.intensity`, and its dip against the accelerometer's vertical against
    /// `mag.inclination`, as the field error across the field (µT: intensity × dip error in
    /// rad). Both are free of the attitude, so recordings without a reference can be analysed.
    MagneticField,
    /// Range from each receiver (hydrophone 1..4) of an acoustic positioning array to the
    /// responder (m), against the ranges the device's own position fix and the receiver geometry
    /// give: the geometry, the sound speed and the range noise and outliers, without a reference.
    AcousticRanges,
    /// The gyro's mean rate over an interval between reference samples (deg/h, 3 components),
    /// from its integrated rotation, against the reference's change of attitude.
    Gyro,
    /// The accelerometer's mean specific force over an interval (µg, 3 components), integrated
    /// in the level frame, against the reference's change of velocity with gravity and Coriolis.
    Accelerometer,
    /// The DVL's four beam (radial) velocities (m/s), in place of its velocity (`discover
    /// --dvl-beams`): each beam's own scale and angle can be told apart only here, since the
    /// device's velocity mixes the beams.
    DvlBeams,
}

impl ChannelKind {
    pub const ALL: [ChannelKind; 8] = [
        ChannelKind::Dvl,
        ChannelKind::Depth,
        ChannelKind::Magnetometer,
        ChannelKind::MagneticField,
        ChannelKind::AcousticRanges,
        ChannelKind::Gyro,
        ChannelKind::Accelerometer,
        ChannelKind::DvlBeams,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ChannelKind::Dvl => "dvl",
            ChannelKind::Depth => "depth",
            ChannelKind::Magnetometer => "magnetometer",
            ChannelKind::MagneticField => "magnetic_field",
            ChannelKind::AcousticRanges => "acoustic_ranges",
            ChannelKind::Gyro => "gyro",
            ChannelKind::Accelerometer => "accelerometer",
            ChannelKind::DvlBeams => "dvl_beams",
        }
    }

    pub fn dims(self) -> usize {
        self.component_names().len()
    }

    /// The name of each component, as reports print it.
    pub fn component_names(self) -> &'static [&'static str] {
        match self {
            ChannelKind::Depth => &["depth"],
            ChannelKind::MagneticField => &["magnitude", "dip"],
            ChannelKind::AcousticRanges => &["r0", "r1", "r2", "r3"],
            ChannelKind::DvlBeams => &["beam1", "beam2", "beam3", "beam4"],
            ChannelKind::Dvl
            | ChannelKind::Magnetometer
            | ChannelKind::Gyro
            | ChannelKind::Accelerometer => &["x", "y", "z"],
        }
    }

    /// `channel component`, e.g. `dvl x` or `acoustic_ranges r2`.
    pub fn component_label(self, k: usize) -> String {
        match self.component_names().get(k) {
            Some(c) if self.dims() > 1 => format!("{} {c}", self.name()),
            Some(_) => self.name().to_string(),
            None => format!("{} {k}", self.name()),
        }
    }

    /// Whether the channel is compared with the reference motion (the attitude-free magnetic
    /// field and the acoustic ranges, against the device's own fix, are not).
    pub fn needs_reference(self) -> bool {
        !matches!(
            self,
            ChannelKind::MagneticField | ChannelKind::AcousticRanges
        )
    }

    /// Whether a reading may lack some components (a receiver without a range this time).
    pub fn partial(self) -> bool {
        self == ChannelKind::AcousticRanges
    }

    pub fn unit(self) -> &'static str {
        match self {
            ChannelKind::Dvl | ChannelKind::DvlBeams => "m/s",
            ChannelKind::Depth => "m",
            ChannelKind::Magnetometer | ChannelKind::MagneticField => "uT",
            ChannelKind::AcousticRanges => "m",
            ChannelKind::Gyro => "deg/h",
            ChannelKind::Accelerometer => "ug",
        }
    }

    /// What the simulator's sensor model reads at stamp `t_s` under `e`, from the reference;
    /// None where the reference does not cover the time of validity.
    pub fn predict(self, e: &Effects, reference: &Reference, t_s: f64) -> Option<[f64; 3]> {
        match self {
            ChannelKind::Dvl => {
                let r = reference.at(t_s - e.dvl_time_offset)?;
                let v = DvlInstallation::from_effects(e).bottom_track_reading(
                    t_s,
                    &r.c_body_to_ned,
                    &r.velocity_ned,
                    &r.omega_eb_body,
                );
                Some(v.into())
            }
            ChannelKind::Depth => {
                let r = reference.at(t_s)?;
                Some([
                    DepthModel::reading(e, -r.height_m, &r.c_body_to_ned),
                    0.0,
                    0.0,
                ])
            }
            ChannelKind::Magnetometer => {
                let r = reference.at(t_s)?;
                Some(MagnetometerModel::reading(e, &r.c_body_to_ned).into())
            }
            // Implicit, against the reading's own fix, over intervals, or four components: see
            // [`Channel::residual`].
            ChannelKind::DvlBeams
            | ChannelKind::MagneticField
            | ChannelKind::AcousticRanges
            | ChannelKind::Gyro
            | ChannelKind::Accelerometer => None,
        }
    }
}

/// Most components a channel has (the acoustic ranges: four receivers).
pub const MAX_DIMS: usize = 4;

/// One channel's measured readings (stamp s, value in the channel's unit).
#[derive(Debug, Clone)]
pub struct Channel {
    pub kind: ChannelKind,
    pub times: Vec<f64>,
    /// The readings (the first `dims` components; NaN where a partial reading has none).
    pub values: Vec<[f64; MAX_DIMS]>,
    /// Per reading, what the prediction needs besides the reference: the specific force (m/s²,
    /// sensor axes) of the magnetic-field channel, the device's fix (array frame, m) of the
    /// acoustic ranges, the reference's mean rate or specific force of the IMU channels (empty
    /// for the other channels).
    pub auxiliary: Vec<[f64; 3]>,
    /// The receiver positions the acoustic device is configured with (array frame, m; zero when
    /// the recording does not say).
    pub receivers: [f64; 12],
    /// Readings left out (invalid, non-finite).
    pub skipped: usize,
    /// The DVL's bottom track may see a moving bed (a river, soft sediment): `dvl.bed_velocity`
    /// is a candidate of this channel ([`Collector::with_moving_bed`]).
    pub moving_bed: bool,
    /// The residual's strongest line ([`periodic::with_line`]): the period and phase at which
    /// `dvl.periodic_velocity_error` is a candidate of this channel (none: not a candidate).
    pub periodic_line: Option<periodic::PeriodicLine>,
}

impl Channel {
    pub fn new(kind: ChannelKind) -> Channel {
        Channel {
            kind,
            times: Vec::new(),
            values: Vec::new(),
            auxiliary: Vec::new(),
            receivers: [0.0; 12],
            skipped: 0,
            moving_bed: false,
            periodic_line: None,
        }
    }

    /// An acoustic update: the ranges per receiver (NaN where none) and the device's fix.
    pub fn push_ranges(&mut self, t_s: f64, ranges: [f64; 4], fix: [f64; 3]) {
        let ok = t_s.is_finite()
            && fix.iter().all(|x| x.is_finite())
            && ranges.iter().any(|x| x.is_finite())
            && ranges.iter().all(|x| !x.is_infinite());
        if ok {
            self.times.push(t_s);
            self.values.push(ranges);
            self.auxiliary.push(fix);
        } else {
            self.skipped += 1;
        }
    }

    /// An IMU interval: the measured mean (the reference's plus the integrated error) and the
    /// reference's mean, in the channel's unit.
    pub fn push_imu(&mut self, t_s: f64, measured: Vector3<f64>, reference: Vector3<f64>) {
        if t_s.is_finite()
            && measured
                .iter()
                .chain(reference.iter())
                .all(|x| x.is_finite())
        {
            self.times.push(t_s);
            self.values.push([measured.x, measured.y, measured.z, 0.0]);
            self.auxiliary.push(reference.into());
        } else {
            self.skipped += 1;
        }
    }

    /// A magnetometer reading (µT) with the specific force at its time (any unit: only the
    /// direction counts).
    pub fn push_field(&mut self, t_s: f64, field_ut: [f64; 3], force: [f64; 3]) {
        let ok = t_s.is_finite()
            && field_ut.iter().chain(&force).all(|x| x.is_finite())
            && Vector3::from(force).norm() > 0.0;
        if ok {
            self.times.push(t_s);
            self.values
                .push([field_ut[0], field_ut[1], field_ut[2], 0.0]);
            self.auxiliary.push(force);
        } else {
            self.skipped += 1;
        }
    }

    /// Reading `i` measured − predicted under `e` (the first `dims` components); None where the
    /// prediction is not available (outside the reference). The magnetic-field channel is
    /// implicit: the reading is corrected by the effects' soft and hard iron (the inverse of the
    /// simulator's model), and its magnitude and dip are compared with the field's.
    pub fn residual(
        &self,
        e: &Effects,
        reference: &Reference,
        i: usize,
    ) -> Option<[f64; MAX_DIMS]> {
        let z = self.values[i];
        if self.kind == ChannelKind::AcousticRanges {
            let nominal: [Vector3<f64>; 4] = std::array::from_fn(|k| {
                Vector3::new(
                    self.receivers[3 * k],
                    self.receivers[3 * k + 1],
                    self.receivers[3 * k + 2],
                )
            });
            let p = Vector3::from(*self.auxiliary.get(i)?);
            let predicted = auvnav_sim::sensors::hydrophone_ranges(e, &nominal, &p);
            return Some(std::array::from_fn(|k| z[k] - predicted[k]));
        }
        if self.kind == ChannelKind::DvlBeams {
            let r = reference.at(self.times[i] - e.dvl_time_offset)?;
            let v = DvlInstallation::from_effects(e).bottom_track_reading(
                self.times[i],
                &r.c_body_to_ned,
                &r.velocity_ned,
                &r.omega_eb_body,
            );
            let predicted = auvnav_sim::sensors::dvl_beam_readings(e, &v);
            return Some(std::array::from_fn(|k| z[k] - predicted[k]));
        }
        if matches!(self.kind, ChannelKind::Gyro | ChannelKind::Accelerometer) {
            let truth = Vector3::from(*self.auxiliary.get(i)?);
            let predicted = if self.kind == ChannelKind::Gyro {
                ImuModel::gyro_reading(e, &(truth * DEG_PER_H)) / DEG_PER_H
            } else {
                ImuModel::accel_reading(e, &(truth * MICRO_G)) / MICRO_G
            };
            return Some([
                z[0] - predicted.x,
                z[1] - predicted.y,
                z[2] - predicted.z,
                0.0,
            ]);
        }
        if self.kind == ChannelKind::MagneticField {
            let body = MagnetometerModel::body_field(e, &Vector3::new(z[0], z[1], z[2]))?;
            let down = -Vector3::from(*self.auxiliary.get(i)?).normalize();
            let norm = body.norm();
            if norm <= 0.0 {
                return None;
            }
            let dip = (down.dot(&body) / norm).clamp(-1.0, 1.0).asin();
            return Some([
                norm - e.mag_intensity,
                e.mag_intensity * (dip - e.mag_inclination.to_radians()),
                0.0,
                0.0,
            ]);
        }
        let p = self.kind.predict(e, reference, self.times[i])?;
        Some([z[0] - p[0], z[1] - p[1], z[2] - p[2], 0.0])
    }

    /// A DVL reading's four beam velocities (m/s).
    pub fn push_beams(&mut self, t_s: f64, beams: [f64; 4]) {
        if t_s.is_finite() && beams.iter().all(|x| x.is_finite()) {
            self.times.push(t_s);
            self.values.push(beams);
        } else {
            self.skipped += 1;
        }
    }

    pub fn push(&mut self, t_s: f64, v: [f64; 3]) {
        if t_s.is_finite() && v[..self.kind.dims()].iter().all(|x| x.is_finite()) {
            self.times.push(t_s);
            self.values.push([v[0], v[1], v[2], 0.0]);
        } else {
            self.skipped += 1;
        }
    }

    pub fn len(&self) -> usize {
        self.times.len()
    }

    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }
}

/// A candidate cause: one of the simulator's effects, the channel it acts on, and the step of
/// its numerical derivative (in the effect's unit).
#[derive(Debug, Clone, Copy)]
pub struct Candidate {
    pub name: &'static str,
    pub channel: ChannelKind,
    pub step: f64,
}

/// The candidates, in vocabulary order. Left out, with the reason: `dvl.sound_speed` and
/// `depth.density`'s twin would be exact aliases (`dvl.sound_speed` scales the velocity exactly
/// as `dvl.scale_factor` does, reported under that name); noise, outlier and lock-loss effects
/// are statistics of the residual, described rather than fitted; `mag.soft_iron` is calibrated by
/// `auvnav calibrate mag`. `dvl.bed_velocity` (a moving bed under bottom track) is a candidate
/// only where the caller says the bed may move (`--moving-bed`): on long straight legs it is
/// hard to tell from the DVL's yaw and scale, and a per-voyage effect that can absorb them would
/// weaken the evidence for the installation. `dvl.periodic_velocity_error` is a candidate only
/// where the DVL residual has a line standing out, at its period and phase ([`periodic`]), its
/// amplitudes fitted. Without a reference attitude (the magnetic-field channel)
/// `mag.declination` does not act on the reading at all. On the beams (`dvl_beams`) a scale
/// common to the four beams is `dvl.scale_factor`; `dvl.beam_scale_factor` is each beam's own.
pub const CANDIDATES: &[Candidate] = &[
    Candidate {
        name: "dvl.scale_factor",
        channel: ChannelKind::Dvl,
        step: 1e-4,
    },
    Candidate {
        name: "dvl.mount_roll",
        channel: ChannelKind::Dvl,
        step: 0.01,
    },
    Candidate {
        name: "dvl.mount_pitch",
        channel: ChannelKind::Dvl,
        step: 0.01,
    },
    Candidate {
        name: "dvl.mount_yaw",
        channel: ChannelKind::Dvl,
        step: 0.01,
    },
    Candidate {
        name: "dvl.lever_arm",
        channel: ChannelKind::Dvl,
        step: 0.01,
    },
    Candidate {
        name: "dvl.time_offset",
        channel: ChannelKind::Dvl,
        step: 0.005,
    },
    Candidate {
        name: "dvl.bed_velocity",
        channel: ChannelKind::Dvl,
        step: 0.001,
    },
    Candidate {
        name: "dvl.periodic_velocity_error",
        channel: ChannelKind::Dvl,
        step: 0.001,
    },
    Candidate {
        name: "dvl.scale_factor",
        channel: ChannelKind::DvlBeams,
        step: 1e-4,
    },
    Candidate {
        name: "dvl.mount_roll",
        channel: ChannelKind::DvlBeams,
        step: 0.01,
    },
    Candidate {
        name: "dvl.mount_pitch",
        channel: ChannelKind::DvlBeams,
        step: 0.01,
    },
    Candidate {
        name: "dvl.mount_yaw",
        channel: ChannelKind::DvlBeams,
        step: 0.01,
    },
    Candidate {
        name: "dvl.lever_arm",
        channel: ChannelKind::DvlBeams,
        step: 0.01,
    },
    Candidate {
        name: "dvl.time_offset",
        channel: ChannelKind::DvlBeams,
        step: 0.005,
    },
    Candidate {
        name: "dvl.bed_velocity",
        channel: ChannelKind::DvlBeams,
        step: 0.001,
    },
    Candidate {
        name: "dvl.beam_scale_factor",
        channel: ChannelKind::DvlBeams,
        step: 100.0,
    },
    Candidate {
        name: "dvl.beam_angle_error",
        channel: ChannelKind::DvlBeams,
        step: 0.01,
    },
    Candidate {
        name: "depth.bias",
        channel: ChannelKind::Depth,
        step: 0.01,
    },
    Candidate {
        name: "depth.density",
        channel: ChannelKind::Depth,
        step: 0.1,
    },
    Candidate {
        name: "depth.lever_arm",
        channel: ChannelKind::Depth,
        step: 0.01,
    },
    Candidate {
        name: "mag.hard_iron",
        channel: ChannelKind::Magnetometer,
        step: 0.1,
    },
    Candidate {
        name: "mag.declination",
        channel: ChannelKind::Magnetometer,
        step: 0.01,
    },
    Candidate {
        name: "mag.inclination",
        channel: ChannelKind::Magnetometer,
        step: 0.01,
    },
    Candidate {
        name: "mag.intensity",
        channel: ChannelKind::Magnetometer,
        step: 0.1,
    },
    Candidate {
        name: "usbl.hydrophone_offset",
        channel: ChannelKind::AcousticRanges,
        step: 0.01,
    },
    Candidate {
        name: "usbl.sound_speed",
        channel: ChannelKind::AcousticRanges,
        step: 1.0,
    },
    Candidate {
        name: "imu.gyro_bias",
        channel: ChannelKind::Gyro,
        step: 1.0,
    },
    Candidate {
        name: "imu.gyro_scale_factor",
        channel: ChannelKind::Gyro,
        step: 100.0,
    },
    Candidate {
        name: "imu.gyro_misalignment",
        channel: ChannelKind::Gyro,
        step: 0.1,
    },
    Candidate {
        name: "imu.accel_bias",
        channel: ChannelKind::Accelerometer,
        step: 10.0,
    },
    Candidate {
        name: "imu.accel_scale_factor",
        channel: ChannelKind::Accelerometer,
        step: 100.0,
    },
    Candidate {
        name: "imu.accel_misalignment",
        channel: ChannelKind::Accelerometer,
        step: 0.1,
    },
    Candidate {
        name: "mag.hard_iron",
        channel: ChannelKind::MagneticField,
        step: 0.1,
    },
    Candidate {
        name: "mag.inclination",
        channel: ChannelKind::MagneticField,
        step: 0.01,
    },
    Candidate {
        name: "mag.intensity",
        channel: ChannelKind::MagneticField,
        step: 0.1,
    },
];

/// The largest departure from nominal an effect can plausibly have for the sensor classes an
/// AUV carries (tactical MEMS to navigation-grade IMUs, calibrated by their maker): per
/// component, in the effect's unit. An estimate beyond it is not a finding about the sensor —
/// a 9 % accelerometer scale factor or a 28 mrad axis misalignment fitted against a
/// post-processed reference points at that reference (its attitude, its timing) or at an effect
/// outside the vocabulary. The simulator's ranges are wider (what can be simulated, not what a
/// sensor of the class has).
pub const PLAUSIBLE: &[(&str, f64)] = &[
    ("imu.gyro_scale_factor", 10_000.0),
    ("imu.accel_scale_factor", 10_000.0),
    ("imu.gyro_misalignment", 10.0),
    ("imu.accel_misalignment", 10.0),
];

/// The effect's specification in the simulator's vocabulary.
pub fn spec(name: &str) -> Option<&'static auvnav_sim::effects::EffectSpec> {
    auvnav_sim::effects::SPECS.iter().find(|s| s.name == name)
}
