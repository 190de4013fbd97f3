//! Hidden-effect trials on surface runs: a boat with a compass, a DVL and GNSS, and no IMU — what
//! `auvnav import pd0` and `auvnav import riversurveyor` make of a boat ADCP's run. Each trial
//! simulates a seeded route at the surface (straight legs, turns of either sign, speed changes),
//! hides an effect of [`SURFACE_HIDDEN`] (or nothing), and then keeps only what such a run records:
//! the DVL, the compass on the attitude channel, the GNSS fixes, and as the reference what the
//! importers write (position and velocity over ground from the fixes, the compass's attitude;
//! [`auvnav_import::gps_reference::reference_from_fixes`]). `auvnav discover --moving-bed` decides
//! on it as on a measured run, the GNSS positions deciding the installation.

use super::command::{DiscoverOptions, run};
use super::hidden_effects::{Hidden, SetTrial, coloured as coloured_noise, score};
use anyhow::Context;
use auvnav_log::{LogHeader, LogMessage, write_log_atomically};
use auvnav_shm_schema::{AttitudeV1, GnssFixV1, topic};
use auvnav_sim::effects::Effects;
use auvnav_sim::rng::Rng;
use auvnav_sim::scenario::Scenario;
use auvnav_sim::{SimConfig, simulate_to_vec};
use std::path::Path;

/// Effects the surface trials hide, with the magnitude range drawn from (per component, either
/// sign, as an offset from nominal). The compass deviation's constant `A` is a mounting yaw by
/// another name and stays 0; its one- and two-cycle coefficients are drawn.
pub const SURFACE_HIDDEN: &[(&str, f64, f64)] = &[
    ("dvl.mount_yaw", 1.0, 4.0),
    ("dvl.scale_factor", 0.005, 0.02),
    ("dvl.time_offset", 0.3, 1.0),
    ("heading.deviation", 1.0, 4.0),
    ("dvl.bed_velocity", 0.03, 0.15),
];

/// The sensors' noise on every surface trial: the DVL's white noise (m/s) and the GNSS
/// position's (m per horizontal axis), a consumer receiver's.
const DVL_NOISE_M_S: f64 = 0.01;
const GNSS_NOISE_M: f64 = 0.02;

/// A route at the surface for trial `seed`: 8 to 12 straight legs of 20–50 s, each followed by a
/// turn of 30–150° either way at 2–6°/s, with a speed change (0.8–2.5 m/s) before every second
/// leg (only a change of speed moves the DVL's reading with a time offset). Whether its headings fill the compass card's sectors is left to the draw: a route that
/// does not swing leaves the deviation card not excited, and the report must say so.
pub fn surface_scenario(seed: u64) -> String {
    let mut rng = Rng::new(seed, "discover.surface.trajectory");
    let mut u = |lo: f64, hi: f64| lo + rng.uniform() * (hi - lo);
    let legs = u(8.0, 13.0).floor() as usize;
    let mut text = String::new();
    for k in 0..legs {
        if k % 2 == 1 {
            text.push_str(&format!(
                "[[legs]]\nkind = \"speed\"\ntarget_m_s = {}\naccel_m_s2 = {}\n\n",
                u(0.8, 2.5),
                u(0.05, 0.15)
            ));
        }
        text.push_str(&format!(
            "[[legs]]\nkind = \"straight\"\nduration_s = {}\n\n",
            u(20.0, 50.0)
        ));
        let sign = if u(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 };
        text.push_str(&format!(
            "[[legs]]\nkind = \"turn\"\nangle_deg = {}\nrate_deg_s = {}\nbank_deg = 0.0\n\n",
            sign * u(30.0, 150.0),
            u(2.0, 6.0)
        ));
    }
    format!(
        "name = \"surface_trial\"\n\
         description = \"a boat at the surface: straight legs, turns, speed changes\"\n\
         seabed_depth_m = 20.0\n\n\
         [start]\nlatitude_deg = {}\nlongitude_deg = {}\ndepth_m = 0.0\nheading_deg = {}\nspeed_m_s = {}\n\n\
         [rates]\nimu_hz = 10\ndvl_hz = 1\nusbl_hz = 0\ndepth_hz = 0\nmagnetometer_hz = 0\n\
         gnss_hz = 1\ntruth_hz = 1\ncompass_hz = 1\n\n\
         {text}",
        u(-60.0, 60.0),
        u(-180.0, 180.0),
        u(0.0, 360.0),
        u(1.0, 2.0),
    )
}

