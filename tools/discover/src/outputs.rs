//! What discovery found, in the forms other tools take: an effect set for the simulator
//! (`auvnav sim --effects-from`), a navigator configuration (the calibration the daemon and
//! `auvnav replay` take); the navigation error before/after is in `navigation`.

use super::ChannelKind;
use super::findings::{DiscoverReport, NavigationGain};
use auvnav_core::aid::magnetometer::MagnetometerConfig;
use auvnav_core::config::DvlInstallation;
use auvnav_sim::effects::{self, Effects};
use auvnav_sim::sensors::{MagnetometerModel, dvl_velocity_std_per_beam_noise};
use serde::Serialize;

/// The simulator's noise effect of a channel from the RMS per component of its residual with the
/// effects found. `dvl.noise` is per beam: each DVL-frame component's RMS is divided by what one
/// unit of beam noise gives that component. The IMU channels are means over intervals of
/// `spacing_s`: white noise of density N gives N / √spacing, so the random walks are the RMS
/// times √spacing (in the effects' units).
pub fn noise_estimate(
    kind: ChannelKind,
    rms: &[f64],
    spacing_s: f64,
) -> super::findings::NoiseEstimate {
    let rms_all = (rms.iter().map(|r| r * r).sum::<f64>() / rms.len().max(1) as f64).sqrt();
    let (name, value) = match kind {
        // deg/h × √s → deg/√h: × √(s / 3600).
        ChannelKind::Gyro => (
            "imu.angle_random_walk",
            rms_all * (spacing_s / 3600.0).sqrt(),
        ),
        // µg × √s → m/s/√h: × 9.80665e-6 × √s × 60.
        ChannelKind::Accelerometer => (
            "imu.velocity_random_walk",
            rms_all * auvnav_sim::sensors::MICRO_G * spacing_s.sqrt() * 60.0,
        ),
        ChannelKind::Dvl => {
            let per = dvl_velocity_std_per_beam_noise();
            let m = rms
                .iter()
                .zip(per.iter())
                .map(|(r, f)| (r / f).powi(2))
                .sum::<f64>()
                / rms.len().max(1) as f64;
            ("dvl.noise", m.sqrt())
        }
        // The beams' residual is the per-beam noise itself.
        ChannelKind::DvlBeams => ("dvl.noise", rms_all),
        ChannelKind::Depth => ("depth.noise", rms.first().copied().unwrap_or(0.0)),
        ChannelKind::AcousticRanges => ("usbl.range_noise", rms_all),
        ChannelKind::Magnetometer | ChannelKind::MagneticField => ("mag.noise", rms_all),
    };
    noise_named(
        name,
        value,
        kind,
        "RMS of the residual with the effects found: an upper bound on the white noise when \
         structure is left unexplained",
    )
}

/// A noise effect in the simulator's name and unit, its value clamped to the effect's range.
fn noise_named(
    name: &str,
    value: f64,
    kind: ChannelKind,
    note: &str,
) -> super::findings::NoiseEstimate {
    let spec = super::spec(name);
    super::findings::NoiseEstimate {
        name: name.into(),
        value: spec.map_or(value, |s| value.clamp(s.min, s.max)),
        unit: spec.map_or("", |s| s.unit).into(),
        channel: kind,
        note: note.into(),
    }
}

