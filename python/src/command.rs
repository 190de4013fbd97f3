//! The commands Python calls by name, with keyword options that are the command line's: each
//! command's option struct is the library's (with its `clap` feature), so the names, defaults,
//! accepted values and error messages are those of `auvnav <command> --help`. A Python keyword
//! `min_distance=50` is the flag `--min-distance 50`; `True` switches a flag on; a list repeats
//! a repeatable option. Results are the versioned JSON documents of `--json` (docs/json.md).

use anyhow::Context;
use auvnav_studies::runs::{RunStudy, decode_run, encode_run};
use clap::{ArgAction, Args, FromArgMatches};
use serde::Serialize;

/// A value given for an option, already in the command line's text form.
#[derive(Debug, Clone)]
pub enum OptionValue {
    /// A switch (`--flag`) on or off.
    Switch(bool),
    /// One value.
    One(String),
    /// A repeatable option's values.
    Many(Vec<String>),
}

/// How an option is given.
#[derive(Debug, Clone, Serialize)]
pub struct OptionInfo {
    /// The Python keyword (the long flag with `_` for `-`), or the positional's name.
    pub name: String,
    /// `--long-flag`, absent for positionals.
    pub flag: Option<String>,
    /// positional, positional_list, switch, value or list.
    pub kind: &'static str,
    pub required: bool,
    /// The command line's default, as text.
    pub default: Option<String>,
    pub help: String,
}

/// A command: its name, its clap definition and how it runs.
struct Spec {
    name: &'static str,
    about: &'static str,
    command: fn() -> clap::Command,
    run: fn(&clap::ArgMatches) -> anyhow::Result<String>,
}

fn definition<T: Args>(name: &'static str) -> clap::Command {
    T::augment_args(clap::Command::new(name).no_binary_name(true))
}

fn parsed<T: FromArgMatches>(m: &clap::ArgMatches) -> anyhow::Result<T> {
    T::from_arg_matches(m).map_err(|e| anyhow::anyhow!("{}", e.render()))
}

fn document<T: Serialize>(value: &T) -> anyhow::Result<String> {
    Ok(auvnav_replay::json::to_string_pretty(value)?)
}

macro_rules! spec {
    ($name:literal, $about:literal, $args:ty, |$a:ident| $body:expr) => {
        Spec {
            name: $name,
            about: $about,
            command: || definition::<$args>($name),
            run: |m| {
                let $a: $args = parsed(m)?;
                $body
            },
        }
    };
}

