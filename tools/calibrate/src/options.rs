//! The options of a DVL calibration (`auvnav calibrate dvl`): methods, hold-out, voyages and the
//! searches' settings.

use super::voyage::{FixSource, VoyageSpec};
use std::path::PathBuf;

/// The calibration methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Gauss–Newton with replay sensitivities, priors and an observability test (ours).
    Fast,
    /// Latin hypercube → quadratic response surface → particle swarm (the S-CAL seed).
    Seed,
    /// The seed's two-point formulas on the start and end fixes (yaw and scale only).
    TwoPoint,
    /// The filter's installation states, smoothed over each voyage with its fixes as aids and
    /// fused across the voyages (one shared installation).
    Smoother,
}

/// Hold-out evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Holdout {
    /// Leave-one-voyage-out when there are at least 3 voyages, else none.
    Auto,
    /// Leave each voyage out in turn: fit on the others, score the one left out.
    Loo,
    None,
}

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct CalibrateDvlOptions {
    /// Voyages: logs, or time windows of one as LOG@START..END (seconds from its first message).
    #[cfg_attr(feature = "clap", arg(required = true))]
    pub voyages: Vec<VoyageSpec>,
    /// Where the fixes come from: the GNSS channel, or the truth / reference channel.
    #[cfg_attr(feature = "clap", arg(long, default_value = "gnss"))]
    pub fixes: FixSource,
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = Method::Fast))]
    pub method: Method,
    /// Only fixes at least this far along the track score (m; S-CAL: 5 km).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 5000.0))]
    pub threshold: f64,
    /// Navigation configuration (the daemon's or replay's file: [navigation], [initial]); its
    /// DVL installation is the starting point and the default prior.
    #[cfg_attr(feature = "clap", arg(long))]
    pub config: Option<PathBuf>,
    /// Parameters to estimate, comma-separated (dvl.mount_roll, dvl.mount_pitch, dvl.mount_yaw,
    /// dvl.scale_factor, dvl.lever_arm[.x|.y|.z], dvl.time_offset, dvl.mounting); default: the
    /// seed's four.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub params: Vec<String>,
    /// Bounds of a parameter: NAME=MIN,MAX (repeatable).
    #[cfg_attr(feature = "clap", arg(long = "bound", value_name = "NAME=MIN,MAX", value_parser = auvnav_studies::args::name_and_two_numbers))]
    pub bounds: Vec<String>,
    /// Prior of a parameter: NAME=MEAN,STD (repeatable).
    #[cfg_attr(feature = "clap", arg(long = "prior", value_name = "NAME=MEAN,STD", value_parser = auvnav_studies::args::name_and_two_numbers))]
    pub priors: Vec<String>,
    /// TOML file with one table per parameter: estimate, min, max, prior, prior_std.
    #[cfg_attr(feature = "clap", arg(long))]
    pub limits: Option<PathBuf>,
    /// Seed of the seed method's Latin hypercube and swarm.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Latin-hypercube samples (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 100))]
    pub lhs_samples: usize,
    /// Swarm size (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 20))]
    pub particles: usize,
    /// Swarm iterations at most (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 20))]
    pub iterations: usize,
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = Holdout::Auto))]
    pub holdout: Holdout,
    /// Worker threads (default: the available cores).
    #[cfg_attr(feature = "clap", arg(long))]
    pub threads: Option<usize>,
    /// Print the result as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
    /// Write the calibrated [navigation.dvl] table to this file (atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub write_config: Option<PathBuf>,
    /// Write a report (Markdown, SVG plots, JSON) into this directory.
    #[cfg_attr(feature = "clap", arg(long))]
    pub report: Option<PathBuf>,
    /// Dead-reckon from the attitude channel (a compass or an AHRS) against the GNSS, as for a
    /// surface run, even when the logs carry an IMU (to calibrate the compass's deviation card
    /// with the DVL installation). Logs without an IMU but with a compass are surface runs
    /// without it.
    #[cfg_attr(feature = "clap", arg(long))]
    pub compass: bool,
    /// Surface runs over a bed the current carries (a river): each run's bed velocity (north,
    /// east) is fitted as a nuisance beside the installation, so that the bottom track's lag
    /// behind the GNSS is not taken for a yaw or a scale.
    #[cfg_attr(feature = "clap", arg(long))]
    pub moving_bed: bool,
}

impl CalibrateDvlOptions {
    /// The command's defaults for `voyages` (what the command line gives without options).
    pub fn new(voyages: Vec<VoyageSpec>) -> CalibrateDvlOptions {
        CalibrateDvlOptions {
            voyages,
            fixes: FixSource::Gnss,
            method: Method::Fast,
            threshold: 5000.0,
            config: None,
            params: Vec::new(),
            bounds: Vec::new(),
            priors: Vec::new(),
            limits: None,
            seed: 1,
            lhs_samples: 100,
            particles: 20,
            iterations: 20,
            holdout: Holdout::Auto,
            threads: None,
            json: true,
            write_config: None,
            report: None,
            compass: false,
            moving_bed: false,
        }
    }
}
