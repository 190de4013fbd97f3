//! `auvnav calibrate dvl` and `auvnav perturb` on simulated voyages with known installation
//! errors: the two-point formulas' conventions, the fast method's recovery and hold-out gain,
//! determinism of the seed method, observability on a straight run, the configuration it writes,
//! and clear errors on bad input.

use auvnav_sim::scenario::Scenario;
use auvnav_sim::{SimConfig, effects::Effects, simulate_to_log};
use auvnav_tests::processes::{TempDir, binary};
use auvnav_tools::calibrate::voyage::{FixSource, Voyage, VoyageSpec};
use auvnav_tools::calibrate::{
    CalibrateDvlOptions, Holdout, Method, Problem, calibrate_dvl, objective::Record, two_point,
};
use std::path::{Path, PathBuf};
use std::process::Command;

/// A voyage: `legs` (TOML) from a start at `depth_m`, heading `heading`, with the campaign's
/// navigation-grade sensors plus `extra` effects.
fn voyage(
    dir: &Path,
    name: &str,
    heading: f64,
    depth_m: f64,
    legs: &str,
    extra: &[(&str, &[f64])],
    seed: u64,
) -> PathBuf {
    let text = format!(
        "name = \"{name}\"\nseabed_depth_m = 100.0\n[start]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\n\
         depth_m = {depth_m}\nheading_deg = {heading}\nspeed_m_s = 2.5\n\
         [rates]\nimu_hz = 100\ndvl_hz = 1\nusbl_hz = 0\ndepth_hz = 1\nmagnetometer_hz = 0\ngnss_hz = 1\ntruth_hz = 1\n\
         {legs}\n[effects]\n\"imu.gyro_bias\" = [0.01, -0.01, 0.01]\n\"imu.accel_bias\" = [10.0, -10.0, 10.0]\n\
         \"dvl.noise\" = 0.01\n\"depth.noise\" = 0.05\n\"gnss.noise\" = 3.0\n"
    );
    let scenario = Scenario::parse(&text, name).expect("scenario");
    let mut effects: Effects = scenario.effects().expect("effects");
    for (n, v) in extra {
        effects.set(n, v).expect("effect");
    }
    let out = dir.join(format!("{name}.mcap"));
    simulate_to_log(
        &SimConfig {
            scenario,
            effects,
            seed,
            duration_s: None,
        },
        &out,
    )
    .expect("simulate");
    out
}

fn straight(seconds: f64) -> String {
    format!("[[legs]]\nkind = \"straight\"\nduration_s = {seconds}\n")
}

fn specs(paths: &[PathBuf]) -> Vec<VoyageSpec> {
    paths
        .iter()
        .map(|p| VoyageSpec {
            path: p.clone(),
            window_s: None,
        })
        .collect()
}

fn args(paths: &[PathBuf], threshold: f64) -> CalibrateDvlOptions {
    let mut a = CalibrateDvlOptions::new(specs(paths));
    a.fixes = FixSource::Truth;
    a.threshold = threshold;
    a
}

