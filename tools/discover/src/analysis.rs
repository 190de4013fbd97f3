//! One voyage's discovery: the channels and the reference collected from log messages
//! ([`Collector`], [`read_logs`]), and the fit, selection, floors and description of what is left
//! ([`discover`]). `command` runs it per voyage or over the voyages (`voyages`), against the
//! truth or the smoothed motion (`smoothed`).
//!
//! Long on purpose: one voyage's discovery (collector, fit, selection, floors, description) in the
//! order the report is built.

pub use super::findings::*;
use super::fit::{self, Problem, Selection};
use super::residuals::{Description, describe};
use super::{Channel, ChannelKind, Reference, spec};
use crate::DiscoverError;
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::{AcousticRangesV1, DepthV1, DvlVelocityV1, MagnetometerV1};
use auvnav_sim::effects::Effects;
use nalgebra::Vector3;
use std::path::PathBuf;

/// Collects the channels and the reference from log messages.
#[derive(Default)]
pub struct Collector {
    truth: Vec<auvnav_shm_schema::TruthStateV1>,
    channels: Vec<Channel>,
    /// The vertical at each magnetometer reading: the specific force since the previous one,
    /// the centripetal acceleration of a turn taken off (as `auvnav calibrate mag` reads it).
    vertical: auvnav_import::mag::VerticalBetweenReadings,
    last_force: Option<[f64; 3]>,
    /// The IMU samples, compared with the reference over intervals once it is complete.
    imu: Vec<super::imu::ImuSample>,
    last_imu_time: Option<f64>,
    /// The DVL is compared through its four beam velocities (the `dvl_beams` channel) instead of
    /// its velocity.
    dvl_beams: bool,
}

impl Collector {
    /// Compare the DVL's beam velocities instead of its velocity (readings with all four beams).
    pub fn with_dvl_beams(mut self, on: bool) -> Collector {
        self.dvl_beams = on;
        self
    }

    /// Let the DVL's bottom track see a moving bed: `dvl.bed_velocity` becomes a candidate.
    pub fn with_moving_bed(mut self, on: bool) -> Collector {
        for c in &mut self.channels {
            if matches!(c.kind, ChannelKind::Dvl | ChannelKind::DvlBeams) {
                c.moving_bed = on;
            }
        }
        self
    }

    pub fn new() -> Collector {
        Collector {
            truth: Vec::new(),
            channels: ChannelKind::ALL.iter().map(|&k| Channel::new(k)).collect(),
            vertical: Default::default(),
            last_force: None,
            imu: Vec::new(),
            last_imu_time: None,
            dvl_beams: false,
        }
    }

    pub fn add(&mut self, m: &LogMessage) {
        if let LogMessage::Dvl(d) = m {
            self.vertical.add_dvl(d);
        }
        match m {
            LogMessage::Truth(t) => self.truth.push(*t),
            LogMessage::Dvl(d) if self.dvl_beams => {
                let c = &mut self.channels[7];
                let all =
                    (0..4).all(|i| d.validity & (DvlVelocityV1::VALID_BEAM_VELOCITY << i) != 0);
                if all && !d.is_water_track() {
                    c.push_beams(d.host_time_ns as f64 * 1e-9, d.beam_velocity_m_s);
                } else {
                    c.skipped += 1;
                }
            }
            LogMessage::Dvl(d) => {
                let c = &mut self.channels[0];
                // Bottom track: the velocity over the ground the model predicts.
                if d.validity & DvlVelocityV1::VALID_VELOCITY != 0 && !d.is_water_track() {
                    c.push(d.host_time_ns as f64 * 1e-9, d.velocity_dvl_m_s);
                } else {
                    c.skipped += 1;
                }
            }
            LogMessage::Depth(d) => {
                let c = &mut self.channels[1];
                if d.validity & DepthV1::VALID_DEPTH != 0 {
                    c.push(d.host_time_ns as f64 * 1e-9, [d.depth_m, 0.0, 0.0]);
                } else {
                    c.skipped += 1;
                }
            }
            LogMessage::AcousticRanges(a) => {
                let c = &mut self.channels[4];
                if a.validity & AcousticRangesV1::VALID_POSITION == 0 {
                    c.skipped += 1;
                    return;
                }
                if a.validity & AcousticRangesV1::VALID_RECEIVER_POSITIONS != 0
                    && c.is_empty()
                    && a.receiver_position_m.iter().all(|x| x.is_finite())
                {
                    c.receivers = a.receiver_position_m;
                }
                let ranges = std::array::from_fn(|k| {
                    if a.range_valid(k) && a.range_m[k] > 0.0 {
                        a.range_m[k]
                    } else {
                        f64::NAN
                    }
                });
                c.push_ranges(a.host_time_ns as f64 * 1e-9, ranges, a.position_array_m);
            }
            LogMessage::Imu(x) => {
                let force = x.specific_force().map(Vector3::from);
                let t = x.host_time_ns as f64 * 1e-9;
                let dt = if x.interval_s.is_finite() && x.interval_s > 0.0 {
                    Some(x.interval_s)
                } else {
                    self.last_imu_time.map(|p| t - p).filter(|d| *d > 0.0)
                };
                self.last_imu_time = Some(t);
                let rate = x.angular_rate().map(Vector3::from);
                self.vertical.add(force, rate);
                match dt {
                    Some(dt_s) if dt_s <= 1.0 && (rate.is_some() || force.is_some()) => {
                        self.imu.push(super::imu::ImuSample {
                            t_end_s: t,
                            dt_s,
                            rate,
                            force,
                        })
                    }
                    _ => {
                        self.channels[5].skipped += 1;
                        self.channels[6].skipped += 1;
                    }
                }
            }
            LogMessage::Magnetometer(m) => {
                let t = m.host_time_ns as f64 * 1e-9;
                if let Some(f) = self.vertical.take(t) {
                    self.last_force = Some(f.into());
                }
                let field = m.field_t.map(|b| b * 1e6);
                if m.validity & MagnetometerV1::VALID_FIELD != 0 {
                    self.channels[2].push(t, field);
                    match self.last_force {
                        Some(f) => self.channels[3].push_field(t, field, f),
                        None => self.channels[3].skipped += 1,
                    }
                } else {
                    self.channels[2].skipped += 1;
                    self.channels[3].skipped += 1;
                }
            }
            _ => {}
        }
    }

