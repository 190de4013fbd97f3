"""The commands from Python give what the command line gives."""

from __future__ import annotations

import json
import subprocess

import pytest

import auvnav

# Fields that measure the machine, not the result.
WALL = {"wall_s", "real_time_factor"}


def _cli_json(cli: str, *args: str) -> dict:
    out = subprocess.run([cli, *args, "--json"], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def _without_wall(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k not in WALL}


def test_replay_equals_the_command_line(cli, lawnmower):
    py = auvnav.replay(lawnmower, min_distance=50)
    sh = _cli_json(cli, "replay", str(lawnmower), "--min-distance", "50")
    assert py["format_version"] == sh["format_version"] == 1
    assert _without_wall(py) == _without_wall(sh)
    assert py["accuracy"]["horizontal_error_final_m"] < 1.0


def test_a_study_equals_the_command_line(cli):
    py = auvnav.align(runs=4, seconds=120, per_run=True, seed=7)
    sh = _cli_json(cli, "align", "--runs", "4", "--seconds", "120", "--per-run", "--seed", "7")
    assert _without_wall(py) == _without_wall(sh)
    assert len(py["per_run"]) == 4 and len(py["per_run"][0]) == 3


def test_keywords_are_the_long_flags_and_unknown_ones_are_type_errors(lawnmower):
    names = {o["name"] for o in auvnav.options("discover")}
    assert {"reference", "effect", "write_config", "fit_fraction"} <= names
    assert "json" not in names
    with pytest.raises(TypeError, match="unexpected keyword argument \"fit_fractoin\""):
        auvnav.discover(lawnmower, fit_fractoin=0.5)
    with pytest.raises(TypeError):
        auvnav.replay(lawnmower, bogus=1)
    assert "reference" in (auvnav.discover.__doc__ or "")


def test_library_errors_are_auvnav_errors_with_the_library_message(tmp_path):
    with pytest.raises(auvnav.AuvnavError, match="--runs must be at least 1"):
        auvnav.align(runs=0)
    with pytest.raises(auvnav.AuvnavError, match="invalid value"):
        auvnav.align(scenario="turning", runs="many")
    with pytest.raises(auvnav.AuvnavError):
        auvnav.replay(tmp_path / "missing.mcap")
    with pytest.raises(auvnav.AuvnavError, match="min_distance -1"):
        auvnav.replay(tmp_path / "missing.mcap", min_distance=-1)
    with pytest.raises(auvnav.AuvnavError, match="unknown effect|dvl.scale_facter"):
        auvnav.simulate("lawnmower", tmp_path / "x.mcap", effects={"dvl.scale_facter": 0.01})


def test_the_effect_vocabulary_is_the_simulators(cli):
    listing = subprocess.run(
        [cli, "sim", "--list-effects"], check=True, capture_output=True, text=True
    ).stdout
    names = [line.split()[0] for line in listing.splitlines() if line and not line.startswith(" ")]
    assert [e["name"] for e in auvnav.effects()] == names
    assert "dvl.scale_factor" in names


def test_an_effect_hidden_with_perturb_is_found_by_discover(tmp_path):
    base = tmp_path / "base.mcap"
    auvnav.simulate("lawnmower", base, duration=600, seed=11, clean=True)
    hidden = tmp_path / "hidden.mcap"
    done = auvnav.perturb(base, hidden, {"dvl.scale_factor": 1.02}, seed=2)
    assert done["counts"]["dvl_changed"] > 0
    report = auvnav.discover(hidden, write_config=tmp_path / "found.toml")
    found = {e["name"]: e["value"] for e in report["effects"]}
    assert "dvl.scale_factor" in found, report["effects"]
    assert found["dvl.scale_factor"] == pytest.approx(1.02, abs=0.002)
    assert (tmp_path / "found.toml").exists()


def test_smoothing_a_log_reports_forward_and_smoothed(lawnmower, tmp_path):
    r = auvnav.smooth(lawnmower, out=tmp_path / "smoothed.csv")
    assert r["format_version"] == 1
    assert (tmp_path / "smoothed.csv").exists()


def test_a_snapir_segment_imports_and_replays(shared_data, tmp_path):
    out = tmp_path / "seg1.mcap"
    s = auvnav.import_snapir(shared_data / "snapir-auv", segment=1, out=out)
    assert s["imu"]["rows"] == 40000
    log = auvnav.read_log(out)
    assert {"imu", "dvl", "truth"} <= set(log)
    r = auvnav.replay(out)
    assert r["accuracy"]["distance_travelled_m"] > 100
