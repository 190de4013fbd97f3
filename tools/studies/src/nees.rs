//! `auvnav montecarlo nees`: filter consistency by Monte Carlo.
//!
//! Each run simulates the scenario with sensor errors drawn from exactly the statistics the
//! filter assumes (white IMU noise at the configured random walks, constant IMU biases drawn from
//! the initial bias uncertainty, bias random walks, DVL beam noise and depth noise), starts the
//! navigator from the truth perturbed by a draw from its initial covariance, and records at every
//! truth epoch the normalised estimation error squared (NEES) of position, velocity and attitude:
//! `e^T P^-1 e` with `e` the estimate minus the truth and `P` the filter's block. Averaged over `N`
//! runs, `N * ANEES` of a consistent filter is chi-square with `3 N` degrees of freedom; the report
//! gives the two-sided 95 % bounds and the fraction of epochs inside them per block.

use crate::StudyError;
use crate::error::usage;
use auvnav_core::earth;
use auvnav_core::ekf as filter;
use auvnav_core::navigator::NavConfig;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_core::strapdown::truth_position;
use auvnav_log::LogMessage;
use auvnav_sim::{self as sim, SimConfig, effects::Effects, rng::Rng, scenario::Scenario};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::Serialize;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct NeesOptions {
    /// Number of Monte Carlo runs.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 50))]
    pub runs: usize,
    /// Built-in scenario or scenario file.
    #[cfg_attr(feature = "clap", arg(long, default_value = "lawnmower"))]
    pub scenario: String,
    /// Simulated seconds per run (default: the whole scenario).
    #[cfg_attr(feature = "clap", arg(long))]
    pub seconds: Option<f64>,
    /// First seed; run k uses seed + k.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// DVL beam noise (m/s).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.01))]
    pub dvl_beam_noise: f64,
    /// Epochs before this time (s from the start) are left out of the statistics.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 10.0))]
    pub skip_seconds: f64,
    /// Configuration TOML with a `[navigation]` table (the filter and the simulated errors both
    /// follow it).
    #[cfg_attr(feature = "clap", arg(long))]
    pub config: Option<std::path::PathBuf>,
    /// Write the run-averaged NEES per epoch to this CSV (time_s, position, velocity, attitude).
    #[cfg_attr(feature = "clap", arg(long))]
    pub series: Option<std::path::PathBuf>,
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// Statistics of one NEES block.
#[derive(Debug, Clone, Serialize)]
pub struct NeesBlock {
    /// Mean over epochs of the run-averaged NEES (3 for a consistent filter).
    pub mean_anees: f64,
    /// Fraction of epochs whose run-averaged NEES is inside the 95 % bounds.
    pub fraction_inside: f64,
    pub fraction_above: f64,
    pub fraction_below: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct NeesReport {
    pub scenario: String,
    pub runs: usize,
    pub epochs: usize,
    pub wall_s_per_run: f64,
    /// Two-sided 95 % bounds of the run-averaged NEES (3 degrees of freedom per run).
    pub lower_bound: f64,
    pub upper_bound: f64,
    pub position: NeesBlock,
    pub velocity: NeesBlock,
    pub attitude: NeesBlock,
    /// Run-averaged NEES per epoch: time (s), position, velocity, attitude.
    #[serde(skip)]
    pub series: Vec<[f64; 4]>,
}

/// The χ² quantile with `k` degrees of freedom at the probability of the standard normal's `z`
/// (z = ±1.96: the 2.5 % and 97.5 % points), from `statrs` (exact inverse; k > 0).
pub fn chi2_quantile(k: f64, z: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};
    let p = Normal::standard().cdf(z);
    match ChiSquared::new(k) {
        Ok(chi2) => chi2.inverse_cdf(p),
        Err(_) => f64::NAN,
    }
}

/// The F quantile with `d1` and `d2` degrees of freedom at the probability of the standard
/// normal's `z`, from `statrs`; an infinite `d2` gives the χ² quantile over `d1`.
pub fn f_quantile(d1: f64, d2: f64, z: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, FisherSnedecor, Normal};
    if !d2.is_finite() {
        return chi2_quantile(d1, z) / d1;
    }
    let p = Normal::standard().cdf(z);
    match FisherSnedecor::new(d1, d2) {
        Ok(f) => f.inverse_cdf(p),
        Err(_) => f64::NAN,
    }
}

