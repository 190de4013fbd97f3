//! `auvnav._native`: the Python package's native module. It is thin on purpose: every function
//! calls a library crate (replay, smooth, calibrate, discover, studies, import, sim, log) and
//! returns what the command line would print with `--json` (the versioned documents of
//! docs/json.md) or, for a log's tables, columns as little-endian bytes that numpy reads without a
//! copy per value. The Python layer (`python/auvnav`) turns them into dicts and DataFrames.
//!
//! Long calls release the GIL, so threads and a Dask worker's other tasks run meanwhile. Library
//! errors become `auvnav.AuvnavError` with the library's message; a keyword the command does not
//! have is a `TypeError`.

#![forbid(unsafe_code)]

mod command;

use command::OptionValue;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyList, PyTuple};
use std::path::PathBuf;

create_exception!(
    auvnav,
    AuvnavError,
    PyException,
    "An error of an auvnav library: a log that cannot be read, options out of range, a failed calibration. The message is the library's."
);

fn error(e: anyhow::Error) -> PyErr {
    let text = format!("{e:#}");
    if text.contains("got an unexpected keyword argument") {
        PyTypeError::new_err(text)
    } else {
        AuvnavError::new_err(text)
    }
}

/// A Python value as an option's text: `True`/`False` as a switch, a list or tuple as a
/// repeatable option's values, anything else (numbers, strings, paths) by `str()`.
fn option_value(value: &Bound<'_, PyAny>) -> PyResult<Option<OptionValue>> {
    if value.is_none() {
        return Ok(None);
    }
    if let Ok(b) = value.cast::<PyBool>() {
        return Ok(Some(OptionValue::Switch(b.is_true())));
    }
    let text = |v: &Bound<'_, PyAny>| -> PyResult<String> {
        let s = v
            .call_method0("__fspath__")
            .or_else(|_| v.str().map(|s| s.into_any()))?;
        s.extract::<String>()
    };
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for v in value.try_iter()? {
            out.push(text(&v?)?);
        }
        return Ok(Some(OptionValue::Many(out)));
    }
    Ok(Some(OptionValue::One(text(value)?)))
}

fn options_of(options: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, OptionValue)>> {
    let mut out = Vec::new();
    if let Some(d) = options {
        for (k, v) in d.iter() {
            if let Some(v) = option_value(&v)? {
                out.push((k.extract::<String>()?, v));
            }
        }
    }
    Ok(out)
}

fn texts(values: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
    match option_value(values)? {
        None => Ok(Vec::new()),
        Some(OptionValue::Many(v)) => Ok(v),
        Some(OptionValue::One(v)) => Ok(vec![v]),
        Some(OptionValue::Switch(_)) => Err(PyTypeError::new_err("a positional cannot be a bool")),
    }
}

/// The auvnav version this module was built from.
#[pyfunction]
fn version() -> String {
    auvnav_version::VERSION.to_string()
}

/// The commands `run` knows, as (name, one line) pairs.
#[pyfunction]
fn commands() -> Vec<(&'static str, &'static str)> {
    command::commands()
}

/// The options of a command, as JSON: name, flag, kind, required, default, help.
#[pyfunction]
fn options(command: &str) -> PyResult<String> {
    let o = command::options(command).map_err(error)?;
    serde_json::to_string(&o).map_err(|e| error(e.into()))
}

/// Runs a command with positionals and keyword options; its JSON document.
#[pyfunction]
#[pyo3(signature = (command, positionals, options=None))]
fn run(
    py: Python<'_>,
    command: &str,
    positionals: &Bound<'_, PyAny>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let positionals = texts(positionals)?;
    let options = options_of(options)?;
    py.detach(|| command::run(command, &positionals, &options))
        .map_err(error)
}

/// The studies whose runs can be spread over workers.
#[pyfunction]
fn studies() -> Vec<&'static str> {
    command::STUDIES.to_vec()
}

