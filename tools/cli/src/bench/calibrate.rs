//! `auvnav bench calibrate`: wall time and full replays of the DVL calibration methods on the
//! simulated S-CAL campaign (four straight voyages of 5.8–6.9 km, 100 Hz IMU) with a hidden
//! installation error, on all available cores.

#[allow(unused_imports)]
use super::*;
use crate::calibrate::{CalibrateDvlOptions, Holdout, Method, calibrate_dvl, voyage::VoyageSpec};

/// One method's cost and result.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrateBench {
    pub method: Method,
    pub full_replays: usize,
    pub surrogate_jacobians: usize,
    /// Fit and re-score (s): what the targets compare.
    pub fit_wall_s: f64,
    pub full_replays_per_second: f64,
    pub threads: usize,
    pub mount_yaw_deg: f64,
    pub scale_factor: f64,
    pub objective_before: f64,
    pub objective_after: f64,
}

/// The benchmark's output.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrateBenchReport {
    pub version: u32,
    pub campaign: String,
    pub seed: u64,
    pub voyages: usize,
    pub log_duration_s: f64,
    pub hidden_mount_yaw_deg: f64,
    pub hidden_scale_factor: f64,
    pub methods: Vec<CalibrateBench>,
    /// seed fit time over fast fit time.
    pub seed_over_fast: f64,
}

/// Simulates the campaign and times `fast`, `seed`, `smoother` and `two-point` on it.
pub fn calibrate(seed: u64, methods: &[Method], json: bool) -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("auvnav-bench-calibrate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = (|| -> anyhow::Result<CalibrateBenchReport> {
        let (yaw, scale) = (1.3, 1.003);
        let configs = sim::campaign::campaign(
            sim::campaign::CampaignKind::Scal,
            seed,
            &[
                ("dvl.mount_yaw".into(), vec![yaw]),
                ("dvl.scale_factor".into(), vec![scale]),
            ],
        )?;
        let mut specs = Vec::new();
        let mut log_duration_s = 0.0;
        for (i, cfg) in configs.iter().enumerate() {
            let path = dir.join(format!("voyage_{}.mcap", i + 1));
            log_duration_s += sim::simulate_to_log(cfg, &path)?.duration_s;
            specs.push(VoyageSpec {
                path,
                window_s: None,
            });
        }
        let mut out = Vec::new();
        for &method in methods {
            let mut a = CalibrateDvlOptions::new(specs.clone());
            a.method = method;
            a.holdout = Holdout::None;
            a.json = true;
            let r = calibrate_dvl(&a)?;
            let value = |n: &str| {
                r.parameters
                    .iter()
                    .find(|p| p.name == n)
                    .map(|p| p.value)
                    .unwrap_or(f64::NAN)
            };
            out.push(CalibrateBench {
                method,
                full_replays: r.evaluations.full_replays_fit,
                surrogate_jacobians: r.evaluations.surrogate_jacobians,
                fit_wall_s: r.evaluations.fit_wall_s,
                full_replays_per_second: r.evaluations.full_replays_per_second,
                threads: r.evaluations.threads,
                mount_yaw_deg: value("dvl.mount_yaw"),
                scale_factor: value("dvl.scale_factor"),
                objective_before: r.objective.before,
                objective_after: r.objective.after,
            });
        }
        let time = |m: Method| out.iter().find(|b| b.method == m).map(|b| b.fit_wall_s);
        let seed_over_fast = match (time(Method::Seed), time(Method::Fast)) {
            (Some(s), Some(f)) => s / f,
            _ => f64::NAN,
        };
        Ok(CalibrateBenchReport {
            version: 1,
            campaign: "scal".into(),
            seed,
            voyages: specs.len(),
            log_duration_s,
            hidden_mount_yaw_deg: yaw,
            hidden_scale_factor: scale,
            methods: out,
            seed_over_fast,
        })
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let r = result?;
    if json {
        crate::json::print(&r)?;
    } else {
        println!(
            "S-CAL campaign (seed {}): {} voyages, {:.0} s of log; hidden yaw {} deg, scale {}",
            r.seed, r.voyages, r.log_duration_s, r.hidden_mount_yaw_deg, r.hidden_scale_factor
        );
        for b in &r.methods {
            println!(
                "{:<10} {:>4} full replays in {:>7.1} s ({:.2}/s, {} threads): yaw {:.4} deg, scale {:.5}, objective {:.6} -> {:.6}",
                format!("{:?}", b.method),
                b.full_replays,
                b.fit_wall_s,
                b.full_replays_per_second,
                b.threads,
                b.mount_yaw_deg,
                b.scale_factor,
                b.objective_before,
                b.objective_after
            );
        }
        println!("seed / fast wall time: {:.1}", r.seed_over_fast);
    }
    Ok(())
}