fn specs() -> Vec<Spec> {
    use auvnav_calibrate::CalibrateDvlOptions;
    use auvnav_calibrate::mag::CalibrateMagOptions;
    use auvnav_discover::command::DiscoverOptions;
    use auvnav_import::{
        MagCsvOptions, Pd0Options, RiverSurveyorOptions, SnapirOptions, UgpsOptions,
    };
    use auvnav_smooth::SmoothOptions;
    use auvnav_studies::align::{AlignMeasuredOptions, AlignOptions};
    use auvnav_studies::nees::NeesOptions;
    use auvnav_studies::usbl::UsblOptions;
    vec![
        spec!(
            "smooth",
            "auvnav smooth: forward-backward smoothing of logs",
            SmoothOptions,
            |a| document(&auvnav_smooth::run(&a)?)
        ),
        spec!(
            "calibrate_dvl",
            "auvnav calibrate dvl: S-CAL DVL installation",
            CalibrateDvlOptions,
            |a| document(&auvnav_calibrate::calibrate_dvl(&a)?)
        ),
        spec!(
            "calibrate_mag",
            "auvnav calibrate mag: magnetometer hard and soft iron",
            CalibrateMagOptions,
            |a| document(&auvnav_calibrate::mag::run(&a)?)
        ),
        spec!(
            "discover",
            "auvnav discover: model discovery",
            DiscoverOptions,
            |a| document(&auvnav_discover::command::run(&a)?)
        ),
        spec!(
            "align",
            "auvnav align: fine-alignment Monte Carlo",
            AlignOptions,
            |a| document(&auvnav_studies::align::run(&a)?)
        ),
        spec!(
            "align_measured",
            "auvnav align-measured: fine alignment on the Snapir segments",
            AlignMeasuredOptions,
            |a| document(&auvnav_studies::align::measured_rows(&a)?)
        ),
        spec!(
            "usbl",
            "auvnav usbl: S-USBL Monte Carlo",
            UsblOptions,
            |a| {
                if a.table {
                    document(&auvnav_studies::usbl::run_table(&a)?)
                } else {
                    document(&auvnav_studies::usbl::run(&a)?)
                }
            }
        ),
        spec!(
            "nees",
            "auvnav montecarlo nees: filter consistency",
            NeesOptions,
            |a| {
                let cfg = auvnav_replay::load_navigation(a.config.as_deref())?;
                let r = auvnav_studies::nees::nees_monte_carlo(&a, &cfg)?;
                if let Some(p) = &a.series {
                    auvnav_studies::nees::write_series(p, &r)?;
                }
                document(&r)
            }
        ),
        spec!(
            "discover_trials",
            "auvnav bench discover's hidden-effect and null trials",
            auvnav_discover::trials::TrialsOptions,
            |a| {
                let study = auvnav_discover::trials::TrialsStudy::new(&a)?;
                let threads = auvnav_studies::parallel::default_threads();
                let bar = auvnav_studies::progress::Progress::new(true)
                    .runs("discovery trials", study.runs());
                document(&auvnav_studies::runs::run_local(&study, threads, &bar)?)
            }
        ),
        spec!(
            "import_snapir",
            "auvnav import snapir: a Snapir segment into a log",
            SnapirOptions,
            |a| document(&auvnav_import::snapir(&a)?)
        ),
        spec!(
            "import_pd0",
            "auvnav import pd0: a PD0 file with GPS into a log",
            Pd0Options,
            |a| document(&auvnav_import::pd0(&a)?)
        ),
        spec!(
            "import_riversurveyor",
            "auvnav import riversurveyor: a SonTek RiverSurveyor MATLAB export into a log",
            RiverSurveyorOptions,
            |a| document(&auvnav_import::riversurveyor(&a)?)
        ),
        spec!(
            "import_mag_csv",
            "auvnav import mag-csv: a magnetometer CSV into a log",
            MagCsvOptions,
            |a| document(&auvnav_import::mag_csv(&a)?)
        ),
        spec!(
            "import_ugps_g2",
            "auvnav import ugps-g2: a UGPS G2 acoustic log into a log",
            UgpsOptions,
            |a| document(&auvnav_import::ugps(&a)?)
        ),
    ]
}

fn find(name: &str) -> anyhow::Result<Spec> {
    let all = specs();
    let names: Vec<&str> = all.iter().map(|s| s.name).collect();
    let joined = names.join(", ");
    all.into_iter()
        .find(|s| s.name == name)
        .with_context(|| format!("no command {name:?} (commands: {joined})"))
}

/// The commands, with one line each.
pub fn commands() -> Vec<(&'static str, &'static str)> {
    specs().iter().map(|s| (s.name, s.about)).collect()
}

/// Options the Python layer does not offer: `--json` (results are always the JSON document).
const NOT_OFFERED: [&str; 2] = ["json", "help"];

fn python_name(arg: &clap::Arg) -> String {
    match arg.get_long() {
        Some(l) => l.replace('-', "_"),
        None => arg.get_id().to_string(),
    }
}

fn is_switch(arg: &clap::Arg) -> bool {
    matches!(arg.get_action(), ArgAction::SetTrue)
}

fn is_list(arg: &clap::Arg) -> bool {
    matches!(arg.get_action(), ArgAction::Append)
        || arg.get_num_args().is_some_and(|n| n.max_values() > 1)
}