/// How many runs the study's options ask for (checks the options).
#[pyfunction]
#[pyo3(signature = (study, options=None))]
fn study_runs(study: &str, options: Option<&Bound<'_, PyDict>>) -> PyResult<usize> {
    let options = options_of(options)?;
    command::study_runs(study, &options).map_err(error)
}

/// Run `k` of the study (0-based), as bytes for `study_report`.
#[pyfunction]
#[pyo3(signature = (study, k, options=None))]
fn study_run<'py>(
    py: Python<'py>,
    study: &str,
    k: usize,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyBytes>> {
    let options = options_of(options)?;
    let bytes = py
        .detach(|| command::study_run(study, &options, k))
        .map_err(error)?;
    Ok(PyBytes::new(py, &bytes))
}

/// The study's report (JSON) from every run's bytes in index order.
#[pyfunction]
#[pyo3(signature = (study, runs, wall_s, options=None))]
fn study_report(
    py: Python<'_>,
    study: &str,
    runs: Vec<Vec<u8>>,
    wall_s: f64,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let options = options_of(options)?;
    py.detach(|| command::study_report(study, &options, &runs, wall_s))
        .map_err(error)
}

/// Replays a log through the navigation core (`auvnav replay`); its JSON report.
#[pyfunction]
#[pyo3(signature = (log, config=None, out=None, decimate=None, min_distance=None, usbl=None, compare_recorded=false, reference_lever_arm=None))]
#[allow(clippy::too_many_arguments)]
fn replay(
    py: Python<'_>,
    log: PathBuf,
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    decimate: Option<u64>,
    min_distance: Option<f64>,
    usbl: Option<String>,
    compare_recorded: bool,
    reference_lever_arm: Option<[f64; 3]>,
) -> PyResult<String> {
    let mut o = auvnav_replay::ReplayOptions::new(log);
    o.reference_lever_arm = reference_lever_arm;
    o.config = config;
    o.out = out;
    o.decimate = decimate.unwrap_or(o.decimate);
    o.min_distance = min_distance.unwrap_or(o.min_distance);
    o.compare_recorded = compare_recorded;
    if let Some(u) = usbl {
        o.usbl = Some(u.parse().map_err(|e: String| AuvnavError::new_err(e))?);
    }
    py.detach(|| -> anyhow::Result<String> {
        let r = auvnav_replay::replay(&o)?;
        Ok(auvnav_replay::json::to_string_pretty(&r)?)
    })
    .map_err(error)
}

fn effect_settings(effects: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, Vec<f64>)>> {
    let mut out = Vec::new();
    if let Some(d) = effects {
        for (k, v) in d.iter() {
            let name: String = k.extract()?;
            let values: Vec<f64> = match v.extract::<f64>() {
                Ok(x) => vec![x],
                Err(_) => v.extract()?,
            };
            out.push((name, values));
        }
    }
    Ok(out)
}

/// Simulates a scenario into a log (`auvnav sim`); the run summary as JSON.
#[pyfunction]
#[pyo3(signature = (scenario, out, effects=None, seed=1, duration=None, clean=false))]
fn simulate(
    py: Python<'_>,
    scenario: &str,
    out: PathBuf,
    effects: Option<&Bound<'_, PyDict>>,
    seed: u64,
    duration: Option<f64>,
    clean: bool,
) -> PyResult<String> {
    let settings = effect_settings(effects)?;
    let scenario = scenario.to_string();
    py.detach(move || -> anyhow::Result<String> {
        let scenario = auvnav_sim::scenario::Scenario::load(&scenario)?;
        let mut fx = if clean {
            auvnav_sim::effects::Effects::default()
        } else {
            scenario.effects()?
        };
        for (name, values) in &settings {
            fx.set(name, values)?;
        }
        if let Some(d) = duration {
            anyhow::ensure!(
                d.is_finite() && d > 0.0 && d <= 1.0e6,
                "duration {d}: allowed range is 0 < duration <= 1e6 s"
            );
        }
        let cfg = auvnav_sim::SimConfig {
            scenario,
            effects: fx,
            seed,
            duration_s: duration,
        };
        let summary = auvnav_sim::simulate_to_log(&cfg, &out)?;
        Ok(auvnav_replay::json::to_string_pretty(&summary)?)
    })
    .map_err(error)
}