#[test]
fn two_point_formulas_recover_yaw_and_scale_with_the_settled_signs() {
    let dir = TempDir::new("cal2pt");
    for (k, (yaw, scale, heading)) in [(1.5, 0.996, 30.0), (-2.0, 1.004, 250.0)]
        .into_iter()
        .enumerate()
    {
        let path = voyage(
            dir.path(),
            &format!("v{k}"),
            heading,
            20.0,
            &straight(800.0),
            &[("dvl.mount_yaw", &[yaw]), ("dvl.scale_factor", &[scale])],
            11 + k as u64,
        );
        let cfg = Default::default();
        let v = Voyage::load(&specs(&[path])[0], FixSource::Truth, &cfg).expect("voyage");
        let voyages = [v];
        let problem = Problem::new(&voyages, Default::default(), 100.0, 1);
        let base = problem
            .evaluate(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], Record::default())
            .expect("replay");
        let tp = two_point::per_voyage(&voyages[0], &base.runs[0], 0.0, 1.0).expect("two-point");
        // 2 km with the filter's own heading and DVL noise: both formulas within 0.05 deg and
        // 0.02 % (a wrong sign would be off by twice the hidden error).
        assert!((tp.mount_yaw_deg_a - yaw).abs() < 0.05, "{tp:?}");
        assert!((tp.mount_yaw_deg_b - yaw).abs() < 0.05, "{tp:?}");
        assert!((tp.scale_factor_a - scale).abs() < 2e-4, "{tp:?}");
        assert!((tp.scale_factor_b - scale).abs() < 2e-4, "{tp:?}");
        // The seed's own quantities: (a)'s k corrects the DVL (1 + k = 1 / s), (b)'s k is the
        // DVL's error (1 + k = s / cos eps); eps is minus our yaw in both.
        assert!((1.0 / (1.0 + tp.seed_k_a) - scale).abs() < 2e-4);
        assert!(((1.0 + tp.seed_k_b) * tp.seed_epsilon_b.atan().cos() - scale).abs() < 2e-4);
        assert!((tp.seed_epsilon_a_rad.to_degrees() + yaw).abs() < 0.05);
    }
}

#[test]
fn fast_recovers_yaw_and_scale_and_beats_two_point_on_held_out_voyages() {
    let dir = TempDir::new("calfast");
    // Three 2 km voyages with turns, 0.7 deg yaw and a 0.3 % scale error hidden.
    let legs = format!(
        "{}[[legs]]\nkind = \"turn\"\nangle_deg = 70.0\nrate_deg_s = 3.0\n{}[[legs]]\nkind = \"turn\"\nangle_deg = -120.0\nrate_deg_s = 3.0\n{}",
        straight(250.0),
        straight(250.0),
        straight(250.0)
    );
    let fx: &[(&str, &[f64])] = &[("dvl.mount_yaw", &[0.7]), ("dvl.scale_factor", &[1.003])];
    let paths: Vec<PathBuf> = (0..3)
        .map(|k| {
            voyage(
                dir.path(),
                &format!("v{k}"),
                40.0 + 110.0 * k as f64,
                20.0,
                &legs,
                fx,
                21 + k,
            )
        })
        .collect();
    let mut a = args(&paths, 300.0);
    a.params = vec!["dvl.mount_yaw".into(), "dvl.scale_factor".into()];
    a.write_config = Some(dir.path().join("dvl.toml"));
    a.report = Some(dir.path().join("report"));
    let r = calibrate_dvl(&a).expect("calibrate");
    let yaw = r
        .parameters
        .iter()
        .find(|p| p.name == "dvl.mount_yaw")
        .expect("yaw");
    let scale = r
        .parameters
        .iter()
        .find(|p| p.name == "dvl.scale_factor")
        .expect("scale");
    assert!((yaw.value - 0.7).abs() < 0.05, "yaw {yaw:?}");
    assert!((scale.value - 1.003).abs() < 5e-4, "scale {scale:?}");
    assert!(yaw.std.is_some_and(|s| s > 0.0 && s < 0.05), "{yaw:?}");
    assert!(
        r.objective.after < 0.5 * r.objective.before,
        "{:?}",
        r.objective
    );
    let h = r.holdout.as_ref().expect("three voyages: leave-one-out");
    assert_eq!(h.voyages.len(), 3);
    assert!(h.mean_after < h.mean_before, "{h:?}");
    assert!(h.mean_after <= h.mean_two_point_after * 1.02, "{h:?}");
    // The table it wrote is what the daemon reads, and it is the reported installation.
    let text = std::fs::read_to_string(dir.path().join("dvl.toml")).expect("config");
    let mut daemon_file = String::from(
        "[initial]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\neuler_deg = [0.0, 0.0, 45.0]\n",
    );
    daemon_file.push_str(&text);
    let cfg = auvnav_core::config::DaemonConfig::from_toml(&daemon_file).expect("daemon config");
    let d = cfg.navigation.dvl_installation();
    assert_eq!(d.mount_deg[2], yaw.value);
    assert_eq!(d.scale_factor, scale.value);
    let path = dir.path().join("daemon.toml");
    std::fs::write(&path, &daemon_file).expect("write");
    let check = Command::new(binary("auvnavd"))
        .arg("--check-config")
        .arg(&path)
        .output()
        .expect("auvnavd");
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
    for f in [
        "report.md",
        "report.json",
        "calibration.toml",
        "track_01.svg",
        "error_vs_distance.svg",
    ] {
        assert!(dir.path().join("report").join(f).is_file(), "{f}");
    }
}

