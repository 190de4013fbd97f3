"""A log as pandas tables."""

from __future__ import annotations

import numpy as np
import pytest

import auvnav


def test_every_channel_is_a_table_with_units_in_the_column_names(lawnmower, tmp_path):
    summary = auvnav.simulate("lawnmower", tmp_path / "l.mcap", duration=60, seed=5)
    log = auvnav.read_log(tmp_path / "l.mcap")
    assert log.log_error is None and log.bad_messages == 0
    assert len(log["imu"]) == summary["imu"]
    assert len(log["dvl"]) == summary["dvl"]
    assert len(log["truth"]) == summary["truth"]
    truth = log["truth"]
    for column in ["time_s", "latitude_rad", "velocity_north_m_s", "roll_rad", "yaw_rad"]:
        assert column in truth.columns, column
    assert "velocity_dvl_x_m_s" in log["dvl"].columns
    assert log.schemas["imu"] == "auvnav_msgs/msg/ImuSampleV1"
    # time_s is the host time in seconds; the IMU runs at 200 Hz.
    imu = log["imu"]
    assert np.allclose(imu["time_s"], imu["host_time_ns"] * 1e-9)
    assert np.median(np.diff(imu["time_s"])) == pytest.approx(0.005)
    assert imu["host_time_ns"].dtype == np.uint64
    # A level vehicle: specific force down is about -g.
    assert imu["specific_z"].mean() == pytest.approx(-9.8, abs=0.1)


def test_a_truncated_log_gives_what_was_read_and_why(lawnmower, tmp_path):
    data = lawnmower.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    log = auvnav.read_log(cut)
    assert log.log_error is not None
    full = auvnav.read_log(lawnmower)
    assert 0 < len(log["imu"]) < len(full["imu"])


def test_a_file_that_is_not_a_log_is_an_auvnav_error(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a log at all")
    with pytest.raises(auvnav.AuvnavError, match="junk.mcap"):
        auvnav.read_log(junk)
