//! The smoothing report (`auvnav smooth --report DIR`): per log, the forward and smoothed tracks
//! with the reference and the fixes, the position standard deviation along the voyage (forward
//! and smoothed), the error against the reference, the fixes' innovations (fused and rejected),
//! and the smoothed DVL installation and IMU biases; Markdown, SVG figures and JSON.

use super::{FixInnovation, LogSmoothReport, SmoothReport};
use auvnav_core::earth::{Geodetic, ned_offset};
use auvnav_replay::svg::{PALETTE, Series, plot};
use auvnav_shm_schema::{NavSolutionV1, TruthStateV1};
use std::fmt::Write as _;
use std::path::Path;

/// Time series for the figures, thinned to one point a second.
#[derive(Debug, Clone, Default)]
pub struct Figures {
    origin: Option<Geodetic>,
    last_solution_s: Option<f64>,
    last_reference_s: Option<f64>,
    /// (east, north) m from the first solution.
    pub forward_track: Vec<(f64, f64)>,
    pub smoothed_track: Vec<(f64, f64)>,
    pub reference_track: Vec<(f64, f64)>,
    /// (time s, horizontal σ m): the larger of north and east.
    pub forward_std: Vec<(f64, f64)>,
    pub smoothed_std: Vec<(f64, f64)>,
    /// (time s, horizontal error m) against the reference.
    pub forward_error: Vec<(f64, f64)>,
    pub smoothed_error: Vec<(f64, f64)>,
    pub innovations: Vec<FixInnovation>,
}

fn geo(lat: f64, lon: f64, h: f64) -> Geodetic {
    Geodetic {
        latitude_rad: lat,
        longitude_rad: lon,
        height_m: h,
    }
}

impl Figures {
    fn east_north(&mut self, g: &Geodetic) -> (f64, f64) {
        let o = *self.origin.get_or_insert(*g);
        let d = ned_offset(&o, g);
        (d.y, d.x)
    }

    /// A forward solution and its smoothed counterpart.
    pub fn solution(&mut self, fwd: &NavSolutionV1, sm: &NavSolutionV1) {
        let t = fwd.host_time_ns as f64 * 1e-9;
        if self.last_solution_s.is_some_and(|l| t - l < 1.0) {
            return;
        }
        self.last_solution_s = Some(t);
        let f = self.east_north(&geo(fwd.latitude_rad, fwd.longitude_rad, fwd.height_m));
        let s = self.east_north(&geo(sm.latitude_rad, sm.longitude_rad, sm.height_m));
        self.forward_track.push(f);
        self.smoothed_track.push(s);
        let h = |x: &NavSolutionV1| x.position_std_ned_m[0].max(x.position_std_ned_m[1]);
        self.forward_std.push((t, h(fwd)));
        self.smoothed_std.push((t, h(sm)));
    }

    /// A reference epoch with the forward and smoothed horizontal errors there.
    pub fn reference(&mut self, truth: &TruthStateV1, forward_m: f64, smoothed_m: f64) {
        let t = truth.host_time_ns as f64 * 1e-9;
        if self.last_reference_s.is_some_and(|l| t - l < 1.0) {
            return;
        }
        self.last_reference_s = Some(t);
        let r = self.east_north(&geo(
            truth.latitude_rad,
            truth.longitude_rad,
            truth.height_m,
        ));
        self.reference_track.push(r);
        self.forward_error.push((t, forward_m));
        self.smoothed_error.push((t, smoothed_m));
    }
}

fn series(name: &str, points: &[(f64, f64)], color: usize, markers: bool) -> Series {
    Series {
        name: name.to_string(),
        points: points.to_vec(),
        color: PALETTE[color % PALETTE.len()],
        markers,
        dashed: false,
    }
}

fn write_log_figures(dir: &Path, stem: &str, l: &LogSmoothReport) -> anyhow::Result<Vec<String>> {
    let f = &l.figures;
    let write = auvnav_replay::write_atomically;
    let mut names = Vec::new();
    let mut track = vec![
        series("forward", &f.forward_track, 0, false),
        series("smoothed", &f.smoothed_track, 2, false),
    ];
    if !f.reference_track.is_empty() {
        track.push(series("reference", &f.reference_track, 1, false));
    }
    let name = format!("{stem}.track.svg");
    write(
        &dir.join(&name),
        &plot("Track", "east (m)", "north (m)", &track, true),
    )?;
    names.push(name);
    let name = format!("{stem}.std.svg");
    write(
        &dir.join(&name),
        &plot(
            "Horizontal position standard deviation",
            "log time (s)",
            "sigma (m)",
            &[
                series("forward", &f.forward_std, 0, false),
                series("smoothed", &f.smoothed_std, 2, false),
            ],
            false,
        ),
    )?;
    names.push(name);
    if !f.forward_error.is_empty() {
        let name = format!("{stem}.error.svg");
        write(
            &dir.join(&name),
            &plot(
                "Horizontal error against the reference",
                "log time (s)",
                "error (m)",
                &[
                    series("forward", &f.forward_error, 0, false),
                    series("smoothed", &f.smoothed_error, 2, false),
                ],
                false,
            ),
        )?;
        names.push(name);
    }
    if !f.innovations.is_empty() {
        let pts = |fused: bool| -> Vec<(f64, f64)> {
            f.innovations
                .iter()
                .filter(|i| i.fused == fused)
                .map(|i| (i.time_s, i.innovation[0].hypot(i.innovation[1])))
                .collect()
        };
        let name = format!("{stem}.innovations.svg");
        write(
            &dir.join(&name),
            &plot(
                "Fix innovations (horizontal)",
                "log time (s)",
                "|innovation| (m)",
                &[
                    series("fused", &pts(true), 2, true),
                    series("rejected", &pts(false), 1, true),
                ],
                false,
            ),
        )?;
        names.push(name);
    }
    Ok(names)
}