/// A channel's noise effects: [`noise_estimate`] from the RMS of its residual with the effects
/// found (`set` on the problem `p`), and for the DVL, where that residual shows a
/// time-correlated part (per DVL-frame component the Gauss–Markov variance, the white variance
/// and φ per reading of spacing `spacing_s`, by restricted likelihood searched from three
/// starts: this is the sensor's noise a report gives), that part as the simulator's
/// `dvl.velocity_error_instability` (the RMS over the three axes of the Gauss–Markov deviation)
/// and `dvl.velocity_error_correlation_time` (−spacing / ln φ, the geometric mean over the axes
/// that show one), and `dvl.noise` from the white part alone.
pub fn noise_estimates(
    p: &super::fit::Problem,
    set: &[usize],
    rms: &[f64],
    spacing_s: f64,
) -> Vec<super::findings::NoiseEstimate> {
    let kind = p.channel.kind;
    if kind != ChannelKind::Dvl {
        return vec![noise_estimate(kind, rms, spacing_s)];
    }
    let noise_model = p.noise_of(set, 3).1;
    let correlated: Vec<super::noise::GaussMarkov> =
        noise_model.iter().flatten().copied().collect();
    if correlated.is_empty() || noise_model.len() != rms.len() {
        return vec![noise_estimate(kind, rms, spacing_s)];
    }
    // The white part per component (the RMS where a component shows no correlated part).
    let white: Vec<f64> = noise_model
        .iter()
        .zip(rms)
        .map(|(m, r)| m.map_or(*r, |(_, w, _)| w.sqrt()))
        .collect();
    let mut white_noise = noise_estimate(kind, &white, spacing_s);
    white_noise.note = "the white part of the residual with the effects found, beside its \
                        Gauss–Markov part (restricted likelihood)"
        .into();
    let sigma = (correlated.iter().map(|(g, _, _)| g).sum::<f64>() / rms.len() as f64).sqrt();
    let taus: Vec<f64> = correlated
        .iter()
        .filter(|(_, _, phi)| *phi > 0.0 && *phi < 1.0)
        .map(|(_, _, phi)| -spacing_s / phi.ln())
        .collect();
    let mut out = vec![white_noise];
    let note = format!(
        "the time-correlated part of the residual with the effects found (a first-order \
         Gauss–Markov error by restricted likelihood, on {} of {} DVL-frame axes)",
        correlated.len(),
        rms.len()
    );
    out.push(noise_named(
        "dvl.velocity_error_instability",
        sigma,
        kind,
        &note,
    ));
    if !taus.is_empty() {
        let tau = (taus.iter().map(|t| t.ln()).sum::<f64>() / taus.len() as f64).exp();
        out.push(noise_named(
            "dvl.velocity_error_correlation_time",
            tau,
            kind,
            &note,
        ));
    }
    out
}

/// The effect set of the extended model: every effect that differs from the simulator's
/// defaults (the nominal settings and the effects found), and each analysed channel's noise.
pub fn effect_set(r: &DiscoverReport) -> Vec<(String, Vec<f64>)> {
    let mut model = r.model.clone();
    for n in &r.noise {
        let _ = model.set(&n.name, &[n.value]);
    }
    effects::set::differences(&model)
}

/// The effect set file's text.
pub fn effect_set_toml(r: &DiscoverReport) -> String {
    let comment = format!(
        "Effect set from `auvnav discover` on {}.\n\
         The nominal model, the effects found and each channel's residual noise, in the\n\
         simulator's names and units: `auvnav sim --effects-from THIS_FILE` simulates with them.",
        r.inputs.join(", ")
    );
    effects::set::to_toml(&comment, &effect_set(r))
}

/// The navigator's installation tables for a model: the DVL installation when the DVL channel was
/// analysed, the magnetometer calibration when the magnetometer channel was.
pub fn navigator_tables(
    e: &Effects,
    analysed: &[ChannelKind],
    source: &str,
) -> (Option<DvlInstallation>, Option<MagnetometerConfig>) {
    let dvl = (analysed.contains(&ChannelKind::Dvl) || analysed.contains(&ChannelKind::DvlBeams))
        .then(|| DvlInstallation {
            mount_deg: [e.dvl_mount_roll, e.dvl_mount_pitch, e.dvl_mount_yaw],
            // The simulator's velocity scale: the scale factor with the sound-speed error in it.
            scale_factor: auvnav_sim::sensors::DvlInstallation::from_effects(e).scale,
            lever_arm_m: e.dvl_lever_arm,
            time_offset_s: e.dvl_time_offset,
            // Per-beam effects only from the beams channel (the velocity channel does not see
            // them apart).
            beam_scale_factor_ppm: if analysed.contains(&ChannelKind::DvlBeams) {
                e.dvl_beam_scale_factor
            } else {
                [0.0; 4]
            },
            beam_angle_error_deg: if analysed.contains(&ChannelKind::DvlBeams) {
                e.dvl_beam_angle_error
            } else {
                [0.0; 4]
            },
            source: source.into(),
        });
    let mag = if analysed.contains(&ChannelKind::Magnetometer) {
        Some(MagnetometerConfig {
            source: source.into(),
            ..MagnetometerModel::navigator_config(e)
        })
    } else if analysed.contains(&ChannelKind::MagneticField) {
        // Without a reference attitude the declination is not observed: leave it to the field
        // model (the configuration then needs `model_date` or `declination_deg`).
        Some(MagnetometerConfig {
            source: source.into(),
            declination_deg: None,
            ..MagnetometerModel::navigator_config(e)
        })
    } else {
        None
    };
    (dvl, mag)
}

