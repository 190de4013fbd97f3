//! S-ALIGN fine alignment (`auvnav align`), small Monte Carlo counts (the tool's defaults are the
//! seed's 220 runs): the error models agree when the errors are small, the mounting yaw is not
//! observable on a straight run but is in turns, and model 1 meets the turning target.

use auvnav_tools::align::{AlignOptions, AlignReport, ModelReport, run};

fn args(scenario: &str, runs: usize, seconds: f64, heading: f64, mount: &str) -> AlignOptions {
    AlignOptions {
        models: vec![],
        scenario: scenario.into(),
        runs,
        heading_error: heading,
        mount: mount.into(),
        seed: 11,
        seconds,
        converged_deg: 1.0,
        threads: None,
        per_run: false,
        json: false,
    }
}

fn model(r: &AlignReport, n: u8) -> &ModelReport {
    r.models.iter().find(|m| m.model == n).expect("model")
}

fn heading_at(m: &ModelReport, t: f64) -> f64 {
    m.heading_rms_deg
        .iter()
        .find(|(at, _)| *at == t)
        .map(|(_, v)| *v)
        .expect("checkpoint")
}

#[test]
fn models_1_and_3_agree_when_misalignment_and_mounting_are_small() {
    // 0.5° heading error, DVL aligned with the body: the body-frame and navigation-frame models
    // describe the same small errors.
    let r = run(&args("straight", 6, 600.0, 0.5, "0,0,0")).expect("align");
    let (m1, m3) = (model(&r, 1), model(&r, 3));
    for t in [300.0, 600.0] {
        let (a, b) = (heading_at(m1, t), heading_at(m3, t));
        eprintln!("{t} s: model 1 {a:.4} deg, model 3 {b:.4} deg");
        assert!((a - b).abs() < 0.2 * a.max(b) + 0.005, "{t} s: {a} vs {b}");
    }
    assert!((m1.position_rms_m - m3.position_rms_m).abs() < 0.2 * m3.position_rms_m + 1.0);
}

#[test]
fn the_mounting_yaw_is_observable_in_turns_not_on_a_straight_run() {
    let straight = run(&args("straight", 6, 600.0, 10.0, "random")).expect("align");
    let turning = run(&args("turning", 6, 600.0, 10.0, "random")).expect("align");
    for n in [1, 2] {
        let s = model(&straight, n).mount_error_rms_deg.expect("mounting")[2];
        let t = model(&turning, n).mount_error_rms_deg.expect("mounting")[2];
        eprintln!("model {n}: mounting yaw error RMS straight {s:.3} deg, turning {t:.3} deg");
        // Straight: no better than the 1° prior; turning: a fraction of it.
        assert!(s > 0.5 && t < 0.3 && s > 3.0 * t, "model {n}: {s} vs {t}");
    }
}

#[test]
fn model_1_aligns_within_a_tenth_of_a_degree_by_600_s_when_turning_from_30_degrees() {
    let r = run(&args("turning", 6, 600.0, 30.0, "random")).expect("align");
    let m1 = model(&r, 1);
    let h = heading_at(m1, 600.0);
    eprintln!("model 1, turning, 30°: heading RMS at 600 s {h:.4} deg");
    assert!(h <= 0.1, "{h}");
    assert_eq!(m1.not_converged, 0);
}

/// On every measured segment, started 20° and 45° off the reference heading, every model brings
/// the heading error under 2° by 200 s (the measured figures are in docs/alignment.md).
#[test]
fn measured_segments_align_from_large_heading_offsets() {
    let Some(dir) = auvnav_tests::measured_data("snapir-auv", "imu_01.csv") else {
        return;
    };
    let rows = auvnav_tools::align::run_measured(&auvnav_tools::align::AlignMeasuredOptions {
        dir,
        heading_offsets: vec![20.0, -45.0],
        segments: vec![],
        json: false,
    })
    .expect("measured alignment");
    assert_eq!(rows.len(), 13 * 2 * 3);
    for r in &rows {
        let at200 = r
            .heading_error_deg
            .iter()
            .find(|(t, _)| *t == 200.0)
            .map(|(_, e)| *e)
            .expect("200 s");
        assert!(at200.abs() < 2.0, "{r:?}");
    }
}
