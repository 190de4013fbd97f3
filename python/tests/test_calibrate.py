"""Calibration from Python: the DVL installation from a simulated voyage, as the command line
gives it, and a magnetometer's hard iron from a recording written with numpy."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

import auvnav


def _strip(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k not in {"wall_s", "full_replays_per_s"}}


def test_a_dvl_installation_from_python_equals_the_command_line(cli, tmp_path):
    log = tmp_path / "voyage.mcap"
    auvnav.simulate("lawnmower", log, duration=1200, seed=4, effects={"dvl.mount_yaw": 1.0})
    py = auvnav.calibrate_dvl(
        log, fixes="truth", threshold=300, write_config=tmp_path / "dvl.toml"
    )
    yaw = next(p for p in py["parameters"] if p["name"] == "dvl.mount_yaw")
    assert yaw["status"] == "estimated"
    assert yaw["value"] == pytest.approx(1.0, abs=0.05)
    assert "[navigation.dvl]" in (tmp_path / "dvl.toml").read_text()
    out = subprocess.run(
        [cli, "calibrate", "dvl", str(log), "--fixes", "truth", "--threshold", "300", "--json"],
        check=True, capture_output=True, text=True,
    )
    sh = json.loads(out.stdout)
    assert _strip(py)["parameters"] == _strip(sh)["parameters"]
    assert _strip(py)["voyages"] == _strip(sh)["voyages"]


def _rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_a_hard_iron_offset_comes_back_from_a_turning_recording(tmp_path):
    field = np.array([20.0, 0.0, 45.0])  # µT, NED
    gravity = np.array([0.0, 0.0, -9.81])  # specific force at rest, NED
    hard_iron = np.array([5.0, -3.0, 2.0])
    rows = ["time_s,mag_x,mag_y,mag_z,acc_x,acc_y,acc_z"]
    for k in range(2000):
        t = k * 0.1
        r = _rotation(0.6 * np.sin(0.011 * t), 0.5 * np.cos(0.007 * t), 0.05 * t)
        h = r.T @ field + hard_iron
        f = r.T @ gravity
        rows.append(f"{t:.1f}," + ",".join(repr(float(x)) for x in [*h, *f]))
    csv = tmp_path / "turns.csv"
    csv.write_text("\n".join(rows) + "\n")
    dip = float(np.degrees(np.arctan2(field[2], field[0])))
    r = auvnav.calibrate_mag(
        csv, field_ut=float(np.linalg.norm(field)), dip_deg=dip, report=tmp_path / "report"
    )
    found = next(e for e in r["effects"] if e["name"] == "mag.hard_iron")
    assert np.allclose(found["value"], hard_iron, atol=0.05), found
    assert (tmp_path / "report").is_dir()