/// The model the navigator configuration is written from: the effects found (on all readings)
/// less those withheld because the held-out navigation got worse with them — on surface runs,
/// the refit without them ([`crate::gnss_written::refit`]).
pub fn written_model(r: &DiscoverReport) -> Effects {
    if let Some(f) = &r.refit {
        // What the first pass withheld stays at nominal even where the refit's GNSS decision
        // names it again.
        let names: Vec<&str> = f
            .withheld
            .iter()
            .chain(&r.withheld)
            .map(|w| w.name.as_str())
            .collect();
        return at_nominal(&f.model, &r.nominal_model, &names);
    }
    let names: Vec<&str> = r.withheld.iter().map(|w| w.name.as_str()).collect();
    at_nominal(&r.model, &r.nominal_model, &names)
}

/// `model` with the effects `names` set back to their nominal values.
pub fn at_nominal(model: &Effects, nominal: &Effects, names: &[&str]) -> Effects {
    let mut m = model.clone();
    for name in names {
        if let Some(v) = nominal.get(name) {
            let _ = m.set(name, &v);
        }
    }
    m
}

/// The channels analysed (in any voyage).
pub(crate) fn analysed(r: &DiscoverReport) -> Vec<ChannelKind> {
    let mut kinds: Vec<ChannelKind> = r.channels.iter().map(|c| c.channel).collect();
    if let Some(v) = &r.voyages {
        kinds.extend(
            v.voyages
                .iter()
                .flat_map(|x| x.channels.iter().map(|c| c.channel)),
        );
    }
    kinds.sort();
    kinds.dedup();
    kinds
}

/// The depth sensor's lever arm for the navigator (`depth_lever_arm_m`) when the depth channel
/// was analysed.
pub fn navigator_depth_lever_arm(e: &Effects, analysed: &[ChannelKind]) -> Option<[f64; 3]> {
    analysed
        .contains(&ChannelKind::Depth)
        .then_some(e.depth_lever_arm)
}