/// Applies named effects to a recorded log's sensor messages (`auvnav perturb`); JSON.
#[pyfunction]
#[pyo3(signature = (log, out, effects, seed=1))]
fn perturb(
    py: Python<'_>,
    log: PathBuf,
    out: PathBuf,
    effects: &Bound<'_, PyDict>,
    seed: u64,
) -> PyResult<String> {
    let settings: Vec<String> = effect_settings(Some(effects))?
        .into_iter()
        .map(|(name, v)| {
            let v: Vec<String> = v.iter().map(|x| x.to_string()).collect();
            format!("{name}={}", v.join(","))
        })
        .collect();
    py.detach(move || -> anyhow::Result<String> {
        let p = auvnav_sim::perturb::Perturbation::parse(&settings, seed)?;
        let counts = auvnav_sim::perturb::perturb_log(&log, &out, &p)?;
        Ok(auvnav_replay::json::to_string_pretty(&serde_json::json!({
            "input": log,
            "output": out,
            "effects": p.describe(),
            "seed": seed,
            "counts": counts,
        }))?)
    })
    .map_err(error)
}

/// The effect vocabulary (`auvnav sim --list-effects`) as JSON rows: name, unit, components,
/// range, default, description.
#[pyfunction]
fn effects() -> PyResult<String> {
    let rows: Vec<serde_json::Value> = auvnav_sim::effects::SPECS
        .iter()
        .map(|s| {
            serde_json::json!({
                "name": s.name,
                "unit": s.unit,
                "components": s.components,
                "min": s.min,
                "max": s.max,
                "default": s.default,
                "description": s.doc.trim(),
            })
        })
        .collect();
    auvnav_replay::json::to_string_pretty(&rows).map_err(|e| error(e.into()))
}

/// A log's channels as tables: `({topic: (schema, rows, [(column, kind, values)])}, info)`,
/// kind `f64` or `u64` with little-endian bytes, or `text` with a list of str.
#[pyfunction]
fn read_log<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
    use auvnav_log::table::ColumnValues;
    let tables = py
        .detach(|| auvnav_log::table::read_tables(&path))
        .map_err(|e| AuvnavError::new_err(format!("{}: {e}", path.display())))?;
    let out = PyDict::new(py);
    for (topic, t) in &tables.tables {
        let columns = PyList::empty(py);
        for c in &t.columns {
            let item: Bound<'py, PyTuple> = match &c.values {
                ColumnValues::F64(v) => {
                    let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
                    (c.name.as_str(), "f64", PyBytes::new(py, &b)).into_pyobject(py)?
                }
                ColumnValues::U64(v) => {
                    let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
                    (c.name.as_str(), "u64", PyBytes::new(py, &b)).into_pyobject(py)?
                }
                ColumnValues::Text(v) => {
                    (c.name.as_str(), "text", PyList::new(py, v)?).into_pyobject(py)?
                }
            };
            columns.append(item)?;
        }
        out.set_item(topic, (t.schema.as_str(), t.rows, columns))?;
    }
    let info = PyDict::new(py);
    info.set_item("unknown_messages", tables.unknown_messages)?;
    info.set_item("bad_messages", tables.bad_messages)?;
    info.set_item("log_error", tables.log_error)?;
    Ok((out, info))
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("AuvnavError", m.py().get_type::<AuvnavError>())?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(commands, m)?)?;
    m.add_function(wrap_pyfunction!(options, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(studies, m)?)?;
    m.add_function(wrap_pyfunction!(study_runs, m)?)?;
    m.add_function(wrap_pyfunction!(study_run, m)?)?;
    m.add_function(wrap_pyfunction!(study_report, m)?)?;
    m.add_function(wrap_pyfunction!(replay, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(perturb, m)?)?;
    m.add_function(wrap_pyfunction!(effects, m)?)?;
    m.add_function(wrap_pyfunction!(read_log, m)?)?;
    Ok(())
}
