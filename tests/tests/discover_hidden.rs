//! Model discovery finds an effect hidden in simulated data: seeded draws of an effect from the
//! vocabulary and a magnitude (other seeds than the benchmark's), each required to come back
//! under its name with the value within 10 % and nothing else; null data gives no effect. A
//! DVL roll, which this motion does not excite, is reported as such instead of being fitted.

use auvnav_sim::effects::{Effects, set};
use auvnav_tools::discover::command::{discover, read_logs};
use auvnav_tools::discover::fit::Selection;
use auvnav_tools::discover::hidden_effects::{Hidden, draw, simulate, trial, trial_set};
use auvnav_tools::discover::outputs::effect_set_toml;

struct Dir(std::path::PathBuf);
impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn dir(name: &str) -> Dir {
    let d = std::env::temp_dir().join(format!("auvnav-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    Dir(d)
}

#[test]
fn hidden_effects_are_named_and_estimated_within_ten_percent() {
    let d = dir("discover-hidden");
    for seed in [9001, 9002, 9003, 9004, 9005, 9006] {
        let h = draw(seed);
        let (t, r) = trial(seed, Some(h.clone()), &d.0).expect("trial");
        println!(
            "seed {seed}: hidden {} = {:?}; found {:?}, estimate {:?}, relative error {:?}",
            h.name, h.value, t.found, t.estimate, t.relative_error
        );
        assert!(
            t.correct,
            "seed {seed}: hidden {h:?}, report effects {:#?}",
            r.effects
        );
    }
}

#[test]
fn null_data_gives_no_effect() {
    let d = dir("discover-null");
    for seed in [9101, 9102] {
        let (t, r) = trial(seed, None, &d.0).expect("trial");
        assert!(t.found.is_empty(), "seed {seed}: {:#?}", r.effects);
        // Every channel was analysed and is white around the nominal model.
        // (DVL, depth, magnetometer, gyro and accelerometer.)
        assert_eq!(r.channels.len(), 5, "{:?}", r.notes);
        assert!(r.unexplained.len() <= 1, "{:#?}", r.unexplained);
    }
}

#[test]
fn an_effect_the_motion_does_not_excite_is_reported_not_fitted() {
    let d = dir("discover-roll");
    let h = Hidden::new("dvl.mount_roll", vec![2.0]);
    let (t, r) = trial(9201, Some(h), &d.0).expect("trial");
    assert!(
        !t.found.iter().any(|n| n == "dvl.mount_roll"),
        "{:?}",
        t.found
    );
    assert!(
        r.unobservable.iter().any(|u| u.name == "dvl.mount_roll"),
        "{:?}",
        r.unobservable
    );
}

/// A moving bed under bottom track (the DVL measures the vehicle's velocity relative to a bed
/// that moves, an error fixed on the Earth), with `--moving-bed`: named with its north and east
/// velocity within 10 % and nothing else on the trial voyages' turns, either sign; with the
/// option on, a hidden yaw is still a yaw and a voyage with nothing hidden names nothing.
#[test]
fn a_moving_bed_under_bottom_track_is_named() {
    use auvnav_tools::discover::analysis::{Collector, read_logs_with};
    let d = dir("discover-bed");
    let run = |seed: u64, settings: &[(String, Vec<f64>)]| {
        let log = simulate(seed, settings, &d.0).expect("simulation");
        let (channels, reference, _) =
            read_logs_with(&[log], Collector::new().with_moving_bed(true)).expect("read");
        discover(
            &channels,
            &reference,
            &Effects::default(),
            0.7,
            &Selection::default(),
        )
    };
    for (seed, value) in [(9211, vec![0.03, -0.02]), (9212, vec![-0.015, 0.04])] {
        let r = run(seed, &[("dvl.bed_velocity".into(), value.clone())]);
        let names: Vec<&str> = r.effects.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["dvl.bed_velocity"], "seed {seed}: {:#?}", r.effects);
        let got = auvnav_tools::discover::analysis::values_of(&r.effects[0].value).expect("value");
        let err = ((got[0] - value[0]).powi(2) + (got[1] - value[1]).powi(2)).sqrt()
            / value[0].hypot(value[1]);
        println!(
            "seed {seed}: hidden bed {value:?}, found {got:?} ({:.1} %)",
            100.0 * err
        );
        assert!(err < 0.1, "seed {seed}: {got:?} against {value:?}");
    }
    let r = run(9213, &[("dvl.mount_yaw".into(), vec![1.3])]);
    let names: Vec<&str> = r.effects.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["dvl.mount_yaw"], "{:#?}", r.effects);
    let r = run(9214, &[]);
    assert!(r.effects.is_empty(), "{:#?}", r.effects);
}

