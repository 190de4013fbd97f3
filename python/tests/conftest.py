"""Fixtures of the Python package's tests: the repository's `auvnav` binary (to compare with the
command line), the measured data beside the checkout, and simulated logs."""

from __future__ import annotations

import os
import pathlib
import shutil

import pytest

import auvnav

REPO = pathlib.Path(__file__).resolve().parents[2]
UNDER_CI = os.environ.get("CI") == "true"


def _missing(what: str) -> None:
    if UNDER_CI:
        pytest.fail(f"{what} is missing (CI=true: a missing input is a failure, not a skip)")
    pytest.skip(f"{what} is missing")


@pytest.fixture(scope="session")
def cli() -> str:
    """The `auvnav` command line built from this checkout (AUVNAV_BIN, else target/debug)."""
    path = os.environ.get("AUVNAV_BIN") or str(REPO / "target" / "debug" / "auvnav")
    if not os.path.exists(path):
        found = shutil.which("auvnav")
        if found is None:
            _missing(f"the auvnav binary ({path}; build it with cargo build -p auvnav-tools)")
        path = str(found)
    return path


@pytest.fixture(scope="session")
def shared_data() -> pathlib.Path:
    path = pathlib.Path(os.environ.get("AUVNAV_SHARED_DATA", REPO.parent / "shared" / "data"))
    if not path.is_dir():
        _missing(f"the measured data ({path})")
    return path


@pytest.fixture(scope="session")
def lawnmower(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Two minutes of the lawnmower scenario."""
    out = tmp_path_factory.mktemp("sim") / "lawnmower.mcap"
    auvnav.simulate("lawnmower", out, duration=120, seed=3)
    return out
