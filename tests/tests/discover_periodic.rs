//! Model discovery finds a periodic DVL velocity error (`dvl.periodic_velocity_error`) hidden
//! in simulated trial voyages (other seeds than the benchmark's), with the period and phase of
//! the residual's strongest line.

use auvnav_sim::effects::Effects;
use auvnav_tools::discover::command::{discover, read_logs};
use auvnav_tools::discover::fit::Selection;
use auvnav_tools::discover::hidden_effects::simulate;
use auvnav_tools::discover::periodic::amplitudes_near_phase;

use auvnav_tests::processes::TempDir;
use auvnav_tools::discover::findings::DiscoverReport;

/// Discovery on one log from the nominal model (every effect off), 70 % fitted.
fn discover_log(log: &std::path::Path) -> DiscoverReport {
    let (channels, reference, _) = read_logs(&[log.to_path_buf()]).expect("read");
    discover(
        &channels,
        &reference,
        &Effects::default(),
        0.7,
        &Selection::default(),
    )
}

/// A periodic DVL velocity error (`dvl.periodic_velocity_error`, its period and phase) hidden in
/// the trial voyages, either sign, the axes in phase or in antiphase: named alone, its amplitudes
/// within 10 %, its period within 2 % and within four of its deviations, its phase within 15°;
/// a voyage with nothing hidden offers the candidate at its strongest line and names nothing.
#[test]
fn a_periodic_dvl_velocity_error_is_named_with_its_period_and_phase() {
    let d = TempDir::new("discover-periodic");
    let cases: [(u64, [f64; 3], f64, f64); 2] = [
        (9221, [0.02, -0.012, 0.0], 31.0, 40.0),
        (9222, [-0.008, 0.015, 0.004], 17.0, -120.0),
    ];
    for (seed, amplitude, period, phase) in cases {
        let settings = [
            (
                "dvl.periodic_velocity_error".to_string(),
                amplitude.to_vec(),
            ),
            ("dvl.periodic_velocity_error_period".into(), vec![period]),
            ("dvl.periodic_velocity_error_phase".into(), vec![phase]),
        ];
        let r = discover_log(&simulate(seed, &settings, &d.0).expect("simulation"));
        let names: Vec<&str> = r.effects.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(
            names,
            ["dvl.periodic_velocity_error"],
            "seed {seed}: {:#?}",
            r.effects
        );
        let e = &r.effects[0];
        let line = e.line.expect("the line it was fitted at");
        // ±a at φ and φ + 180° are the same error: compared at the hidden phase's sign.
        let got = amplitudes_near_phase(
            &auvnav_tools::discover::analysis::values_of(&e.value).expect("value"),
            line.phase_deg,
            phase,
        );
        let err = (0..3)
            .map(|k| (got[k] - amplitude[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            / amplitude.iter().map(|a| a * a).sum::<f64>().sqrt();
        // The phase's error modulo the half turn that a sign of the amplitudes takes.
        let phase_err = (line.phase_deg - phase + 90.0).rem_euclid(180.0) - 90.0;
        println!(
            "seed {seed}: hidden {amplitude:?} m/s, {period} s, {phase}°; found {got:?} \
             ({:.1} %), {:.2} ± {:.2} s, {:.1} ± {:.1}°, line {:.0}× its background",
            100.0 * err,
            line.period_s,
            line.period_std_s,
            line.phase_deg,
            line.phase_std_deg,
            line.line_to_background
        );
        assert!(err < 0.1, "seed {seed}: {got:?} against {amplitude:?}");
        assert!((line.period_s - period).abs() < 0.02 * period, "{line:?}");
        assert!(
            (line.period_s - period).abs() < 4.0 * line.period_std_s,
            "{line:?}"
        );
        assert!(phase_err.abs() < 15.0, "{line:?}");
    }
    let r = discover_log(&simulate(9223, &[], &d.0).expect("simulation"));
    assert!(r.effects.is_empty(), "{:#?}", r.effects);
    assert!(
        r.floors
            .iter()
            .any(|f| f.name == "dvl.periodic_velocity_error"),
        "the candidate was offered and has a floor"
    );
}

/// The same error hidden with `perturb` in each of the 13 measured Snapir segments (DVL against
/// the reference solution, whose own residual is coloured and carries the 86 s line): named in
/// at least seven (eight when this was written), each at its period within three of the line's
/// deviations and each amplitude within three of its own; a segment that does not name it says
/// why (a floor, or pointed at without being determined), never silence. Two segments at a time.
#[test]
fn a_periodic_error_hidden_in_measured_segments_is_found() {
    use auvnav_sim::perturb::{Perturbation, perturb_log};
    let Some(data) = auvnav_tests::measured_data("snapir-auv", "imu_01.csv") else {
        return;
    };
    let d = TempDir::new("discover-periodic-measured");
    let (amplitude, period, phase) = ([0.008, 0.006, -0.003], 25.0, -100.0);
    let p = Perturbation::parse(
        &[
            "dvl.periodic_velocity_error=0.008,0.006,-0.003".to_string(),
            format!("dvl.periodic_velocity_error_period={period}"),
            format!("dvl.periodic_velocity_error_phase={phase}"),
        ],
        1,
    )
    .expect("perturbation");
    let segment_report = |segment: u32| {
        let base = d.0.join(format!("s{segment}.mcap"));
        auvnav_tests::processes::import_snapir(&data, segment, &base);
        let perturbed = d.0.join(format!("s{segment}p.mcap"));
        perturb_log(&base, &perturbed, &p).expect("perturb");
        (segment, discover_log(&perturbed))
    };
    let segments: Vec<u32> = (1..=13).collect();
    let reports: Vec<_> = std::thread::scope(|s| {
        let halves: Vec<_> = segments
            .chunks(7)
            .map(|part| s.spawn(|| part.iter().map(|&k| segment_report(k)).collect::<Vec<_>>()))
            .collect();
        halves
            .into_iter()
            .flat_map(|h| h.join().expect("a segment's discovery"))
            .collect()
    });
    let mut named = 0;
    for (segment, r) in &reports {
        let Some(e) = r
            .effects
            .iter()
            .find(|e| e.name == "dvl.periodic_velocity_error")
        else {
            let accounted = r
                .floors
                .iter()
                .any(|f| f.name == "dvl.periodic_velocity_error")
                || r.undetermined
                    .iter()
                    .any(|u| u.name == "dvl.periodic_velocity_error");
            eprintln!("segment {segment:2}: not named (accounted for: {accounted})");
            assert!(accounted, "segment {segment}: silent on the hidden error");
            continue;
        };
        named += 1;
        let line = e.line.expect("its line");
        let got = amplitudes_near_phase(
            &auvnav_tools::discover::analysis::values_of(&e.value).expect("value"),
            line.phase_deg,
            phase,
        );
        let std = auvnav_tools::discover::analysis::values_of(&e.std).expect("std");
        eprintln!(
            "segment {segment:2}: {got:.4?} ± {std:.4?} m/s at {:.2} ± {:.2} s, {:.1} ± {:.1}°",
            line.period_s, line.period_std_s, line.phase_deg, line.phase_std_deg
        );
        assert!(
            (line.period_s - period).abs() < 3.0 * line.period_std_s,
            "segment {segment}: {line:?}"
        );
        for k in 0..3 {
            assert!(
                (got[k] - amplitude[k]).abs() < 3.0 * std[k],
                "segment {segment}: axis {k}: {} ± {} against {}",
                got[k],
                std[k],
                amplitude[k]
            );
        }
    }
    assert!(named >= 7, "named in {named} of 13 segments");
}