/// What discovery writes as the extended model (`effects.toml`) simulates data that discovery,
/// started from that model, finds nothing more in, with residuals of the size the first data
/// showed: the extension reproduces the residual statistics (on another trajectory and seed).
#[test]
fn the_extended_model_reproduces_the_residuals_and_leaves_nothing_to_find() {
    let d = dir("discover-extend");
    let hidden = Hidden::new("dvl.lever_arm", vec![-0.8, 0.2, 0.4]);
    let (t, first) = trial(9301, Some(hidden), &d.0).expect("trial");
    assert!(t.correct, "{:#?}", first.effects);
    let text = effect_set_toml(&first);
    let settings = set::parse(&text).expect("effect set reads back");
    let names: Vec<&str> = settings.iter().map(|(n, _)| n.as_str()).collect();
    for n in ["dvl.lever_arm", "dvl.noise", "depth.noise", "mag.noise"] {
        assert!(names.contains(&n), "{n} missing from\n{text}");
    }
    let log = simulate(9302, &settings, &d.0).expect("simulate the extension");
    let (channels, reference, _) = read_logs(std::slice::from_ref(&log)).expect("read");
    let mut nominal = Effects::default();
    set::apply(&mut nominal, &settings).expect("apply");
    let second = discover(&channels, &reference, &nominal, 0.7, &Selection::default());
    assert!(second.effects.is_empty(), "{:#?}", second.effects);
    for (a, b) in first.channels.iter().zip(&second.channels) {
        assert_eq!(a.channel, b.channel);
        let ratio = b.held_out_mse_nominal / a.held_out_mse_selected;
        println!(
            "{}: measured residual {:.4e}, simulated with the extension {:.4e} (ratio {ratio:.2})",
            a.channel.name(),
            a.held_out_mse_selected,
            b.held_out_mse_nominal
        );
        assert!(
            (0.7..1.4).contains(&ratio),
            "{}: ratio {ratio}",
            a.channel.name()
        );
    }
}

/// Two different effects hidden at once (other seeds than the benchmark's): both named, each
/// within 10 %, nothing else.
#[test]
fn two_hidden_effects_are_both_found() {
    use auvnav_tools::discover::hidden_effects::{draw_pair, trial_set};
    let d = dir("discover-pairs");
    for seed in [9401, 9402, 9403] {
        let h = draw_pair(seed);
        let (t, r) = trial_set(seed, &h, &d.0).expect("trial");
        println!(
            "seed {seed}: hidden {:?}; found {:?}, relative errors {:?}",
            h.iter().map(|h| (&h.name, &h.value)).collect::<Vec<_>>(),
            t.found,
            t.relative_errors
        );
        assert!(
            t.correct,
            "seed {seed}: {h:?}, report effects {:#?}",
            r.effects
        );
    }
}

/// The messages of a simulated log without its truth topic: a magnetometer and an IMU with no
/// reference attitude, as a bench or field recording has them.
fn without_truth(log: &std::path::Path) -> Vec<auvnav_log::LogMessage> {
    let mut reader = auvnav_log::LogReader::open(log).expect("open the trial log");
    let mut out = Vec::new();
    while let Some(raw) = reader.next_message().expect("read the trial log") {
        match raw.decode_any() {
            Ok(auvnav_log::LogMessage::Truth(_)) | Err(_) => {}
            Ok(m) => out.push(m),
        }
    }
    out
}