/// The attitude error `phi` with `C_est = (I - [phi x]) C_true`.
fn attitude_error(est: &UnitQuaternion<f64>, truth: &UnitQuaternion<f64>) -> Vector3<f64> {
    -(est * truth.inverse()).scaled_axis()
}

fn nees(e: &Vector3<f64>, p: &Matrix3<f64>) -> f64 {
    match p.try_inverse() {
        Some(inv) => (e.transpose() * inv * e)[(0, 0)],
        None => f64::INFINITY,
    }
}

/// The simulation effects matching the filter's noise model, with biases drawn for one run.
pub fn matched_effects(
    cfg: &NavConfig,
    dvl_beam_noise: f64,
    rng: &mut Rng,
) -> Result<Effects, StudyError> {
    let mut e = Effects::default();
    // A Gauss-Markov bias with sigma s and correlation time T grows like a random walk of
    // density sqrt(2 s^2 / T) for t << T: pick s so the densities agree. The simulator starts
    // the Gauss-Markov state from its stationary spread s, so the constant part is drawn with
    // the rest of the initial uncertainty, sqrt(P0 - s^2).
    let tau = 1.0e6;
    e.set("imu.bias_correlation_time", &[tau])?;
    let gyro_gm = cfg.gyro_bias_walk_deg_h_sqrt_h / 60.0 * (tau / 2.0).sqrt();
    let accel_gm = cfg.accel_bias_walk_ug_sqrt_h / 60.0 * (tau / 2.0).sqrt();
    if gyro_gm > cfg.initial_gyro_bias_std_deg_h || accel_gm > cfg.initial_accel_bias_std_ug {
        usage!(
            "the bias walk over the correlation time exceeds the initial bias uncertainty; \
             raise initial_gyro_bias_std_deg_h / initial_accel_bias_std_ug"
        );
    }
    e.set("imu.gyro_bias_instability", &[gyro_gm])?;
    e.set("imu.accel_bias_instability", &[accel_gm])?;
    let gb = (cfg.initial_gyro_bias_std_deg_h.powi(2) - gyro_gm.powi(2)).sqrt();
    let ab = (cfg.initial_accel_bias_std_ug.powi(2) - accel_gm.powi(2)).sqrt();
    e.set(
        "imu.gyro_bias",
        &[rng.gauss(gb), rng.gauss(gb), rng.gauss(gb)],
    )?;
    e.set(
        "imu.accel_bias",
        &[rng.gauss(ab), rng.gauss(ab), rng.gauss(ab)],
    )?;
    e.set(
        "imu.angle_random_walk",
        &[cfg.gyro_angle_random_walk_deg_sqrt_h],
    )?;
    e.set(
        "imu.velocity_random_walk",
        &[cfg.accel_velocity_random_walk_m_s_sqrt_h],
    )?;
    e.set("dvl.noise", &[dvl_beam_noise])?;
    e.set("depth.noise", &[cfg.depth_std_m])?;
    Ok(e)
}

/// Runs the Monte Carlo and returns the report.
pub fn nees_monte_carlo(a: &NeesOptions, cfg: &NavConfig) -> Result<NeesReport, StudyError> {
    nees_monte_carlo_with(a, cfg, cfg)
}

/// The Monte Carlo with the simulated errors drawn from `truth_cfg` and the filter run with
/// `filter_cfg` (to show what a mis-tuned filter looks like), on this machine's cores.
pub fn nees_monte_carlo_with(
    a: &NeesOptions,
    truth_cfg: &NavConfig,
    filter_cfg: &NavConfig,
) -> Result<NeesReport, StudyError> {
    let study = NeesStudy::new(a, truth_cfg, filter_cfg)?;
    let bar = crate::progress::Progress::new(!a.json).runs("NEES Monte Carlo", a.runs);
    crate::runs::run_local(&study, crate::parallel::default_threads(), &bar)
}