/// The navigator configuration file's text (`[navigation.dvl]`, `[navigation.magnetometer]`,
/// the depth sensor's `depth_lever_arm_m`), from the effects found on all readings; the depth
/// bias and density, which the navigator does not model, are listed as comments.
pub fn navigator_toml(r: &DiscoverReport) -> anyhow::Result<String> {
    #[derive(Serialize)]
    struct Navigation {
        #[serde(skip_serializing_if = "Option::is_none")]
        depth_lever_arm_m: Option<[f64; 3]>,
        /// The compass's deviation card, where one was found (surface runs steer by it).
        #[serde(skip_serializing_if = "Option::is_none")]
        compass_deviation_deg: Option<[f64; 5]>,
        #[serde(skip_serializing_if = "Option::is_none")]
        dvl: Option<DvlInstallation>,
        #[serde(skip_serializing_if = "Option::is_none")]
        magnetometer: Option<MagnetometerConfig>,
    }
    #[derive(Serialize)]
    struct File {
        navigation: Navigation,
    }
    let source = format!("auvnav discover on {}", r.inputs.join(", "));
    // The installation found is written only where it does not make the navigation worse
    // (`NavigationGain::judge`: a larger position or velocity error against the reference on
    // any log): where every effect found does, the largest set with which no log does
    // (`navigation::withhold`).
    let model = &written_model(r);
    let (dvl, magnetometer) = navigator_tables(model, &analysed(r), &source);
    let depth_lever_arm_m = navigator_depth_lever_arm(model, &analysed(r));
    let body = toml::to_string(&File {
        navigation: Navigation {
            depth_lever_arm_m,
            compass_deviation_deg: (model.heading_deviation != r.nominal_model.heading_deviation)
                .then_some(model.heading_deviation),
            dvl,
            magnetometer,
        },
    })?;
    let mut head = String::from(
        "# Navigator configuration from `auvnav discover`: the installation the data show.\n\
         # Merge these tables into the daemon's configuration or pass the file to\n\
         # `auvnav replay --config` (with an [initial] table for logs without a reference).\n",
    );
    if analysed(r).contains(&ChannelKind::MagneticField) {
        head.push_str(
            "# The magnetometer was analysed without a reference attitude: the declination is not\n\
             # determined; add `model_date` (or `declination_deg`) to [navigation.magnetometer].\n",
        );
    }
    let worse: Vec<&NavigationGain> = r.navigation.iter().filter(|g| g.worse).collect();
    for g in &worse {
        head.push_str(&format!(
            "# With every effect found the navigation of {} got {}.\n",
            g.log, g.verdict
        ));
    }
    for w in &r.withheld {
        head.push_str(&format!(
            "# NOT APPLIED: {} ({}); the tables below keep its nominal value.\n",
            w.name, w.note
        ));
    }
    if let Some(f) = &r.refit {
        head.push_str(&format!(
            "# Fitted again without {}: {}.\n",
            f.without.join(", "),
            f.changes.join("; ")
        ));
        for w in &f.withheld {
            head.push_str(&format!(
                "# NOT APPLIED (after the refit): {} ({}).\n",
                w.name, w.note
            ));
        }
    }
    for u in &r.unseparable {
        head.push_str(&format!(
            "# Not determined by these data: {} ({}); check before use.\n",
            u.effects.join(" with "),
            u.note
        ));
    }
    if analysed(r).contains(&ChannelKind::AcousticRanges) {
        for e in r.effects.iter().filter(|e| e.name.starts_with("usbl.")) {
            head.push_str(&format!("# {} = {} {} found", e.name, e.value, e.unit));
            head.push_str(if e.name == "usbl.hydrophone_offset" {
                ": relative to the receiver positions the logs give (their origin when they give\n\
                 # none); [navigation.usbl] hydrophone_offset_m is relative to the array the\n\
                 # daemon configures (baseline_m): convert before use.\n"
            } else {
                ": the navigator estimates the range error on line; not applied.\n"
            });
        }
    }
    for e in r.effects.iter().filter(|e| e.name.starts_with("imu.")) {
        head.push_str(&format!(
            "# {} = {} {} found: the navigator estimates the IMU biases on line \
             (initial_*_bias_std_*) and corrects no scale factor or misalignment; not applied.\n",
            e.name, e.value, e.unit
        ));
    }
    if r.effects.iter().any(|e| e.name.starts_with("dvl.beam_")) {
        head.push_str(
            "# Per-beam corrections found (beam_scale_factor_ppm, beam_angle_error_deg): the\n\
             # navigator applies them to readings that carry all four beam velocities; a DVL\n\
             # that sends only its velocity needs the beam fixed or the device reconfigured.\n",
        );
    }
    for name in ["depth.bias", "depth.density"] {
        if let Some(e) = r.effects.iter().find(|e| e.name == name) {
            head.push_str(&format!(
                "# {name} = {} {} found: the navigator has no depth correction; not applied.\n",
                e.value, e.unit
            ));
        }
    }
    Ok(head + &body)
}