#[test]
fn a_straight_run_does_not_determine_pitch_roll_or_the_lever_arm() {
    let dir = TempDir::new("calobs");
    let fx: &[(&str, &[f64])] = &[("dvl.mount_yaw", &[-1.0])];
    let paths: Vec<PathBuf> = (0..2)
        .map(|k| {
            voyage(
                dir.path(),
                &format!("s{k}"),
                60.0 + 90.0 * k as f64,
                20.0,
                &straight(700.0),
                fx,
                31 + k,
            )
        })
        .collect();
    let mut a = args(&paths, 300.0);
    a.params = vec![
        "dvl.mounting".into(),
        "dvl.scale_factor".into(),
        "dvl.lever_arm".into(),
    ];
    let r = calibrate_dvl(&a).expect("calibrate");
    let status = |n: &str| {
        r.parameters
            .iter()
            .find(|p| p.name == n)
            .map(|p| p.status.clone())
            .expect(n)
    };
    for n in [
        "dvl.mount_roll",
        "dvl.mount_pitch",
        "dvl.lever_arm.x",
        "dvl.lever_arm.y",
        "dvl.lever_arm.z",
    ] {
        assert_eq!(status(n), "held_at_prior", "{n}: {}", r.verdict);
    }
    assert_eq!(status("dvl.mount_yaw"), "estimated", "{}", r.verdict);
    assert!(r.verdict.contains("cannot determine"), "{}", r.verdict);
    let yaw = r
        .parameters
        .iter()
        .find(|p| p.name == "dvl.mount_yaw")
        .expect("yaw");
    assert!((yaw.value + 1.0).abs() < 0.05, "{yaw:?}");
}

#[test]
fn the_seed_method_is_deterministic_per_seed() {
    let dir = TempDir::new("calseed");
    let path = voyage(
        dir.path(),
        "d",
        10.0,
        20.0,
        &straight(300.0),
        &[("dvl.mount_yaw", &[0.5])],
        41,
    );
    let run = |seed: u64| {
        let mut a = args(std::slice::from_ref(&path), 100.0);
        a.method = Method::Seed;
        a.params = vec!["dvl.mount_yaw".into(), "dvl.scale_factor".into()];
        a.bounds = vec!["dvl.mount_yaw=-3,3".into()];
        a.lhs_samples = 8;
        a.particles = 3;
        a.iterations = 3;
        a.seed = seed;
        a.holdout = Holdout::None;
        calibrate_dvl(&a).expect("seed method")
    };
    let (a, b, c) = (run(5), run(5), run(6));
    assert_eq!(a.history, b.history);
    assert_eq!(
        a.parameters.iter().map(|p| p.value).collect::<Vec<_>>(),
        b.parameters.iter().map(|p| p.value).collect::<Vec<_>>()
    );
    assert_ne!(a.history, c.history);
    // 8 samples + the surface optimum + 3 particles x 3 iterations (the first reuses it).
    assert_eq!(a.evaluations.full_replays_fit, 8 + 1 + 2 + 3 * 2 + 1);
}