/// Writes the run-averaged NEES per epoch as CSV (time_s, position, velocity, attitude).
pub fn write_series(path: &std::path::Path, r: &NeesReport) -> Result<(), StudyError> {
    let mut text = String::from("time_s,anees_position,anees_velocity,anees_attitude\n");
    for e in &r.series {
        text.push_str(&format!("{},{},{},{}\n", e[0], e[1], e[2], e[3]));
    }
    std::fs::write(path, text).map_err(|e| StudyError::Output {
        path: path.to_path_buf(),
        source: e.into(),
    })
}

/// One run of the NEES study.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct NeesRun {
    /// Simulated seconds.
    pub seconds: f64,
    /// Per evaluated epoch: time (s from the start), position, velocity and attitude NEES.
    pub epochs: Vec<[f64; 4]>,
}

/// The NEES study: the scenario loaded, the configurations of the truth and the filter.
pub struct NeesStudy {
    args: NeesOptions,
    scenario: Scenario,
    truth_cfg: NavConfig,
    filter_cfg: NavConfig,
}

impl NeesStudy {
    /// Checks the options and loads the scenario.
    pub fn new(
        a: &NeesOptions,
        truth_cfg: &NavConfig,
        filter_cfg: &NavConfig,
    ) -> Result<NeesStudy, StudyError> {
        if a.runs == 0 {
            usage!("--runs must be at least 1");
        }
        // The errors the runs draw must be simulatable (a caller's configuration, checked once
        // here rather than failing every run).
        matched_effects(truth_cfg, a.dvl_beam_noise, &mut Rng::new(a.seed, "check"))?;
        Ok(NeesStudy {
            args: a.clone(),
            scenario: Scenario::load(&a.scenario)?,
            truth_cfg: truth_cfg.clone(),
            filter_cfg: filter_cfg.clone(),
        })
    }
}

impl crate::runs::RunStudy for NeesStudy {
    type Run = NeesRun;
    type Report = NeesReport;

    fn runs(&self) -> usize {
        self.args.runs
    }

    fn run(&self, k: usize) -> Result<NeesRun, StudyError> {
        self.one_run(k).map_err(|e| StudyError::run(k, e))
    }

    fn report(&self, runs: Vec<NeesRun>, wall_s: f64) -> Result<NeesReport, StudyError> {
        self.report_runs(runs, wall_s)
    }
}

impl NeesStudy {
    fn one_run(&self, k: usize) -> anyhow::Result<NeesRun> {
        let (a, truth_cfg, filter_cfg) = (&self.args, &self.truth_cfg, &self.filter_cfg);
        let seed = a.seed.wrapping_add(k as u64);
        let mut rng = Rng::new(seed, "montecarlo.nees");
        let effects = matched_effects(truth_cfg, a.dvl_beam_noise, &mut rng)?;
        let sim_cfg = SimConfig {
            scenario: self.scenario.clone(),
            effects,
            seed,
            duration_s: a.seconds,
        };
        // The daemon's feed path: messages go through the session (aid delay 0, as replay).
        let mut session = Session::new(&SessionConfig {
            navigation: filter_cfg.clone(),
            ..Default::default()
        });
        let mut epochs = Vec::new();
        let mut last_imu_ns = None;
        let mut start_ns = 0u64;
        let summary = sim::simulate(&sim_cfg, |m| -> anyhow::Result<()> {
            match m {
                LogMessage::Truth(t) => {
                    let truth_q = UnitQuaternion::from_euler_angles(
                        t.euler_rad[0],
                        t.euler_rad[1],
                        t.euler_rad[2],
                    );
                    let truth_pos = truth_position(t);
                    let Some(n) = session.navigator() else {
                        let start = crate::perturbed_start::perturbed_start(truth_cfg, t, &mut rng);
                        session.start(start, "truth perturbed by a draw of P0", &mut |_| {
                            Ok::<(), anyhow::Error>(())
                        })?;
                        start_ns = t.host_time_ns;
                        return Ok(());
                    };
                    if last_imu_ns != Some(t.host_time_ns) {
                        return Ok(());
                    }
                    let time_s = (t.host_time_ns - start_ns) as f64 * 1e-9;
                    if time_s < a.skip_seconds {
                        return Ok(());
                    }
                    let s = n.state();
                    let p = n.covariance();
                    let block = |i: usize| -> Matrix3<f64> { p.fixed_view::<3, 3>(i, i).into() };
                    let dp = earth::ned_offset(&truth_pos, &s.position);
                    let dv = s.velocity_ned - Vector3::from(t.velocity_ned_m_s);
                    let phi = attitude_error(&s.q_body_to_ned, &truth_q);
                    epochs.push([
                        time_s,
                        nees(&dp, &block(filter::POS)),
                        nees(&dv, &block(filter::VEL)),
                        nees(&phi, &block(filter::ATT)),
                    ]);
                }
                other if session.started() => {
                    if let Some(x) = other.sensor() {
                        let mut solved = false;
                        session.feed(&x, &mut |o| {
                            solved |= matches!(o, SessionOutput::Solution(_));
                            Ok::<(), anyhow::Error>(())
                        })?;
                        if solved {
                            last_imu_ns = Some(x.host_time_ns());
                        }
                    }
                }
                _ => {}
            }
            Ok(())
        })?;
        Ok(NeesRun {
            seconds: summary.duration_s,
            epochs,
        })
    }