    pub fn finish(mut self) -> (Vec<Channel>, Reference) {
        let reference = Reference::from_truth(&self.truth);
        self.imu.sort_by(|a, b| a.t_end_s.total_cmp(&b.t_end_s));
        let (gyro, accel) = super::imu::imu_channels(&self.imu, &reference);
        let skipped = self.channels[5].skipped;
        self.channels[5] = Channel {
            skipped: gyro.skipped + skipped,
            ..gyro
        };
        let skipped = self.channels[6].skipped;
        self.channels[6] = Channel {
            skipped: accel.skipped + skipped,
            ..accel
        };
        (self.channels, reference)
    }
}

/// Discovery with the default nominal model and selection on messages already in memory (an
/// importer's output).
pub fn discover_messages<'a>(messages: impl IntoIterator<Item = &'a LogMessage>) -> DiscoverReport {
    discover_messages_with(Collector::new(), messages)
}

/// [`discover_messages`] into a configured collector (e.g. [`Collector::with_dvl_beams`]).
pub fn discover_messages_with<'a>(
    collector: Collector,
    messages: impl IntoIterator<Item = &'a LogMessage>,
) -> DiscoverReport {
    let mut c = collector;
    for m in messages {
        c.add(m);
    }
    let (channels, reference) = c.finish();
    discover(
        &channels,
        &reference,
        &Effects::default(),
        0.7,
        &Selection::default(),
    )
}

/// The channels and the reference of the logs, and the number of messages that did not decode.
pub fn read_logs(paths: &[PathBuf]) -> Result<(Vec<Channel>, Reference, usize), DiscoverError> {
    read_logs_with(paths, Collector::new())
}

/// [`read_logs`] into a configured collector (e.g. [`Collector::with_dvl_beams`]).
pub fn read_logs_with(
    paths: &[PathBuf],
    collector: Collector,
) -> Result<(Vec<Channel>, Reference, usize), DiscoverError> {
    let mut c = collector;
    let mut undecodable = 0;
    for p in paths {
        let mut reader = LogReader::open(p).map_err(|e| DiscoverError::read(p, e))?;
        while let Some(raw) = reader
            .next_message()
            .map_err(|e| DiscoverError::read(p, e))?
        {
            match raw.decode_any() {
                Ok(m) => c.add(&m),
                Err(_) => undecodable += 1,
            }
        }
    }
    let (channels, reference) = c.finish();
    Ok((channels, reference, undecodable))
}

pub use super::findings::values_of;

/// Component `k` of residuals interleaved `d` per epoch.
fn component(res: &[f64], d: usize, k: usize) -> Vec<f64> {
    res.iter().skip(k).step_by(d).copied().collect()
}

pub(crate) fn json_of(v: &[f64]) -> serde_json::Value {
    let num = |x: f64| {
        serde_json::Number::from_f64(x).map_or(serde_json::Value::Null, serde_json::Value::Number)
    };
    if v.len() == 1 {
        num(v[0])
    } else {
        serde_json::Value::Array(v.iter().map(|&x| num(x)).collect())
    }
}