#[test]
fn magnetometer_effects_are_found_without_a_reference_attitude() {
    use auvnav_tools::discover::ChannelKind;
    use auvnav_tools::discover::command::{discover_messages, values_of};
    let d = dir("discover-field");
    // Null: the simulator's nominal field and no iron: nothing to find on the field channel.
    let log = simulate(9301, &[], &d.0).expect("simulate");
    let r = discover_messages(&without_truth(&log));
    let field = r
        .channels
        .iter()
        .find(|c| c.channel == ChannelKind::MagneticField)
        .expect("the magnetic-field channel is analysed without a reference");
    assert!(field.compared > 1000, "{field:?}");
    assert!(
        r.effects.is_empty(),
        "null data, no reference: {:#?}",
        r.effects
    );
    assert!(
        r.channels
            .iter()
            .all(|c| c.channel == ChannelKind::MagneticField),
        "only the field channel can be analysed without a reference: {:?}",
        r.notes
    );
    // Hidden hard iron and a different local field (intensity, dip).
    let hard = [7.0, -11.0, 4.0];
    let settings = vec![
        ("mag.hard_iron".to_string(), hard.to_vec()),
        ("mag.intensity".to_string(), vec![51.5]),
        ("mag.inclination".to_string(), vec![58.0]),
    ];
    for seed in [9302, 9303] {
        let log = simulate(seed, &settings, &d.0).expect("simulate");
        let r = discover_messages(&without_truth(&log));
        let get = |name: &str| {
            r.effects
                .iter()
                .find(|e| e.name == name && e.channel == ChannelKind::MagneticField)
                .and_then(|e| values_of(&e.value))
        };
        let found_hard = get("mag.hard_iron").expect("hard iron found");
        println!("seed {seed}: {:#?}\n{:#?}", r.effects, r.unseparable);
        // The horizontal components turn with the heading: determined whatever the motion.
        for k in 0..2 {
            assert!(
                (found_hard[k] - hard[k]).abs() <= 0.1 * hard[k].abs(),
                "seed {seed}: hard iron {found_hard:?} against {hard:?}"
            );
        }
        // The vertical one, the intensity and the dip either come back within 10 % of what was
        // hidden or are reported as not separable on this motion.
        let confounded = r
            .unseparable
            .iter()
            .any(|u| u.effects.iter().any(|e| e == "mag.inclination"));
        let z_ok = (found_hard[2] - hard[2]).abs() <= 0.1 * hard[2].abs();
        let field_ok = get("mag.intensity").is_some_and(|v| (v[0] - 51.5).abs() <= 0.35)
            && get("mag.inclination").is_some_and(|v| (v[0] - 58.0).abs() <= 1.3);
        assert!(
            (z_ok && field_ok) || confounded,
            "seed {seed}: {:#?} {:#?}",
            r.effects,
            r.unseparable
        );
    }
}

/// Acoustic updates of a four-receiver array whose receivers sit `offsets` from where the
/// device's configuration puts them, with range noise and multipath outliers, for a responder
/// moving about the array; the ranges come from the simulator's own model
/// (`auvnav_sim::sensors::hydrophone_ranges`).
fn acoustic_updates(
    seed: u64,
    offsets: &[f64; 12],
    noise_m: f64,
    outlier_fraction: f64,
) -> Vec<auvnav_log::LogMessage> {
    use auvnav_shm_schema::AcousticRangesV1;
    use nalgebra::Vector3;
    let mut e = Effects::default();
    e.set("usbl.hydrophone_offset", offsets).expect("offsets");
    let nominal = auvnav_sim::sensors::hydrophone_positions(2.0);
    let mut receivers = [0.0; 12];
    for (k, h) in nominal.iter().enumerate() {
        receivers[3 * k..3 * k + 3].copy_from_slice(h.as_slice());
    }
    let mut rng = auvnav_sim::rng::Rng::new(seed, "acoustic test");
    (0..2000u64)
        .map(|i| {
            let t = i as f64;
            // A responder wandering 10–80 m from the array at 2–20 m depth.
            let p = Vector3::new(
                45.0 * (t / 300.0).cos() + 20.0 * (t / 47.0).sin(),
                45.0 * (t / 300.0).sin() + 15.0 * (t / 61.0).cos(),
                11.0 + 9.0 * (t / 150.0).sin(),
            );
            let mut r = auvnav_sim::sensors::hydrophone_ranges(&e, &nominal, &p);
            for x in &mut r {
                *x += rng.gauss(noise_m);
                if rng.uniform() < outlier_fraction {
                    *x += 2.0 + 8.0 * rng.uniform();
                }
            }
            auvnav_log::LogMessage::AcousticRanges(AcousticRangesV1 {
                host_time_ns: i * 1_000_000_000,
                device_time_ns: i * 1_000_000_000,
                sequence: i,
                range_m: r,
                receiver_position_m: receivers,
                position_array_m: p.into(),
                position_std_m: 0.1,
                noise_db: [0.0; 4],
                rssi_db: [0.0; 4],
                validity: 0xf
                    | AcousticRangesV1::VALID_POSITION
                    | AcousticRangesV1::VALID_RECEIVER_POSITIONS,
                reserved: [0; 2],
            })
        })
        .collect()
}