    fn report_runs(&self, runs: Vec<NeesRun>, _wall_s: f64) -> Result<NeesReport, StudyError> {
        let a = &self.args;
        if runs.len() != a.runs {
            return Err(StudyError::Results(format!(
                "{} run results for {} runs",
                runs.len(),
                a.runs
            )));
        }
        // Sums over runs per epoch index (in run order): time, position, velocity, attitude NEES.
        let mut sums: Vec<[f64; 4]> = Vec::new();
        let mut counts: Vec<usize> = Vec::new();
        for run in &runs {
            for (epoch, values) in run.epochs.iter().enumerate() {
                if sums.len() <= epoch {
                    sums.push([0.0; 4]);
                    counts.push(0);
                }
                for i in 0..4 {
                    sums[epoch][i] += values[i];
                }
                counts[epoch] += 1;
            }
        }
        let seconds = runs.last().map_or(0.0, |r| r.seconds);
        // Only epochs every run reached.
        let series: Vec<[f64; 4]> = sums
            .iter()
            .zip(&counts)
            .filter(|(_, c)| **c == a.runs)
            .map(|(s, c)| {
                let n = *c as f64;
                [s[0] / n, s[1] / n, s[2] / n, s[3] / n]
            })
            .collect();
        if series.is_empty() {
            return Err(StudyError::Results(
                "no epoch to evaluate (is the run shorter than --skip-seconds?)".into(),
            ));
        }
        let dof = 3.0 * a.runs as f64;
        let lower = chi2_quantile(dof, -1.959_964) / a.runs as f64;
        let upper = chi2_quantile(dof, 1.959_964) / a.runs as f64;
        let block = |i: usize| {
            let n = series.len() as f64;
            let above = series.iter().filter(|s| s[i] > upper).count() as f64 / n;
            let below = series.iter().filter(|s| s[i] < lower).count() as f64 / n;
            NeesBlock {
                mean_anees: series.iter().map(|s| s[i]).sum::<f64>() / n,
                fraction_inside: 1.0 - above - below,
                fraction_above: above,
                fraction_below: below,
            }
        };
        Ok(NeesReport {
            scenario: self.scenario.name.clone(),
            runs: a.runs,
            epochs: series.len(),
            wall_s_per_run: seconds,
            lower_bound: lower,
            upper_bound: upper,
            position: block(1),
            velocity: block(2),
            attitude: block(3),
            series,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_quantiles_match_tables() {
        // Table values, and small degrees of freedom where an approximation would not hold.
        assert!((chi2_quantile(1.0, 1.959_964) - 5.024).abs() < 0.001);
        assert!((chi2_quantile(3.0, -1.959_964) - 0.216).abs() < 0.001);
        assert!((chi2_quantile(3.0, 2.326_348) - 11.345).abs() < 0.001);
        // Tabulated: chi2(150) 2.5 % = 117.98, 97.5 % = 185.80; chi2(30) 2.5 % = 16.79, 97.5 % = 46.98.
        assert!((chi2_quantile(150.0, -1.959_964) - 117.98).abs() < 0.1);
        assert!((chi2_quantile(150.0, 1.959_964) - 185.80).abs() < 0.1);
        assert!((chi2_quantile(30.0, -1.959_964) - 16.79).abs() < 0.1);
        assert!((chi2_quantile(30.0, 1.959_964) - 46.98).abs() < 0.1);
    }
}