/// The detection floor of every candidate of `p` not in `set`: fitted with the effects found,
/// the smaller of `min_sigma` deviations and the held-out gain's floor, per component (none where
/// the motion does not excite it).
fn record_floors(
    p: &Problem,
    set: &[usize],
    sep: &fit::Separability,
    sel: &Selection,
    kind: ChannelKind,
    floors: &mut Vec<DetectionFloor>,
) {
    for c in p.candidates() {
        if set.contains(&c) {
            continue;
        }
        let mut with = set.to_vec();
        with.push(c);
        let fc = p.fit(&with, &p.epochs);
        let (off, len) = fit::offset_of(&with, c);
        let dead = sep
            .unexcited
            .iter()
            .find(|(u, _)| *u == c)
            .map(|(_, comps)| comps.clone())
            .unwrap_or_default();
        // Named takes both tests: min_sigma deviations, and a held-out score lower by
        // min_gain.
        let gain = p.gain_floor(set, c, sel.min_gain);
        let floor = (0..len)
            .map(|k| {
                let s = fc.std[off + k];
                (!dead.contains(&k) && s.is_finite() && s > 0.0)
                    .then(|| (sel.min_sigma * s).max(gain[k]))
            })
            .collect();
        floors.push(DetectionFloor {
            name: fit::name(c).into(),
            channel: kind,
            floor,
            unit: spec(fit::name(c)).map_or("", |s| s.unit).into(),
            sigmas: sel.min_sigma,
        });
    }
    // No line stands out of the residual's spectrum: the periodic error is not a candidate, and
    // its floor is the amplitude that would have made its line stand out.
    if let Some(line) = p.channel.periodic_line.filter(|l| !l.stands_out()) {
        floors.push(DetectionFloor {
            name: crate::periodic::EFFECT.into(),
            channel: kind,
            floor: line
                .floor_m_s
                .iter()
                .map(|f| f.is_finite().then_some(*f))
                .collect(),
            unit: "m/s".into(),
            sigmas: sel.min_sigma,
        });
    }
}

/// The effects selected on `ch` (`steps`, fitted as `f` into the model `full`) into the report,
/// with their evidence: held-out gain, rivals the motion cannot separate, groups of other
/// candidates that mimic a component together, and the sound-speed equivalent of a DVL scale.
#[allow(clippy::too_many_arguments)]
fn record_effects(
    ch: &Channel,
    reference: &Reference,
    nominal: &Effects,
    sel: &Selection,
    steps: &[fit::Step],
    set: &[usize],
    f: &fit::Fit,
    full: &Effects,
    r: &mut DiscoverReport,
) {
    let kind = ch.kind;
    // Effects a group of other candidates mimics together, at the fitted model.
    let confounded = {
        let at_fit = Problem::new(ch, reference, full.clone());
        fit::confounded(&fit::separability(&at_fit), set, sel.max_correlation)
    };
    for s in steps {
        let (off, len) = fit::offset_of(set, s.candidate);
        let name = fit::name(s.candidate);
        let std: Vec<f64> = f.std[off..off + len].to_vec();
        let gain = 1.0 - s.mse_after / s.mse_before;
        let mut evidence = format!(
            "held-out mean squared residual {:.4e} -> {:.4e} ({:.1} % lower)",
            s.mse_before,
            s.mse_after,
            100.0 * gain
        );
        for (rival, corr) in &s.rivals {
            evidence.push_str(&format!(
                "; {} explains the data about as well (correlation {corr:.3})",
                fit::name(*rival)
            ));
            r.unseparable.push(Unseparable {
                effects: vec![name.into(), fit::name(*rival).into()],
                correlation: *corr,
                note: format!(
                    "the motion cannot separate them; reported as {name}, which scored best or, \
                     within the held-out score's noise, has fewer parameters"
                ),
            });
        }
        for c in confounded.iter().filter(|c| c.candidate == s.candidate) {
            let group: Vec<&str> = c.group.iter().map(|&g| fit::name(g)).collect();
            let held: Vec<String> = group
                .iter()
                .map(|g| {
                    let v = full.get(g).unwrap_or_default();
                    format!("{g} = {}", json_of(&v))
                })
                .collect();
            evidence.push_str(&format!(
                "; component {} is mimicked by {} together (correlation {:.3}): its estimate \
                 and std hold only with {}",
                c.component,
                group.join(" and "),
                c.correlation,
                held.join(", ")
            ));
            let mut effects = vec![name.to_string()];
            effects.extend(group.iter().map(|g| g.to_string()));
            let same_set = |u: &Unseparable| {
                let (mut a, mut b) = (u.effects.clone(), effects.clone());
                a.sort();
                b.sort();
                a == b
            };
            if r.unseparable.iter().any(same_set) {
                continue;
            }
            r.unseparable.push(Unseparable {
                effects,
                correlation: c.correlation,
                note: format!(
                    "component {} of {name} is a combination of the others on this motion: \
                     the data cannot determine them together; {name} is reported with the \
                     others at the model's values",
                    c.component
                ),
            });
        }
        let equivalent = if name == "dvl.scale_factor" {
            let first = |n: &str, default: f64| {
                nominal
                    .get(n)
                    .and_then(|v| v.first().copied())
                    .unwrap_or(default)
            };
            sound_speed_equivalent(
                f.theta[off],
                std.first().copied().unwrap_or(f64::NAN),
                first("dvl.scale_factor", 1.0),
                first("dvl.sound_speed", auvnav_sim::sensors::ASSUMED_SOUND_SPEED),
            )
        } else {
            None
        };
        let line = ch.periodic_line.filter(|_| name == crate::periodic::EFFECT);
        if let Some(l) = &line {
            evidence.push_str(&format!(
                "; at the residual's strongest line: period {:.2} ± {:.2} s, phase {:.1} ± {:.1}° \
                 ({:.0} cycles, {:.0} times the spectrum around it)",
                l.period_s,
                l.period_std_s,
                l.phase_deg,
                l.phase_std_deg,
                l.cycles,
                l.line_to_background
            ));
        }
        r.effects.push(FoundEffect {
            name: name.into(),
            value: json_of(&f.theta[off..off + len]),
            std: json_of(&std),
            nominal: json_of(&nominal.get(name).unwrap_or_default()),
            unit: spec(name).map_or("", |s| s.unit).into(),
            channel: kind,
            evidence,
            gain,
            equivalent,
            line,
        });
    }
}