/// Draws an effect of [`SURFACE_HIDDEN`] and its magnitude for trial `seed`.
pub fn surface_draw(seed: u64) -> Hidden {
    let mut rng = Rng::new(seed, "discover.surface.hidden");
    let k = (rng.next_u64() % SURFACE_HIDDEN.len() as u64) as usize;
    let (name, lo, hi) = SURFACE_HIDDEN[k];
    let nominal = Effects::default().get(name).unwrap_or_default();
    let value = nominal
        .iter()
        .enumerate()
        .map(|(i, x)| {
            if name == "heading.deviation" && i == 0 {
                return *x;
            }
            let m = lo + rng.uniform() * (hi - lo);
            if rng.uniform() < 0.5 { x - m } else { x + m }
        })
        .collect();
    Hidden::new(name, value)
}

/// Runs one surface trial in `dir`: the route of `seed` with `hidden` (none: a null trial) and,
/// when `coloured`, a Gauss–Markov DVL velocity error (instability 5–15 mm/s, correlation time
/// 30–120 s, drawn per seed) on top of the white noise; recorded as a boat without an IMU would
/// record it, discovered with `--moving-bed`, and scored as every trial is.
pub fn surface_trial(
    seed: u64,
    hidden: &[Hidden],
    coloured: bool,
    dir: &Path,
) -> anyhow::Result<(SetTrial, Vec<WrittenFold>)> {
    let scenario = Scenario::parse(&surface_scenario(seed), "surface trial")?;
    let mut effects = scenario.effects()?;
    let mut settings: Vec<(String, Vec<f64>)> = vec![
        ("dvl.noise".into(), vec![DVL_NOISE_M_S]),
        ("gnss.noise".into(), vec![GNSS_NOISE_M]),
    ];
    if coloured {
        // The underwater trials' coloured noise, its DVL part (a boat without an IMU).
        settings.extend(
            coloured_noise(seed)
                .into_iter()
                .filter(|(name, _)| name.starts_with("dvl.")),
        );
    }
    settings.extend(hidden.iter().map(|h| (h.name.clone(), h.value.clone())));
    auvnav_sim::effects::set::apply(&mut effects, &settings)?;
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: None,
    };
    let (messages, _) = simulate_to_vec(&cfg).context("simulating the surface trial")?;
    let log = dir.join(format!("surface-{seed}.mcap"));
    write_surface_run(&messages, &log)?;
    let options = DiscoverOptions {
        json: true,
        no_navigation: true,
        moving_bed: true,
        ..DiscoverOptions::new(vec![log.clone()])
    };
    let report = run(&options);
    let _ = std::fs::remove_file(&log);
    let report = report.context("discovering on the surface trial")?;
    let found: Vec<String> = report.effects.iter().map(|e| e.name.clone()).collect();
    let folds = written_folds(&report);
    Ok((score(seed, hidden, found, &[], &report), folds))
}

/// One fold of a surface run navigated against its GNSS (window RMS, m) with the nominal
/// installation, S-CAL's two-point installation from the other fold, and what `auvnav discover
/// --write-config` writes from the other fold.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct WrittenFold {
    pub nominal_m: f64,
    pub two_point_m: f64,
    pub written_m: f64,
    /// Whether the other fold's discovery writes anything.
    pub writes: bool,
}