#[test]
fn bad_input_gives_clear_errors_naming_the_voyage_or_option() {
    let dir = TempDir::new("calbad");
    let path = voyage(dir.path(), "short", 0.0, 20.0, &straight(60.0), &[], 51);
    let err = |a: CalibrateDvlOptions| format!("{:#}", calibrate_dvl(&a).expect_err("must fail"));
    // No GNSS fixes (the voyage stays submerged).
    let mut a = args(std::slice::from_ref(&path), 100.0);
    a.fixes = FixSource::Gnss;
    let e = err(a);
    assert!(e.contains("short.mcap") && e.contains("GNSS"), "{e}");
    // Fixes never pass the distance threshold (150 m travelled).
    let e = err(args(std::slice::from_ref(&path), 5000.0));
    assert!(e.contains("short.mcap") && e.contains("threshold"), "{e}");
    // Bounds inverted.
    let mut a = args(std::slice::from_ref(&path), 100.0);
    a.bounds = vec!["dvl.scale_factor=1.01,0.99".into()];
    let e = err(a);
    assert!(
        e.contains("dvl.scale_factor") && e.contains("--bound"),
        "{e}"
    );
    // A log without DVL.
    let no_dvl = dir.path().join("nodvl.mcap");
    let mut cfg = SimConfig {
        scenario: Scenario::load("straight").expect("scenario"),
        effects: Effects::default(),
        seed: 1,
        duration_s: Some(20.0),
    };
    cfg.scenario.rates.dvl_hz = 0;
    simulate_to_log(&cfg, &no_dvl).expect("simulate");
    let e = err(args(std::slice::from_ref(&no_dvl), 10.0));
    assert!(e.contains("nodvl.mcap") && e.contains("no DVL"), "{e}");
    // A missing file and a bad window on the command line.
    let out = Command::new(binary("auvnav"))
        .args(["calibrate", "dvl", "/nonexistent/v.mcap"])
        .output()
        .expect("auvnav");
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("v.mcap") && !e.contains("panicked"),
        "{e}"
    );
    let out = Command::new(binary("auvnav"))
        .args(["calibrate", "dvl", "v.mcap@5..2"])
        .output()
        .expect("auvnav");
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("5..2") && !e.contains("panicked"),
        "{e}"
    );
}

#[test]
fn perturb_hides_the_installation_the_simulator_would_have_produced() {
    let dir = TempDir::new("calperturb");
    let legs = format!(
        "{}[[legs]]\nkind = \"turn\"\nangle_deg = 90.0\nrate_deg_s = 3.0\n[[legs]]\nkind = \"speed\"\ntarget_m_s = 1.5\naccel_m_s2 = 0.05\n{}",
        straight(60.0),
        straight(60.0)
    );
    let fx: &[(&str, &[f64])] = &[
        ("dvl.mount_yaw", &[1.5]),
        ("dvl.scale_factor", &[0.996]),
        ("dvl.lever_arm", &[-1.5, 0.1, 0.3]),
    ];
    let clean = voyage(dir.path(), "clean", 0.0, 20.0, &legs, &[], 61);
    let hidden = voyage(dir.path(), "hidden", 0.0, 20.0, &legs, fx, 61);
    let perturbed = dir.path().join("perturbed.mcap");
    let out = Command::new(binary("auvnav"))
        .arg("perturb")
        .arg(&clean)
        .args([
            "--effect",
            "dvl.mount_yaw=1.5",
            "--effect",
            "dvl.scale_factor=0.996",
            "--effect",
            "dvl.lever_arm=-1.5,0.1,0.3",
            "--out",
        ])
        .arg(&perturbed)
        .output()
        .expect("perturb");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dvl = |p: &Path| -> Vec<[f64; 3]> {
        let mut r = auvnav_log::LogReader::open(p).expect("open");
        r.read_header().expect("header");
        let mut v = Vec::new();
        while let Some(m) = r.next_message().expect("read") {
            if let Ok(auvnav_log::LogMessage::Dvl(d)) = m.decode_any() {
                v.push(d.velocity_dvl_m_s);
            }
        }
        v
    };
    let (a, b) = (dvl(&hidden), dvl(&perturbed));
    assert_eq!(a.len(), b.len());
    // Same noise stream in both: the perturbed clean log equals the simulator's own to the
    // noise's share of the lever-arm term (the rate is the IMU's, not the truth's).
    let worst = a
        .iter()
        .zip(&b)
        .flat_map(|(x, y)| (0..3).map(move |i| (x[i] - y[i]).abs()))
        .fold(0.0, f64::max);
    assert!(worst < 2e-3, "largest difference {worst} m/s");
    let mut r = auvnav_log::LogReader::open(&perturbed).expect("open");
    let h = r.read_header().expect("header");
    assert_eq!(
        h.notes.get("perturb.effects").map(String::as_str),
        Some("dvl.mount_yaw=1.5;dvl.scale_factor=0.996;dvl.lever_arm=-1.5,0.1,0.3")
    );
}