/// The pairs of candidates the motion cannot separate (correlation above `max_correlation`), not
/// already reported.
fn record_unseparable_pairs(
    sep: &fit::Separability,
    sel: &Selection,
    unseparable: &mut Vec<Unseparable>,
) {
    for &(a, b, c) in &sep.pairs {
        if c > sel.max_correlation
            && !unseparable.iter().any(|u| {
                (u.effects[0] == fit::name(a) && u.effects[1] == fit::name(b))
                    || (u.effects[0] == fit::name(b) && u.effects[1] == fit::name(a))
            })
        {
            unseparable.push(Unseparable {
                effects: vec![fit::name(a).into(), fit::name(b).into()],
                correlation: c,
                note: "not separable on this motion".into(),
            });
        }
    }
}

/// What a channel's residuals are compared with: the motion (speed, turn and pitch rates,
/// forward specific force, depth, time), the acoustic fix's geometry, or the field's own terms.
fn regressors(
    ch: &Channel,
    epochs: &[usize],
    times: &[f64],
    reference: &Reference,
    nominal: &Effects,
) -> Vec<(&'static str, Vec<f64>)> {
    let states: Vec<_> = times.iter().map(|&t| reference.at(t)).collect();
    let reg = |g: &dyn Fn(&super::RefState) -> f64| -> Vec<f64> {
        states.iter().map(|s| s.as_ref().map_or(0.0, g)).collect()
    };
    if ch.kind == ChannelKind::MagneticField {
        field_regressors(ch, epochs, times, nominal)
    } else if ch.kind == ChannelKind::AcousticRanges {
        let fix = |g: &dyn Fn(&[f64; 3]) -> f64| -> Vec<f64> {
            epochs.iter().map(|&i| g(&ch.auxiliary[i])).collect()
        };
        vec![
            ("slant_range", fix(&|x| x[0].hypot(x[1]).hypot(x[2]))),
            ("horizontal_range", fix(&|x| x[0].hypot(x[1]))),
            ("fix_depth", fix(&|x| x[2])),
            ("fix_x", fix(&|x| x[0])),
            ("fix_y", fix(&|x| x[1])),
            ("time", times.iter().map(|t| t - times[0]).collect()),
        ]
    } else {
        vec![
            ("speed", reg(&|s| s.velocity_ned.norm())),
            ("yaw_rate", reg(&|s| s.omega_eb_body.z)),
            ("pitch_rate", reg(&|s| s.omega_eb_body.y)),
            ("forward_specific_force", reg(&|s| s.specific_force_body.x)),
            ("depth", reg(&|s| -s.height_m)),
            ("time", times.iter().map(|t| t - times[0]).collect()),
        ]
    }
}

/// Which of `epochs` hold component `k` (a partial reading, a receiver without a range, lacks
/// some; those are left out).
fn present(ch: &Channel, epochs: &[usize], k: usize) -> Vec<bool> {
    epochs
        .iter()
        .map(|&i| ch.values[i][k].is_finite())
        .collect()
}

/// A note for every component whose residual, with the effects found, is not white: how far
/// from white, anti-correlation, a periodic part, correlation with the motion.
fn record_unexplained(
    selected_desc: &[Description],
    kind: ChannelKind,
    unexplained: &mut Vec<Unexplained>,
) {
    for (k, desc) in selected_desc.iter().enumerate() {
        if desc.white {
            continue;
        }
        let mut note = format!(
            "not white (Ljung-Box Q {:.0} > {:.1}; lag-1 autocorrelation {:.2}); rms {:.4} {}",
            desc.ljung_box_q,
            super::residuals::CHI2_20_99,
            desc.lag1,
            desc.rms,
            kind.unit()
        );
        if desc.lag1 < -0.25 {
            note.push_str(
                "; successive residuals anti-correlated: the noise of a difference (a \
                 reference's attitude or velocity noise enters neighbouring intervals with \
                 opposite signs)",
            );
        }
        if let Some(f) = desc.peak_hz {
            note.push_str(&format!("; periodic at {f:.4} Hz"));
        }
        for (name, c) in &desc.correlated_with {
            note.push_str(&format!("; correlated with {name} ({c:+.2})"));
        }
        unexplained.push(Unexplained {
            channel: kind,
            component: k,
            note,
        });
    }
}