fn value(v: &auvnav_core::smoother::SmoothedValue, digits: usize) -> String {
    format!("{:.*} ± {:.*}", digits, v.value, digits, v.std)
}

/// Writes the report into `dir`.
pub fn write(dir: &Path, r: &SmoothReport) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut md = String::from("# Smoothing report\n\n");
    if let Some(f) = &r.fix_file {
        let _ = writeln!(
            md,
            "Fix file `{}`: {} fixes, {} lines not used.\n",
            f.path,
            f.fixes.len(),
            f.unparsable_lines
        );
    }
    for l in &r.logs {
        let stem = Path::new(&l.log)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "log".into());
        let figures = write_log_figures(dir, &stem, l)?;
        let _ = writeln!(md, "## {}\n", l.log);
        let _ = writeln!(
            md,
            "{:.0} s of log, {} covariance epochs in {} chain(s), {} solutions smoothed. Fixes: {} from the file ({} outside the log), GNSS {} fused / {} rejected, USBL {} fused / {} rejected.\n",
            l.log_duration_s,
            l.epochs,
            l.chains,
            l.solutions_smoothed,
            l.fixes.from_file,
            l.fixes.from_file_outside_log,
            l.fixes.gnss_fused,
            l.fixes.gnss_rejected,
            l.fixes.usbl_fused,
            l.fixes.usbl_rejected
        );
        if let Some(c) = &l.against_reference {
            let _ = writeln!(
                md,
                "| against the reference ({} epochs) | RMS (m) | max (m) | final (m) | horizontal NEES (2 = honest) |\n|---|---|---|---|---|\n| forward | {:.2} | {:.2} | {:.2} | {:.2} |\n| smoothed | {:.2} | {:.2} | {:.2} | {:.2} |\n",
                c.epochs,
                c.forward.horizontal_error_rms_m,
                c.forward.horizontal_error_max_m,
                c.forward.horizontal_error_final_m,
                c.forward_nees_horizontal_mean,
                c.smoothed.horizontal_error_rms_m,
                c.smoothed.horizontal_error_max_m,
                c.smoothed.horizontal_error_final_m,
                c.smoothed_nees_horizontal_mean
            );
        } else {
            md.push_str("The log has no truth or reference channel: no error figures.\n\n");
        }
        if let Some(p) = &l.parameters {
            md.push_str("| smoothed state | first epoch | last epoch |\n|---|---|---|\n");
            let row3 = |md: &mut String,
                        name: &str,
                        a: &Option<[auvnav_core::smoother::SmoothedValue; 3]>,
                        b: &Option<[auvnav_core::smoother::SmoothedValue; 3]>,
                        d: usize| {
                if let (Some(a), Some(b)) = (a, b) {
                    for k in 0..3 {
                        let _ = writeln!(
                            md,
                            "| {name} [{k}] | {} | {} |",
                            value(&a[k], d),
                            value(&b[k], d)
                        );
                    }
                }
            };
            row3(
                &mut md,
                "DVL mounting (deg)",
                &p.first.dvl_mount_deg,
                &p.last.dvl_mount_deg,
                3,
            );
            if let (Some(a), Some(b)) = (&p.first.dvl_scale_factor, &p.last.dvl_scale_factor) {
                let _ = writeln!(
                    md,
                    "| DVL scale factor | {} | {} |",
                    value(a, 5),
                    value(b, 5)
                );
            }
            row3(
                &mut md,
                "DVL lever arm (m)",
                &p.first.dvl_lever_arm_m,
                &p.last.dvl_lever_arm_m,
                3,
            );
            if let (Some(a), Some(b)) = (&p.first.dvl_time_offset_s, &p.last.dvl_time_offset_s) {
                let _ = writeln!(
                    md,
                    "| DVL time offset (s) | {} | {} |",
                    value(a, 3),
                    value(b, 3)
                );
            }
            row3(
                &mut md,
                "USBL errors (m)",
                &p.first.usbl_errors_m,
                &p.last.usbl_errors_m,
                3,
            );
            if let (Some(a), Some(b)) = (&p.imu_biases_first, &p.imu_biases_last) {
                for k in 0..3 {
                    let _ = writeln!(
                        md,
                        "| gyro bias [{k}] (deg/h) | {} | {} |",
                        value(&a.gyro_bias_deg_h[k], 4),
                        value(&b.gyro_bias_deg_h[k], 4)
                    );
                }
                for k in 0..3 {
                    let _ = writeln!(
                        md,
                        "| accelerometer bias [{k}] (µg) | {} | {} |",
                        value(&a.accel_bias_ug[k], 1),
                        value(&b.accel_bias_ug[k], 1)
                    );
                }
            }
            md.push('\n');
        }
        for f in figures {
            let _ = writeln!(md, "![{f}]({f})\n");
        }
    }
    let write = auvnav_replay::write_atomically;
    write(&dir.join("report.md"), &md)?;
    write(&dir.join("report.json"), &serde_json::to_string_pretty(r)?)?;
    Ok(())
}