/// The options of `command`, in the command line's order.
pub fn options(command: &str) -> anyhow::Result<Vec<OptionInfo>> {
    let spec = find(command)?;
    let cmd = (spec.command)();
    Ok(cmd
        .get_arguments()
        .filter(|a| !NOT_OFFERED.contains(&a.get_id().as_str()) && !a.is_hide_set())
        .map(|a| {
            let positional = a.is_positional();
            let kind = match (positional, is_switch(a), is_list(a)) {
                (true, _, true) => "positional_list",
                (true, _, false) => "positional",
                (false, true, _) => "switch",
                (false, false, true) => "list",
                (false, false, false) => "value",
            };
            let default: Vec<String> = a
                .get_default_values()
                .iter()
                .map(|v| v.to_string_lossy().into_owned())
                .collect();
            OptionInfo {
                name: python_name(a),
                flag: a.get_long().map(|l| format!("--{l}")),
                kind,
                required: a.is_required_set(),
                default: (!default.is_empty() && kind != "switch").then(|| default.join(",")),
                help: {
                    let mut help = a
                        .get_long_help()
                        .or(a.get_help())
                        .map(|h| h.to_string())
                        .unwrap_or_default();
                    let values: Vec<String> = a
                        .get_possible_values()
                        .iter()
                        .filter(|v| !v.is_hide_set())
                        .map(|v| v.get_name().to_string())
                        .collect();
                    if !values.is_empty() && kind != "switch" {
                        help = format!("{help} (one of: {})", values.join(", "))
                            .trim_start()
                            .to_string();
                    }
                    help
                },
            }
        })
        .collect())
}

/// The command line of `command` from positionals and keyword options; an unknown keyword or a
/// value of the wrong shape is an error naming the command's options.
fn argv(
    command: &str,
    positionals: &[String],
    options_given: &[(String, OptionValue)],
) -> anyhow::Result<(Spec, clap::ArgMatches)> {
    let spec = find(command)?;
    let cmd = (spec.command)();
    let mut args: Vec<String> = Vec::new();
    for (key, value) in options_given {
        let arg = cmd
            .get_arguments()
            .find(|a| {
                !a.is_positional()
                    && !NOT_OFFERED.contains(&a.get_id().as_str())
                    && python_name(a) == *key
            })
            .with_context(|| {
                let names: Vec<String> = options(command)
                    .unwrap_or_default()
                    .into_iter()
                    .filter(|o| o.flag.is_some())
                    .map(|o| o.name)
                    .collect();
                format!(
                    "{command}() got an unexpected keyword argument {key:?} (options: {})",
                    names.join(", ")
                )
            })?;
        let flag = format!("--{}", arg.get_long().unwrap_or(key));
        match (value, is_switch(arg), is_list(arg)) {
            (OptionValue::Switch(true), true, _) => args.push(flag),
            (OptionValue::Switch(false), true, _) => {}
            (_, true, _) => anyhow::bail!("{command}(): {key} is a switch: give True or False"),
            (OptionValue::Many(vs), false, true) => {
                for v in vs {
                    args.push(format!("{flag}={v}"));
                }
            }
            (OptionValue::Many(_), false, false) => {
                anyhow::bail!("{command}(): {key} takes one value, not a list")
            }
            (OptionValue::One(v), false, _) => args.push(format!("{flag}={v}")),
            (OptionValue::Switch(b), false, _) => args.push(format!("{flag}={b}")),
        }
    }
    args.push("--".into());
    args.extend(positionals.iter().cloned());
    let matches = cmd
        .try_get_matches_from(&args)
        .map_err(|e| anyhow::anyhow!("{command}(): {}", e.render().to_string().trim()))?;
    Ok((spec, matches))
}

/// Runs `command` and returns its JSON document.
pub fn run(
    command: &str,
    positionals: &[String],
    options_given: &[(String, OptionValue)],
) -> anyhow::Result<String> {
    let (spec, matches) = argv(command, positionals, options_given)?;
    (spec.run)(&matches)
}