/// The held-out gain of the selected `set` on `ch`: fitted on the first `fit_fraction` of the
/// epochs, scored on the rest; the report's model takes the values of the fit on every epoch
/// (`full`), its held-out model those of the first part.
fn record_gain(
    ch: &Channel,
    p: &Problem,
    set: &[usize],
    nominal: &Effects,
    full: &Effects,
    fit_fraction: f64,
    r: &mut DiscoverReport,
) {
    let kind = ch.kind;
    let d = kind.dims();
    let cut = ((p.epochs.len() as f64) * fit_fraction).round() as usize;
    let (train, test) = p.epochs.split_at(cut.clamp(1, p.epochs.len() - 1));
    let ft = p.fit(set, train);
    let rms = |res: Vec<f64>| -> Vec<f64> {
        (0..d)
            .map(|k| {
                let v: Vec<f64> = component(&res, d, k)
                    .into_iter()
                    .zip(present(ch, test, k))
                    .filter(|x| x.1)
                    .map(|x| x.0)
                    .collect();
                (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
            })
            .collect()
    };
    let held_out = p.effects(set, &ft.theta);
    r.gain.push(ChannelGain {
        channel: kind,
        fit_fraction,
        rms_before: rms(p.residuals(nominal, test)),
        rms_after: rms(p.residuals(&held_out, test)),
    });
    for &c in set {
        let name = fit::name(c);
        for (model, from) in [(&mut r.model, full), (&mut r.held_out_model, &held_out)] {
            if let Some(v) = from.get(name) {
                // In range: the fit clamps to the effect's range.
                let _ = model.set(name, &v);
            }
        }
    }
}

/// Each component of a residual series (`res`, over `p`'s epochs at `times`) described: level,
/// spread, whiteness, periodic part and correlation with the motion (`regressors`), on the
/// readings that hold the component.
fn describe_components(
    ch: &Channel,
    p: &Problem,
    times: &[f64],
    regressors: &[(&'static str, Vec<f64>)],
    res: &[f64],
) -> Vec<Description> {
    let d = ch.kind.dims();
    (0..d)
        .map(|k| {
            let keep = present(ch, &p.epochs, k);
            let pick = |v: &[f64]| -> Vec<f64> {
                v.iter().zip(&keep).filter(|x| *x.1).map(|x| *x.0).collect()
            };
            let regs: Vec<(&str, Vec<f64>)> =
                regressors.iter().map(|(n, v)| (*n, pick(v))).collect();
            describe(&pick(times), &pick(&component(res, d, k)), &regs)
        })
        .collect()
}

/// Whether `ch` is left out of the analysis, with the reason in the report's notes: the field's
/// magnitude when the full field vector is analysed, a channel without valid readings, the DVL
/// channel the beams replace (or the other way round), a channel that needs a reference motion
/// the logs lack.
fn skipped(ch: &Channel, channels: &[Channel], no_reference: bool, r: &mut DiscoverReport) -> bool {
    let kind = ch.kind;
    if kind == ChannelKind::MagneticField
        && r.channels
            .iter()
            .any(|c| c.channel == ChannelKind::Magnetometer)
    {
        // The full field vector against the reference attitude says more.
        return true;
    }
    if ch.is_empty() {
        let beams_mode = channels
            .iter()
            .any(|c| c.kind == ChannelKind::DvlBeams && (!c.is_empty() || c.skipped > 0));
        if (kind == ChannelKind::Dvl && beams_mode)
            || (kind == ChannelKind::DvlBeams && !beams_mode)
        {
            // The DVL is analysed through one of its two channels.
            return true;
        }
        if kind != ChannelKind::MagneticField {
            r.notes
                .push(format!("{}: no valid readings in the logs", kind.name()));
        } else if channels
            .iter()
            .any(|c| c.kind == ChannelKind::Magnetometer && !c.is_empty())
        {
            r.notes.push(
                "magnetic_field: no accelerometer readings with the magnetometer's: the \
                 field's dip cannot be formed"
                    .into(),
            );
        }
        return true;
    }
    if no_reference && kind.needs_reference() {
        r.notes.push(format!(
            "{}: {} readings, but no reference motion to compare them with",
            kind.name(),
            ch.len()
        ));
        return true;
    }
    false
}

/// Runs discovery on channels against a reference with a nominal model.
pub fn discover(
    channels: &[Channel],
    reference: &Reference,
    nominal: &Effects,
    fit_fraction: f64,
    sel: &Selection,
) -> DiscoverReport {
    let start = std::time::Instant::now();
    let mut r = DiscoverReport::new(nominal);
    let no_reference = reference.len() < 2;
    if no_reference {
        r.notes.push(
            "no reference motion in the logs: only channels that need none (the magnetic field's \
             magnitude and dip, acoustic ranges against the device's own fixes) can be analysed \
             (simulated logs carry the truth topic)"
                .into(),
        );
    }
    for ch in channels {
        let kind = ch.kind;
        if skipped(ch, channels, no_reference, &mut r) {
            continue;
        }
        if kind == ChannelKind::AcousticRanges && ch.receivers.iter().all(|x| *x == 0.0) {
            r.notes.push(
                "acoustic_ranges: the logs do not give the receivers' configured positions: \
                 usbl.hydrophone_offset is each receiver's position in the frame of the device's \
                 fixes, not a correction to a configured geometry"
                    .into(),
            );
        }
        let screened;
        let ch = if kind.partial() {
            screened = screen_outliers(ch, reference, nominal, &mut r);
            &screened
        } else if let Some(lined) = crate::periodic::with_line(ch, reference, nominal) {
            screened = lined;
            &screened
        } else {
            ch
        };
        let p = Problem::new(ch, reference, nominal.clone());
        if p.epochs.len() < 10 * fit::FOLDS {
            r.notes.push(format!(
                "{}: {} of {} readings inside the reference: too few to analyse (at least {})",
                kind.name(),
                p.epochs.len(),
                ch.len(),
                10 * fit::FOLDS
            ));
            continue;
        }
        let r0 = p.residuals(nominal, &p.epochs);
        let d = kind.dims();
        let identical = p.epochs.iter().enumerate().all(|(n, &i)| {
            (0..d).all(|k| r0[n * d + k].abs() <= 1e-9 * (1.0 + ch.values[i][k].abs()))
        });
        if identical {
            r.notes.push(format!(
                "{}: identical to the reference prediction (derived from the reference?): nothing \
                 to learn from it",
                kind.name()
            ));
            continue;
        }
        let sep = fit::separability(&p);
        for (c, comps) in &sep.unexcited {
            r.unobservable.push(Unobservable {
                name: fit::name(*c).into(),
                components: comps.clone(),
            });
        }
        let selected = if fit::parsimonious(kind) {
            fit::select_parsimonious(&p, sel, &sep)
        } else {
            fit::select(&p, sel, &sep)
        };
        if let Some(u) = &selected.undetermined {
            record_undetermined(&p, u, sel, kind, &mut r);
        }
        let base_mse = selected.base;
        let steps = drop_implausible(&p, selected.steps, base_mse, kind, &mut r);
        let set: Vec<usize> = steps.iter().map(|s| s.candidate).collect();
        let f = p.fit(&set, &p.epochs);
        let full = p.effects(&set, &f.theta);
        // The floor of every candidate not named: fitted with the effects found.
        record_floors(&p, &set, &sep, sel, kind, &mut r.floors);
        let lags = fit::correlation_lags(&p.residuals(&full, &p.epochs), d);
        if lags > 0 {
            r.notes.push(format!(
                "{}: the residual with the effects found stays correlated over {lags} readings; \
                 the standard deviations and the significance test allow for it (Newey–West){}",
                kind.name(),
                if set.is_empty() {
                    String::new()
                } else {
                    format!(", {:.1}× wider than for white residuals", f.widening)
                }
            ));
        }
        // Effects a group of other candidates mimics together, at the fitted model.
        record_effects(ch, reference, nominal, sel, &steps, &set, &f, &full, &mut r);
        // Pairs the motion cannot separate among the channel's candidates (for the reader, even
        // when neither was selected).
        record_unseparable_pairs(&sep, sel, &mut r.unseparable);
        // Describe the residuals before and after.
        let d = kind.dims();
        let times: Vec<f64> = p.epochs.iter().map(|&i| ch.times[i]).collect();
        let regressors = regressors(ch, &p.epochs, &times, reference, nominal);
        let describe_all = |res: &[f64]| describe_components(ch, &p, &times, &regressors, res);
        let nominal_desc = describe_all(&r0);
        let r1 = p.residuals(&full, &p.epochs);
        let selected_desc = describe_all(&r1);
        record_unexplained(&selected_desc, kind, &mut r.unexplained);
        // Held-out gain: the selected set fitted on the first part, scored on the rest.
        record_gain(ch, &p, &set, nominal, &full, fit_fraction, &mut r);
        let rms_all: Vec<f64> = selected_desc.iter().map(|d| d.rms).collect();
        let spacing_s = median_spacing(&times);
        let allan = if matches!(kind, ChannelKind::Gyro | ChannelKind::Accelerometer) {
            allan_points(&r1, d, spacing_s)
        } else {
            Vec::new()
        };
        r.noise.extend(super::outputs::noise_estimates(
            &p, &set, &rms_all, spacing_s,
        ));
        r.residuals.push(ResidualSeries {
            channel: kind,
            times: times.clone(),
            nominal: r0.clone(),
            selected: r1,
        });
        r.channels.push(ChannelReport {
            channel: kind,
            unit: kind.unit().into(),
            epochs: ch.len(),
            skipped: ch.skipped,
            compared: p.epochs.len(),
            held_out_mse_nominal: base_mse,
            held_out_mse_selected: steps.last().map_or(base_mse, |s| s.mse_after),
            nominal: nominal_desc,
            selected: selected_desc,
            allan,
            line: ch.periodic_line,
        });
    }
    r.wall_s = start.elapsed().as_secs_f64();
    r
}

/// A value and its deviation to the deviation's second significant digit, per component
/// (`[a, b, c] ± [d, e, f]` for a vector).
pub(crate) fn with_deviation(value: &[f64], std: &[f64]) -> String {
    let (mut vs, mut ss) = (Vec::new(), Vec::new());
    for (v, s) in value.iter().zip(std) {
        let decimals = if s.is_finite() && *s > 0.0 {
            (1 - s.log10().floor() as i64).clamp(0, 9) as usize
        } else {
            3
        };
        vs.push(format!("{v:.decimals$}"));
        ss.push(format!("{s:.decimals$}"));
    }
    if vs.len() == 1 {
        format!("{} ± {}", vs[0], ss[0])
    } else {
        format!("[{}] ± [{}]", vs.join(", "), ss.join(", "))
    }
}

/// The candidate where the selection stopped for want of significance, with its estimate.
fn record_undetermined(
    p: &Problem,
    u: &fit::Undetermined,
    sel: &Selection,
    kind: ChannelKind,
    r: &mut DiscoverReport,
) {
    let name = fit::name(u.candidate);
    let (off, len) = fit::offset_of(&u.set, u.candidate);
    // A fit the readings cannot solve (no finite deviation) points at nothing.
    if u.fit.std[off..off + len].iter().all(|s| !s.is_finite()) {
        return;
    }
    let nominal = p.nominal_theta(&u.set);
    let sigmas = fit::departure_sigmas(&u.fit, &nominal, &u.set, u.candidate);
    let widening = (off..off + len)
        .filter(|&k| u.fit.std_white[k] > 0.0 && u.fit.std_white[k].is_finite())
        .map(|k| u.fit.std[k] / u.fit.std_white[k])
        .fold(1.0, f64::max);
    let value = json_of(&u.fit.theta[off..off + len]);
    let std = json_of(&u.fit.std[off..off + len]);
    let unit = spec(name).map_or("", |s| s.unit);
    let note = format!(
        "{name} ({}): {} {unit}, {sigmas:.1}σ from nominal where the test asks {}σ; it \
         lowers the held-out score {:.3e} → {:.3e}, but the residual's correlation in time \
         makes its deviation {widening:.1}× what white residuals would give: these data point \
         at it without determining it (not named)",
        kind.name(),
        with_deviation(&u.fit.theta[off..off + len], &u.fit.std[off..off + len]),
        sel.min_sigma,
        u.mse_before,
        u.mse_after
    );
    r.undetermined.push(super::findings::Undetermined {
        name: name.into(),
        channel: kind,
        value,
        std,
        nominal: json_of(&nominal[off..off + len]),
        unit: unit.into(),
        sigmas,
        widening,
        held_out_before: u.mse_before,
        held_out_after: u.mse_after,
        note,
    });
}

/// The selected `steps` without the effects whose estimate lies beyond what the sensor's class
/// allows ([`crate::PLAUSIBLE`]), each recorded in the report with a note.
fn drop_implausible(
    p: &Problem,
    steps: Vec<fit::Step>,
    base_mse: f64,
    kind: ChannelKind,
    r: &mut DiscoverReport,
) -> Vec<fit::Step> {
    let set: Vec<usize> = steps.iter().map(|s| s.candidate).collect();
    let bounded = |c: &usize| crate::PLAUSIBLE.iter().any(|(n, _)| *n == fit::name(*c));
    if !set.iter().any(bounded) {
        return steps;
    }
    let f = p.fit(&set, &p.epochs);
    let nominal = p.nominal_theta(&set);
    let mut drop = Vec::new();
    for &c in &set {
        let name = fit::name(c);
        let Some(&(_, limit)) = crate::PLAUSIBLE.iter().find(|(n, _)| *n == name) else {
            continue;
        };
        let (off, len) = fit::offset_of(&set, c);
        if !(off..off + len).any(|k| (f.theta[k] - nominal[k]).abs() > limit) {
            continue;
        }
        let value: Vec<f64> = f.theta[off..off + len].to_vec();
        let unit = crate::spec(name).map_or("", |s| s.unit).to_string();
        let shown: Vec<String> = value.iter().map(|v| super::findings::sig(*v)).collect();
        let note = format!(
            "{name} ({}): fitted [{}] {unit}, beyond ±{limit} {unit}, more than the IMUs an AUV \
             carries have: not named; it points at the reference (its attitude or timing) or at \
             an effect outside the vocabulary",
            kind.name(),
            shown.join(", ")
        );
        r.notes.push(note.clone());
        r.implausible.push(super::findings::Implausible {
            name: name.to_string(),
            channel: kind,
            value: serde_json::json!(value),
            unit,
            limit,
            note,
        });
        drop.push(c);
    }
    if drop.is_empty() {
        steps
    } else {
        fit::without(p, steps, base_mse, &drop)
    }
}

/// Outliers beyond this many robust standard deviations (1.4826 × the median absolute residual)
/// are left out of a partial channel before the analysis.
pub const OUTLIER_SIGMAS: f64 = 5.0;

/// A partial channel (acoustic ranges) without its outliers: every candidate is fitted on all
/// readings, and the components whose residual lies beyond [`OUTLIER_SIGMAS`] robust standard
/// deviations of that component are set aside (NaN); the count, their sizes and the outlier
/// fraction (`usbl.outlier_fraction`, for the effect set) go into the report. A least-squares fit
/// of the geometry would otherwise follow a few multipath ranges tens of metres long.
pub(crate) fn screen_outliers(
    ch: &Channel,
    reference: &Reference,
    nominal: &Effects,
    r: &mut DiscoverReport,
) -> Channel {
    let p = Problem::new(ch, reference, nominal.clone());
    let mut out = ch.clone();
    if p.epochs.len() < 10 * fit::FOLDS {
        return out;
    }
    let all = p.candidates();
    let f = p.fit(&all, &p.epochs);
    let res = p.residuals(&p.effects(&all, &f.theta), &p.epochs);
    let d = ch.kind.dims();
    let (mut total, mut outliers) = (0usize, Vec::new());
    for k in 0..d {
        let idx: Vec<usize> = (0..p.epochs.len())
            .filter(|&n| ch.values[p.epochs[n]][k].is_finite())
            .collect();
        let mut abs: Vec<f64> = idx.iter().map(|&n| res[n * d + k].abs()).collect();
        if abs.is_empty() {
            continue;
        }
        total += abs.len();
        abs.sort_by(f64::total_cmp);
        let sigma = 1.4826 * abs[abs.len() / 2];
        for &n in &idx {
            let e = res[n * d + k];
            if sigma > 0.0 && e.abs() > OUTLIER_SIGMAS * sigma {
                out.values[p.epochs[n]][k] = f64::NAN;
                outliers.push(e);
            }
        }
    }
    if !outliers.is_empty() {
        let fraction = outliers.len() as f64 / total.max(1) as f64;
        let longer = outliers.iter().filter(|e| **e > 0.0).count();
        let (lo, hi) = outliers
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), e| {
                (lo.min(e.abs()), hi.max(e.abs()))
            });
        r.notes.push(format!(
            "{}: {} of {} readings ({:.2} %) are outliers beyond {OUTLIER_SIGMAS} robust \
             standard deviations of a fit of every candidate, {} of them longer than predicted \
             (multipath), |error| {lo:.2} to {hi:.2} {}: left out of the analysis",
            ch.kind.name(),
            outliers.len(),
            total,
            100.0 * fraction,
            longer,
            ch.kind.unit()
        ));
        if ch.kind == ChannelKind::AcousticRanges {
            r.noise.push(NoiseEstimate {
                name: "usbl.outlier_fraction".into(),
                value: fraction,
                unit: "1".into(),
                channel: ch.kind,
                note: format!(
                    "readings beyond {OUTLIER_SIGMAS} robust standard deviations; sizes \
                     {lo:.2} to {hi:.2} m ({longer} of {} longer than predicted)",
                    outliers.len()
                ),
            });
        }
    }
    out
}

/// The Allan deviation of each component of `res` (`d` components, readings `spacing_s` apart).
fn allan_points(res: &[f64], d: usize, spacing_s: f64) -> Vec<AllanPoint> {
    let per: Vec<Vec<(f64, f64)>> = (0..d)
        .map(|k| super::imu::allan_deviation(&component(res, d, k), spacing_s))
        .collect();
    let n = per.iter().map(Vec::len).min().unwrap_or(0);
    (0..n)
        .map(|i| AllanPoint {
            tau_s: per[0][i].0,
            deviation: per.iter().map(|c| c[i].1).collect(),
        })
        .collect()
}

/// The median interval between successive readings (s; 0 for fewer than two).
fn median_spacing(times: &[f64]) -> f64 {
    let mut d: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(0.0)
}

/// The motion regressors of the magnetic-field channel, from the readings themselves: the
/// specific force's deviation from its median magnitude (accelerations the dip takes for tilt),
/// the vertical's direction in sensor axes (tilt), the nominally corrected field's direction in
/// sensor axes (what a soft iron or a mis-scaled axis correlates with) and time.
fn field_regressors(
    ch: &Channel,
    epochs: &[usize],
    times: &[f64],
    nominal: &Effects,
) -> Vec<(&'static str, Vec<f64>)> {
    let force: Vec<Vector3<f64>> = epochs
        .iter()
        .map(|&i| Vector3::from(ch.auxiliary[i]))
        .collect();
    let mut mags: Vec<f64> = force.iter().map(|f| f.norm()).collect();
    mags.sort_by(f64::total_cmp);
    let median = mags.get(mags.len() / 2).copied().unwrap_or(1.0).max(1e-12);
    let field: Vec<Vector3<f64>> = epochs
        .iter()
        .map(|&i| {
            auvnav_sim::sensors::MagnetometerModel::body_field(
                nominal,
                &Vector3::new(ch.values[i][0], ch.values[i][1], ch.values[i][2]),
            )
            .and_then(|b| b.try_normalize(1e-12))
            .unwrap_or_else(Vector3::zeros)
        })
        .collect();
    let up = |k: usize| -> Vec<f64> { force.iter().map(|f| f[k] / f.norm()).collect() };
    let dir = |k: usize| -> Vec<f64> { field.iter().map(|b| b[k]).collect() };
    vec![
        (
            "dynamic_acceleration",
            force.iter().map(|f| f.norm() / median - 1.0).collect(),
        ),
        ("vertical_x", up(0)),
        ("vertical_y", up(1)),
        ("vertical_z", up(2)),
        ("field_direction_x", dir(0)),
        ("field_direction_y", dir(1)),
        ("field_direction_z", dir(2)),
        ("time", times.iter().map(|t| t - times[0]).collect()),
    ]
}