/// The sensors a log's reference solution was computed with (the header's
/// [`auvnav_log::REFERENCE_AIDED_BY`]) among the channels analysed, and the note's description.
fn reference_aided_by(
    log: &std::path::Path,
    kinds: &[ChannelKind],
) -> Option<(Vec<String>, String)> {
    let mut reader = auvnav_log::LogReader::open(log).ok()?;
    let note = reader
        .read_header()
        .ok()?
        .notes
        .get(auvnav_log::REFERENCE_AIDED_BY)?
        .clone();
    let (names, description) = note.split_once(':').unwrap_or((note.as_str(), ""));
    let seen = |name: &str| match name {
        "dvl" => kinds
            .iter()
            .any(|k| matches!(k, ChannelKind::Dvl | ChannelKind::DvlBeams)),
        "imu" => kinds
            .iter()
            .any(|k| matches!(k, ChannelKind::Gyro | ChannelKind::Accelerometer)),
        "depth" => kinds.contains(&ChannelKind::Depth),
        "magnetometer" => kinds
            .iter()
            .any(|k| matches!(k, ChannelKind::Magnetometer | ChannelKind::MagneticField)),
        _ => false,
    };
    let shared: Vec<String> = names
        .split(',')
        .map(str::trim)
        .filter(|n| seen(n))
        .map(String::from)
        .collect();
    (!shared.is_empty()).then(|| (shared, description.trim().to_string()))
}

/// A note for every log whose reference was computed with sensors the report analysed against
/// it: what such a reference can show of their effects, and what it cannot.
pub fn reference_caveats(logs: &[std::path::PathBuf], r: &mut DiscoverReport) {
    let kinds = analysed(r);
    for log in logs {
        if let Some((sensors, description)) = reference_aided_by(log, &kinds) {
            r.notes.push(format!(
                "{}: its reference was computed with this log's {} ({description}): the effects \
                 found on {} describe them against a solution that has already absorbed part of \
                 their errors, so the navigation error against it does not judge them \
                 independently. What it can show: the held-out velocity error and whether logs \
                 analysed one at a time agree on an effect; what it cannot: the position gain of \
                 an installation of the sensors it was computed with (a GNSS or acoustic \
                 reference would)",
                log.display(),
                sensors.join(" and "),
                sensors.join(" and ")
            ));
        }
    }
}

/// For every log whose heading is a magnetic compass's: its declination not applied
/// ([`DiscoverReport::compass`]) and a note beside the heading offset discovery estimated
/// (named or pointed at), or why the declination cannot be given.
pub fn compass_declinations(logs: &[std::path::PathBuf], r: &mut DiscoverReport) {
    let (found, notes) = auvnav_calibrate::surface::compass::declinations(
        logs.iter().map(|p| p.as_path()),
        yaw_estimate(r),
    );
    r.compass.extend(found);
    r.notes.extend(notes);
}

/// The heading offset discovery estimated: named, pointed at, or else the GNSS positions'
/// estimate of a surface run (value, deviation; deg).
fn yaw_estimate(r: &DiscoverReport) -> Option<(f64, f64, &'static str)> {
    let named = r.effects.iter().find(|e| e.name == "dvl.mount_yaw");
    if let Some(e) = named {
        return Some((e.value.as_f64()?, e.std.as_f64()?, "named"));
    }
    if let Some(u) = r.undetermined.iter().find(|u| u.name == "dvl.mount_yaw") {
        return Some((u.value.as_f64()?, u.std.as_f64()?, "pointed at"));
    }
    let p = r
        .gnss
        .as_ref()?
        .params
        .iter()
        .find(|p| p.name == "dvl.mount_yaw" && p.std.is_finite())?;
    Some((p.estimate, p.std, "estimated on the GNSS positions"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_navigator_installation_carries_the_simulators_velocity_scale_and_geometry() {
        let mut e = Effects::default();
        for (n, v) in [
            ("dvl.scale_factor", vec![1.01]),
            ("dvl.sound_speed", vec![1470.0]),
            ("dvl.mount_yaw", vec![1.5]),
            ("dvl.lever_arm", vec![-1.0, 0.1, 0.2]),
            ("dvl.time_offset", vec![0.3]),
        ] {
            e.set(n, &v).expect("valid");
        }
        let (dvl, mag) = navigator_tables(&e, &[ChannelKind::Dvl], "test");
        let d = dvl.expect("DVL analysed");
        assert!((d.scale_factor - 1.01 * 1500.0 / 1470.0).abs() < 1e-12);
        assert_eq!(d.mount_deg, [0.0, 0.0, 1.5]);
        assert_eq!(d.lever_arm_m, [-1.0, 0.1, 0.2]);
        assert_eq!(d.time_offset_s, 0.3);
        assert!(mag.is_none());
    }
}
