//! DVL calibration on measured data: four Snapir segments, as recorded and with a known
//! installation error hidden by `auvnav perturb` (mounting yaw +1.5 deg, scale 0.996). The fast
//! method must find the hidden error as the difference between the two calibrations. Outside CI
//! the test is skipped with a message when the data is absent; under CI its absence is a failure.

use auvnav_tests::processes::{TempDir, binary};
use auvnav_tools::calibrate::voyage::{FixSource, VoyageSpec};
use auvnav_tools::calibrate::{CalibrateDvlOptions, Holdout, calibrate_dvl};
use std::path::PathBuf;
use std::process::Command;

fn run(cmd: &mut Command) {
    let out = cmd.output().expect("auvnav");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_hidden_yaw_and_scale_error_is_recovered_on_snapir_segments() {
    let Some(data) = auvnav_tests::measured_data("snapir-auv", "imu_01.csv") else {
        return;
    };
    let dir = TempDir::new("calsnapir");
    let mut plain = Vec::new();
    let mut perturbed = Vec::new();
    for segment in [2, 3, 7, 13] {
        let a = dir.path().join(format!("seg{segment}.mcap"));
        let b = dir.path().join(format!("pert{segment}.mcap"));
        run(Command::new(binary("auvnav"))
            .args(["import", "snapir"])
            .arg(&data)
            .args(["--segment", &segment.to_string(), "--out"])
            .arg(&a));
        run(Command::new(binary("auvnav"))
            .arg("perturb")
            .arg(&a)
            .args([
                "--effect",
                "dvl.mount_yaw=1.5",
                "--effect",
                "dvl.scale_factor=0.996",
                "--out",
            ])
            .arg(&b));
        plain.push(a);
        perturbed.push(b);
    }
    let fit = |paths: &[PathBuf]| {
        let mut a = CalibrateDvlOptions::new(
            paths
                .iter()
                .map(|p| VoyageSpec {
                    path: p.clone(),
                    window_s: None,
                })
                .collect(),
        );
        a.fixes = FixSource::Truth;
        a.threshold = 100.0;
        a.params = vec!["dvl.mount_yaw".into(), "dvl.scale_factor".into()];
        a.holdout = Holdout::None;
        let r = calibrate_dvl(&a).expect("calibrate");
        let v = |n: &str| {
            r.parameters
                .iter()
                .find(|p| p.name == n)
                .map(|p| p.value)
                .expect(n)
        };
        (v("dvl.mount_yaw"), v("dvl.scale_factor"), r.objective.after)
    };
    let (yaw0, scale0, cep0) = fit(&plain);
    let (yaw1, scale1, cep1) = fit(&perturbed);
    eprintln!(
        "recorded: yaw {yaw0:.4} deg, scale {scale0:.5}, CEP50 {cep0:.5}; perturbed: yaw {yaw1:.4} deg, scale {scale1:.5}, CEP50 {cep1:.5}"
    );
    assert!((yaw1 - yaw0 - 1.5).abs() < 0.1, "yaw {yaw0} -> {yaw1}");
    assert!(
        (scale1 / scale0 - 0.996).abs() < 1e-3,
        "scale {scale0} -> {scale1}"
    );
    // Calibrated, the perturbed segments navigate as well as the recorded ones (within 10 %).
    assert!(cep1 < 1.1 * cep0, "CEP50 {cep0} -> {cep1}");
}