/// A short dive that starts and ends at the surface (GNSS there only), with two turns and a dive
/// and ascent in between: the motion that shows the mounting pitch besides the yaw and scale.
fn surface_to_surface_legs(turn_deg: f64) -> String {
    let depth = |change: f64| {
        format!("[[legs]]\nkind = \"depth\"\nchange_m = {change}\npitch_deg = 10.0\n")
    };
    let turn = |angle: f64| {
        format!(
            "[[legs]]\nkind = \"turn\"\nangle_deg = {angle}\nrate_deg_s = 3.0\nbank_deg = {}\n",
            8.0 * angle.signum()
        )
    };
    [
        straight(60.0),
        depth(20.0),
        straight(200.0),
        turn(turn_deg),
        straight(200.0),
        turn(-turn_deg),
        straight(150.0),
        depth(-20.0),
        straight(60.0),
    ]
    .concat()
}

#[test]
fn the_smoother_method_recovers_the_installation_from_surface_fixes_and_holds_what_it_cannot_see() {
    let dir = TempDir::new("calsmooth");
    let (yaw, pitch, scale) = (-1.7, 0.4, 0.998);
    let fx: &[(&str, &[f64])] = &[
        ("dvl.mount_yaw", &[yaw]),
        ("dvl.mount_pitch", &[pitch]),
        ("dvl.scale_factor", &[scale]),
    ];
    let paths: Vec<PathBuf> = (0..2)
        .map(|k| {
            voyage(
                dir.path(),
                &format!("v{k}"),
                20.0 + 150.0 * k as f64,
                0.0,
                &surface_to_surface_legs(if k == 0 { 70.0 } else { -100.0 }),
                fx,
                4101 + k,
            )
        })
        .collect();
    let mut a = CalibrateDvlOptions::new(specs(&paths));
    a.method = Method::Smoother;
    a.fixes = FixSource::Gnss;
    a.threshold = 1000.0;
    a.holdout = Holdout::None;
    let r = calibrate_dvl(&a).expect("calibrate by smoothing");
    let p = |n: &str| r.parameters.iter().find(|p| p.name == n).cloned().expect(n);
    for (n, truth, max_err) in [
        ("dvl.mount_yaw", yaw, 0.2),
        ("dvl.mount_pitch", pitch, 0.1),
        ("dvl.scale_factor", scale, 5e-4),
    ] {
        let q = p(n);
        let std = q.std.expect("a std");
        eprintln!("{n}: {} ± {std} (hidden {truth})", q.value);
        assert_eq!(q.status, "estimated", "{n}: {q:?}\n{}", r.verdict);
        // Within its own uncertainty (4 sigma) and within what an installation needs.
        assert!(
            (q.value - truth).abs() < (4.0 * std).max(1e-9) && (q.value - truth).abs() < max_err,
            "{n}: {} ± {std} against {truth}",
            q.value
        );
    }
    // Roll is hardly seen by a DVL on a vehicle that does not roll: held, not fitted to noise.
    assert_eq!(p("dvl.mount_roll").status, "held_at_prior", "{}", r.verdict);
    assert!(
        r.objective.after < 0.5 * r.objective.before,
        "{:?}",
        r.objective
    );
}