/// A Monte Carlo study built from its command's options.
enum Study {
    Align(Box<auvnav_studies::align::AlignStudy>),
    Usbl(Box<auvnav_studies::usbl::UsblStudy>),
    Nees(Box<auvnav_studies::nees::NeesStudy>),
    Trials(auvnav_discover::trials::TrialsStudy),
}

fn study(name: &str, options_given: &[(String, OptionValue)]) -> anyhow::Result<Study> {
    let (_, m) = argv(name, &[], options_given)?;
    Ok(match name {
        "align" => Study::Align(Box::new(auvnav_studies::align::AlignStudy::new(&parsed(
            &m,
        )?)?)),
        "usbl" => {
            let a: auvnav_studies::usbl::UsblOptions = parsed(&m)?;
            anyhow::ensure!(!a.table, "usbl(table=True) is eighteen studies, not one");
            Study::Usbl(Box::new(auvnav_studies::usbl::UsblStudy::new(&a)?))
        }
        "nees" => {
            let a: auvnav_studies::nees::NeesOptions = parsed(&m)?;
            let cfg = auvnav_replay::load_navigation(a.config.as_deref())?;
            Study::Nees(Box::new(auvnav_studies::nees::NeesStudy::new(
                &a, &cfg, &cfg,
            )?))
        }
        "discover_trials" => {
            Study::Trials(auvnav_discover::trials::TrialsStudy::new(&parsed(&m)?)?)
        }
        _ => anyhow::bail!(
            "{name:?} is not a study of independent runs ({})",
            STUDIES.join(", ")
        ),
    })
}

/// The studies whose runs can be spread over a cluster.
pub const STUDIES: [&str; 4] = ["align", "usbl", "nees", "discover_trials"];

/// How many runs the study's options ask for (and a check of the options).
pub fn study_runs(name: &str, options_given: &[(String, OptionValue)]) -> anyhow::Result<usize> {
    Ok(match study(name, options_given)? {
        Study::Align(s) => s.runs(),
        Study::Usbl(s) => s.runs(),
        Study::Nees(s) => s.runs(),
        Study::Trials(s) => s.runs(),
    })
}

/// Run `k` of the study, as bytes.
pub fn study_run(
    name: &str,
    options_given: &[(String, OptionValue)],
    k: usize,
) -> anyhow::Result<Vec<u8>> {
    fn one<S: RunStudy>(s: &S, k: usize) -> anyhow::Result<Vec<u8>> {
        anyhow::ensure!(k < s.runs(), "run {k} of a study of {} runs", s.runs());
        Ok(encode_run(&s.run(k)?)?)
    }
    match study(name, options_given)? {
        Study::Align(s) => one(s.as_ref(), k),
        Study::Usbl(s) => one(s.as_ref(), k),
        Study::Nees(s) => one(s.as_ref(), k),
        Study::Trials(s) => one(&s, k),
    }
}

/// The study's report (JSON) from every run's bytes, in index order.
pub fn study_report(
    name: &str,
    options_given: &[(String, OptionValue)],
    runs: &[Vec<u8>],
    wall_s: f64,
) -> anyhow::Result<String> {
    fn report<S: RunStudy>(s: &S, runs: &[Vec<u8>], wall_s: f64) -> anyhow::Result<String> {
        let runs = runs
            .iter()
            .map(|b| decode_run(b))
            .collect::<Result<Vec<S::Run>, auvnav_studies::StudyError>>()?;
        document(&s.report(runs, wall_s)?)
    }
    match study(name, options_given)? {
        Study::Align(s) => report(s.as_ref(), runs, wall_s),
        Study::Usbl(s) => report(s.as_ref(), runs, wall_s),
        Study::Nees(s) => report(s.as_ref(), runs, wall_s),
        Study::Trials(s) => report(&s, runs, wall_s),
    }
}