/// The folds of a report's GNSS evidence that were scored with what the others write.
pub fn written_folds(r: &super::findings::DiscoverReport) -> Vec<WrittenFold> {
    let Some(g) = r.gnss.as_ref() else {
        return Vec::new();
    };
    g.written_held_out
        .iter()
        .filter_map(|w| {
            let h = g.held_out.iter().find(|h| h.run == w.fold)?;
            Some(WrittenFold {
                nominal_m: h.scores.nominal.rms_error_m,
                two_point_m: h.scores.two_point.rms_error_m,
                written_m: w.score.as_ref()?.rms_error_m,
                writes: !w.written.is_empty(),
            })
        })
        .collect()
}

/// Writes what a boat without an IMU records of the simulated `messages` into `log`: the DVL,
/// the compass (attitude), the GNSS fixes, and the importers' reference from the fixes and the
/// compass at each DVL ping in place of the simulated truth.
pub fn write_surface_run(messages: &[LogMessage], log: &Path) -> anyhow::Result<()> {
    let (mut fixes, mut compass, mut pings) = (Vec::new(), Vec::new(), Vec::new());
    for m in messages {
        match m {
            LogMessage::Gnss(f) => fixes.push(*f),
            LogMessage::Attitude(a) => compass.push(*a),
            LogMessage::Dvl(d) => pings.push(d.host_time_ns),
            _ => {}
        }
    }
    let reference = auvnav_import::gps_reference::reference_from_fixes(&fixes, &compass, &pings);
    let mut kept: Vec<(u64, u8, LogMessage)> = messages
        .iter()
        .filter_map(|m| match m {
            LogMessage::Dvl(d) => Some((d.host_time_ns, 0, *m)),
            LogMessage::Attitude(a) => Some((a.host_time_ns, 1, *m)),
            LogMessage::Gnss(f) => Some((f.host_time_ns, 2, *m)),
            _ => None,
        })
        .collect();
    kept.extend(
        reference
            .into_iter()
            .map(|t| (t.host_time_ns, 3, LogMessage::Truth(t))),
    );
    kept.sort_by_key(|&(t, order, _)| (t, order));
    let mut header = LogHeader::new("discovery surface trial", "");
    header.notes.insert(
        "reference".into(),
        "the GNSS fixes (position, velocity over ground) and the compass (attitude) at each DVL \
         ping, as the surface runs' importers write it"
            .into(),
    );
    write_log_atomically(log, &header, |w| {
        for (_, _, m) in &kept {
            match m {
                LogMessage::Dvl(x) => w.write(topic::DVL, x)?,
                LogMessage::Attitude(x) => w.write::<AttitudeV1>(topic::ATTITUDE, x)?,
                LogMessage::Gnss(x) => w.write::<GnssFixV1>(topic::GNSS, x)?,
                LogMessage::Truth(x) => w.write(topic::TRUTH, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", log.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("auvnav-surface-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("dir");
        d
    }

    /// Boats with nothing hidden, their reference differenced from GNSS positions (2 cm): no time
    /// offset is named. Before the fit gave back what interpolating the noisy reference takes
    /// (`reference_noise`), nine of ten such runs named one of 0.3–0.5 s.
    #[test]
    fn a_noisy_gnss_reference_does_not_make_a_time_offset() {
        let d = dir("null");
        for seed in 9301..9306 {
            let (t, _) = surface_trial(seed, &[], false, &d).expect("trial");
            assert!(
                !t.found.iter().any(|n| n == "dvl.time_offset"),
                "seed {seed}: {:?}",
                t.found
            );
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A mounting yaw, a moving bed and a time offset hidden in surface runs are each named
    /// within 10 %, and nothing else.
    #[test]
    fn an_installation_hidden_in_a_surface_run_is_named() {
        let d = dir("hidden");
        for (seed, h) in [
            (9311, Hidden::new("dvl.mount_yaw", vec![2.5])),
            (9312, Hidden::new("dvl.bed_velocity", vec![0.1, -0.06])),
            (9313, Hidden::new("dvl.time_offset", vec![0.6])),
        ] {
            let (t, _) = surface_trial(seed, std::slice::from_ref(&h), false, &d).expect("trial");
            assert!(t.correct, "seed {seed}, {} hidden: {t:?}", h.name);
        }
        let _ = std::fs::remove_dir_all(&d);
    }
}
