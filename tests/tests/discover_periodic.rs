//! Model discovery finds a periodic DVL velocity error (`dvl.periodic_velocity_error`) hidden
//! in simulated trial voyages (other seeds than the benchmark's), with the period and phase of
//! the residual's strongest line.

use auvnav_sim::effects::Effects;
use auvnav_tools::discover::command::{discover, read_logs};
use auvnav_tools::discover::fit::Selection;
use auvnav_tools::discover::hidden_effects::simulate;

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

/// A periodic DVL velocity error (`dvl.periodic_velocity_error`, its period and phase) hidden in
/// the trial voyages, either sign, the axes in phase or in antiphase: named alone, its amplitudes
/// within 10 %, its period within 2 % and within four of its deviations, its phase within 15°;
/// a voyage with nothing hidden offers the candidate at its strongest line and names nothing.
#[test]
fn a_periodic_dvl_velocity_error_is_named_with_its_period_and_phase() {
    let d = dir("discover-periodic");
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
        let log = simulate(seed, &settings, &d.0).expect("simulation");
        let (channels, reference, _) = read_logs(std::slice::from_ref(&log)).expect("read");
        let r = discover(
            &channels,
            &reference,
            &Effects::default(),
            0.7,
            &Selection::default(),
        );
        let names: Vec<&str> = r.effects.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(
            names,
            ["dvl.periodic_velocity_error"],
            "seed {seed}: {:#?}",
            r.effects
        );
        let e = &r.effects[0];
        let got = auvnav_tools::discover::analysis::values_of(&e.value).expect("value");
        let line = e.line.expect("the line it was fitted at");
        let err = (0..3)
            .map(|k| (got[k] - amplitude[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            / amplitude.iter().map(|a| a * a).sum::<f64>().sqrt();
        let phase_err = (line.phase_deg - phase + 540.0).rem_euclid(360.0) - 180.0;
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
    let log = simulate(9223, &[], &d.0).expect("simulation");
    let (channels, reference, _) = read_logs(std::slice::from_ref(&log)).expect("read");
    let r = discover(
        &channels,
        &reference,
        &Effects::default(),
        0.7,
        &Selection::default(),
    );
    assert!(r.effects.is_empty(), "{:#?}", r.effects);
    assert!(
        r.floors
            .iter()
            .any(|f| f.name == "dvl.periodic_velocity_error"),
        "the candidate was offered and has a floor"
    );
}