#[test]
fn receiver_geometry_and_outliers_are_found_in_acoustic_ranges() {
    use auvnav_tools::discover::ChannelKind;
    use auvnav_tools::discover::command::{discover_messages, values_of};
    // Null: the configured geometry is right; noise and outliers only.
    let r = discover_messages(&acoustic_updates(9401, &[0.0; 12], 0.05, 0.02));
    assert!(
        r.channels
            .iter()
            .any(|c| c.channel == ChannelKind::AcousticRanges),
        "{:?}",
        r.notes
    );
    assert!(r.effects.is_empty(), "null geometry: {:#?}", r.effects);
    let fraction = r
        .noise
        .iter()
        .find(|n| n.name == "usbl.outlier_fraction")
        .map(|n| n.value)
        .expect("outliers counted");
    assert!((0.015..=0.025).contains(&fraction), "{fraction}");
    let noise = r
        .noise
        .iter()
        .find(|n| n.name == "usbl.range_noise")
        .map(|n| n.value)
        .expect("range noise");
    assert!((0.045..=0.056).contains(&noise), "{noise}");
    // Receivers displaced by 0.1–0.6 m (other seeds: other displacements).
    for seed in [9402u64, 9403] {
        let mut rng = auvnav_sim::rng::Rng::new(seed, "offsets");
        let offsets: [f64; 12] = std::array::from_fn(|_| {
            let m = 0.1 + 0.5 * rng.uniform();
            if rng.uniform() < 0.5 { -m } else { m }
        });
        let r = discover_messages(&acoustic_updates(seed, &offsets, 0.05, 0.02));
        let found = r
            .effects
            .iter()
            .find(|e| e.name == "usbl.hydrophone_offset")
            .and_then(|e| values_of(&e.value))
            .expect("the receiver offsets are found");
        let err: f64 = found
            .iter()
            .zip(&offsets)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let size: f64 = offsets.iter().map(|x| x * x).sum::<f64>().sqrt();
        println!("seed {seed}: {offsets:?} -> {found:?} ({:.3})", err / size);
        assert!(
            err <= 0.1 * size,
            "seed {seed}: {found:?} against {offsets:?}"
        );
        assert!(
            !r.effects.iter().any(|e| e.name == "usbl.sound_speed"),
            "{:#?}",
            r.effects
        );
        // The report folder takes a four-component channel.
        let dir = std::env::temp_dir().join(format!(
            "auvnav-acoustic-report-{}-{seed}",
            std::process::id()
        ));
        auvnav_tools::discover::report::write_report_dir(&dir, &r).expect("report");
        let md = std::fs::read_to_string(dir.join("report.md")).expect("report.md");
        assert!(md.contains("acoustic_ranges r3"), "{md}");
        assert!(dir.join("residual_acoustic_ranges_3.svg").exists());
        assert!(dir.join("spectrum_acoustic_ranges.svg").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// IMU errors against the reference motion: a gyro bias on every axis, a scale factor on the
/// yaw gyro (the axis the turns excite) and a horizontal accelerometer bias, hidden together in
/// a trial voyage with the trial's IMU noise (magnitudes drawn per seed); each must come back
/// within 10 % and nothing else.
#[test]
fn imu_errors_are_found_against_the_reference_motion() {
    let d = dir("discover-imu");
    for seed in [9501u64, 9502] {
        let mut rng = auvnav_sim::rng::Rng::new(seed, "imu magnitudes");
        let mut draw = |lo: f64, hi: f64| {
            let m = lo + (hi - lo) * rng.uniform();
            if rng.uniform() < 0.5 { -m } else { m }
        };
        let hidden = [
            Hidden::new(
                "imu.gyro_bias",
                vec![draw(0.5, 5.0), draw(0.5, 5.0), draw(0.5, 5.0)],
            ),
            Hidden::new(
                "imu.gyro_scale_factor",
                vec![0.0, 0.0, draw(1000.0, 5000.0)],
            ),
            Hidden::new(
                "imu.accel_bias",
                vec![draw(100.0, 1000.0), draw(100.0, 1000.0), 0.0],
            ),
        ];
        let (t, r) = trial_set(seed, &hidden, &d.0).expect("trial");
        println!(
            "seed {seed}: hidden {hidden:?}; found {:?}, estimates {:?}, relative errors {:?}",
            t.found, t.estimates, t.relative_errors
        );
        assert!(t.correct, "seed {seed}: {:#?}", r.effects);
        // The Allan deviation of what is left is reported for both IMU channels.
        for c in r
            .channels
            .iter()
            .filter(|c| c.unit == "deg/h" || c.unit == "ug")
        {
            assert!(c.allan.len() >= 4, "{:?}", c.channel);
        }
    }
}

/// A null run whose DVL error is coloured (first-order Gauss–Markov, 1 cm/s, 60 s, on top of
/// the white beam noise), seeds of its own: the effects' standard deviations allow for the
/// residual's correlation, so no DVL effect is named; the report says the residual is
/// correlated. (With white-residual deviations, the same run with seeds 11 and 12 named
/// `dvl.scale_factor` 1.0021 ± 0.0001, and `dvl.mount_yaw` 0.19° with `dvl.mount_pitch` −0.13°.)
#[test]
fn coloured_dvl_noise_names_no_dvl_effect() {
    use auvnav_sim::{SimConfig, scenario::Scenario};
    use auvnav_tools::discover::command::discover_messages;
    for seed in [9511u64, 9512, 9513] {
        let scenario = Scenario::load("lawnmower").expect("scenario");
        let mut effects = scenario.effects().expect("effects");
        effects
            .set("dvl.velocity_error_instability", &[0.01])
            .expect("instability");
        effects
            .set("dvl.velocity_error_correlation_time", &[60.0])
            .expect("correlation time");
        let cfg = SimConfig {
            scenario,
            effects,
            seed,
            duration_s: Some(900.0),
        };
        let r = discover_messages(&auvnav_tests::grade::simulate(&cfg));
        let dvl: Vec<&str> = r
            .effects
            .iter()
            .filter(|e| e.name.starts_with("dvl."))
            .map(|e| e.name.as_str())
            .collect();
        println!("seed {seed}: DVL effects {dvl:?}");
        assert!(dvl.is_empty(), "seed {seed}: {dvl:?}");
        assert!(
            r.notes
                .iter()
                .any(|n| n.starts_with("dvl: the residual") && n.contains("correlated")),
            "{:#?}",
            r.notes
        );
    }
}

/// Null trial voyages with the benchmark's coloured noise (`hidden::coloured`: a Gauss–Markov
/// DVL error and IMU biases drifting 0.5–5 deg/h and 20–200 µg over 120–900 s), twelve seeds
/// of their own (9531–9542): the drift's mean over a voyage is a bias and may be named as one,
/// but an IMU scale factor or misalignment is named in at most one of them. Before the drift
/// was taken out as a nuisance and the bias preferred to what level motion cannot tell from it,
/// four of these twelve named one (9531 an accelerometer scale factor beside the biases; 9533,
/// 9539 and 9541 a misalignment in place of the accelerometer bias); now none does.
#[test]
fn a_drifting_imu_bias_is_not_taken_for_a_scale_or_misalignment() {
    use auvnav_tools::discover::hidden_effects::{coloured, trial_set_with};
    let d = dir("discover-drift");
    let mut named = Vec::new();
    for seed in 9531u64..=9542 {
        let (t, _) = trial_set_with(seed, &[], &coloured(seed), &d.0).expect("trial");
        let imu: Vec<String> = t
            .found
            .iter()
            .filter(|n| n.starts_with("imu.") && !n.ends_with("_bias"))
            .cloned()
            .collect();
        println!("seed {seed}: found {:?}", t.found);
        if !imu.is_empty() {
            named.push((seed, imu));
        }
    }
    assert!(named.len() <= 1, "{named:?}");
}

/// An estimate beyond what the IMU classes an AUV carries have is not named: a gyro z scale
/// factor of 2 % (the turns excite it well) comes back in `implausible` with its value and a
/// note, and the report names nothing in its place; 0.4 % is named as usual.
#[test]
fn an_implausible_imu_estimate_is_reported_not_named() {
    let d = dir("discover-implausible");
    let (t, r) = trial_set(
        9571,
        &[Hidden::new(
            "imu.gyro_scale_factor",
            vec![0.0, 0.0, 20_000.0],
        )],
        &d.0,
    )
    .expect("trial");
    println!("found {:?}, implausible {:?}", t.found, r.implausible);
    assert!(t.found.is_empty(), "{:?}", t.found);
    let i = r
        .implausible
        .iter()
        .find(|i| i.name == "imu.gyro_scale_factor")
        .expect("reported as implausible");
    let z = i.value[2].as_f64().expect("z");
    assert!((z - 20_000.0).abs() < 0.1 * 20_000.0, "z {z}");
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("imu.gyro_scale_factor") && n.contains("not named"))
    );
    let (t, _) = trial_set(
        9572,
        &[Hidden::new(
            "imu.gyro_scale_factor",
            vec![0.0, 0.0, 4_000.0],
        )],
        &d.0,
    )
    .expect("trial");
    assert!(t.correct, "{t:?}");
}

/// What a log cannot show is said: a 0.37 s DVL time offset hidden in a docking run (seed 8803,
/// whose accelerations sit in its last minutes, so that the held-out blocks cannot confirm an
/// offset) is either named or reported with a floor above it. The floor is what the selection
/// would name: on the same run a DVL scale error twice its scale floor is named, one at half of
/// it is not.
#[test]
fn an_effect_below_the_floor_is_reported_as_such() {
    use auvnav_sim::{SimConfig, scenario::Scenario};
    use auvnav_tools::discover::command::{DiscoverReport, discover_messages};
    let run = |hidden: &[(&str, f64)]| -> DiscoverReport {
        let scenario = Scenario::load("docking").expect("scenario");
        let mut effects = scenario.effects().expect("effects");
        for (name, value) in hidden {
            effects.set(name, &[*value]).expect("hidden");
        }
        let cfg = SimConfig {
            scenario,
            effects,
            seed: 8803,
            duration_s: None,
        };
        discover_messages(&auvnav_tests::grade::simulate(&cfg))
    };
    let floor_of = |r: &DiscoverReport, name: &str| {
        r.floors
            .iter()
            .find(|f| f.name == name)
            .and_then(|f| f.floor[0])
    };
    let named = |r: &DiscoverReport, name: &str| r.effects.iter().any(|e| e.name == name);
    let small = run(&[("dvl.time_offset", 0.37)]);
    let offset_floor = floor_of(&small, "dvl.time_offset");
    println!(
        "0.37 s: named {}, floor {offset_floor:?} s",
        named(&small, "dvl.time_offset")
    );
    assert!(
        named(&small, "dvl.time_offset") || offset_floor.is_some_and(|f| f > 0.37),
        "{offset_floor:?}"
    );
    let scale_floor = floor_of(&small, "dvl.scale_factor").expect("a scale floor");
    for (factor, expect) in [(2.0, true), (0.5, false)] {
        let departure = factor * scale_floor;
        let r = run(&[("dvl.scale_factor", 1.0 + departure)]);
        println!(
            "scale 1 + {departure:.5} ({factor} × the floor {scale_floor:.5}): named {}",
            named(&r, "dvl.scale_factor")
        );
        assert_eq!(named(&r, "dvl.scale_factor"), expect, "{:#?}", r.effects);
    }
}
