"""auvnav from Python: a vehicle's logs as pandas tables, and the offline tools of the
``auvnav`` command line — replay, smoothing, DVL and magnetometer calibration, model discovery,
simulation, perturbation, imports and Monte Carlo studies — as functions.

Every function calls the same Rust libraries as the command line (``auvnav._native``), and
returns the document ``auvnav <command> --json`` prints, as a dict (the vocabulary of
docs/json.md: units in the names, ``format_version`` first). Keyword options are the command
line's long flags with ``_`` for ``-``: ``calibrate_dvl(*logs, threshold=50, method="fast")`` is
``auvnav calibrate dvl LOGS --threshold 50 --method fast``. ``True`` switches a flag on, a list
repeats a repeatable option, ``None`` leaves the default. ``help(auvnav.discover)`` lists the
options with their defaults.

Errors of the libraries are raised as :class:`AuvnavError` with the library's message; a keyword
the command does not have is a ``TypeError``. Long calls release the GIL.

For many logs or many Monte Carlo runs on a cluster, see :mod:`auvnav.fleet`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Union

from . import _native
from ._native import AuvnavError

if TYPE_CHECKING:
    import pandas as pd

# numpy and pandas are imported by read_log only: a replay or a study from a script or a Dask
# task does not pay for them.

__all__ = [
    "AuvnavError",
    "LogTables",
    "align",
    "align_measured",
    "calibrate_dvl",
    "calibrate_mag",
    "discover",
    "discover_trials",
    "effects",
    "import_mag_csv",
    "import_pd0",
    "import_riversurveyor",
    "import_snapir",
    "import_ugps_g2",
    "nees",
    "options",
    "perturb",
    "read_log",
    "replay",
    "simulate",
    "smooth",
    "usbl",
]

__version__: str = _native.version()

PathLike = Union[str, "os.PathLike[str]"]


def _fspath(p: PathLike) -> str:
    return os.fspath(p)


def _document(text: str) -> dict[str, Any]:
    value: dict[str, Any] = json.loads(text)
    return value


# ---------------------------------------------------------------------------------------------
# Logs as tables


@dataclass
class LogTables(Mapping[str, "pd.DataFrame"]):
    """A log's channels, one :class:`pandas.DataFrame` per topic (``"sensors/imu"``,
    ``"nav/solution"``, ``"truth"``...), one row per message, the unit in every column name
    (``time_s``, ``velocity_north_m_s``, ``roll_rad``). ``time_s`` is the message's host time.
    """

    channels: dict[str, "pd.DataFrame"]
    #: The schema of each channel (``auvnav_msgs/msg/ImuSampleV1``).
    schemas: dict[str, str] = field(default_factory=dict)
    #: Messages on channels of a schema this version does not know (not tabled).
    unknown_messages: int = 0
    #: Messages whose bytes did not match their schema (not tabled).
    bad_messages: int = 0
    #: Why the log ended early (a truncated or damaged tail), or None.
    log_error: str | None = None

    def __getitem__(self, topic: str) -> pd.DataFrame:
        return self.channels[topic]

    def __iter__(self) -> Iterator[str]:
        return iter(self.channels)

    def __len__(self) -> int:
        return len(self.channels)

    def to_arrow(self, topic: str) -> Any:
        """One channel as a ``pyarrow.Table`` (needs pyarrow)."""
        import pyarrow as pa  # noqa: PLC0415 (optional dependency)

        return pa.Table.from_pandas(self.channels[topic], preserve_index=False)


def read_log(path: PathLike) -> LogTables:
    """Reads an auvnav log (MCAP) into one DataFrame per channel.

    A truncated or damaged tail gives the tables read so far and the reason in
    ``log_error``; a file that is not a log raises :class:`AuvnavError`.
    """
    import numpy as np
    import pandas as pd

    tables, info = _native.read_log(_fspath(path))
    channels: dict[str, pd.DataFrame] = {}
    schemas: dict[str, str] = {}
    for topic, (schema, rows, columns) in tables.items():
        data: dict[str, Any] = {}
        for name, kind, values in columns:
            if kind == "f64":
                data[name] = np.frombuffer(values, dtype="<f8")
            elif kind == "u64":
                data[name] = np.frombuffer(values, dtype="<u8")
            else:
                data[name] = values
        frame = pd.DataFrame(data)
        assert len(frame) == rows
        channels[topic] = frame
        schemas[topic] = schema
    return LogTables(
        channels=channels,
        schemas=schemas,
        unknown_messages=info["unknown_messages"],
        bad_messages=info["bad_messages"],
        log_error=info["log_error"],
    )


# ---------------------------------------------------------------------------------------------
# Commands


def options(command: str) -> list[dict[str, Any]]:
    """The keyword options of ``command`` (``"calibrate_dvl"``, ``"discover"``...): name, flag,
    kind (positional, positional_list, switch, value, list), required, default, help."""
    value: list[dict[str, Any]] = json.loads(_native.options(command))
    return value


def _run(command: str, positionals: tuple[Any, ...], opts: dict[str, Any]) -> dict[str, Any]:
    return _document(_native.run(command, list(positionals), opts))


def smooth(*logs: PathLike, **options: Any) -> dict[str, Any]:
    return _run("smooth", logs, options)


def calibrate_dvl(*logs: PathLike, **options: Any) -> dict[str, Any]:
    return _run("calibrate_dvl", logs, options)


def calibrate_mag(*inputs: PathLike, **options: Any) -> dict[str, Any]:
    return _run("calibrate_mag", inputs, options)


def discover(*logs: PathLike, **options: Any) -> dict[str, Any]:
    return _run("discover", logs, options)


def align(**options: Any) -> dict[str, Any]:
    return _run("align", (), options)


def align_measured(dir: PathLike, **options: Any) -> dict[str, Any]:
    return _run("align_measured", (dir,), options)


def usbl(**options: Any) -> dict[str, Any]:
    return _run("usbl", (), options)


def nees(**options: Any) -> dict[str, Any]:
    return _run("nees", (), options)


def discover_trials(**options: Any) -> dict[str, Any]:
    return _run("discover_trials", (), options)


def import_snapir(dir: PathLike, **options: Any) -> dict[str, Any]:
    return _run("import_snapir", (dir,), options)


def import_pd0(*positionals: PathLike, **options: Any) -> dict[str, Any]:
    return _run("import_pd0", positionals, options)


def import_riversurveyor(*positionals: PathLike, **options: Any) -> dict[str, Any]:
    return _run("import_riversurveyor", positionals, options)


def import_mag_csv(*positionals: PathLike, **options: Any) -> dict[str, Any]:
    return _run("import_mag_csv", positionals, options)


def import_ugps_g2(*positionals: PathLike, **options: Any) -> dict[str, Any]:
    return _run("import_ugps_g2", positionals, options)


def _describe(fn: Any, command: str, about: str) -> None:
    lines = [about, "", "Returns the document of ``--json`` as a dict.", "", "Options:"]
    for o in options(command):
        if o["kind"].startswith("positional"):
            head = f"  {o['name']} (positional{', several' if o['kind'] == 'positional_list' else ''})"
        else:
            default = "" if o["default"] is None else f", default {o['default']}"
            head = f"  {o['name']}={{{o['kind']}}}{default}"
        lines.append(head)
        if o["help"]:
            lines.append("      " + " ".join(o["help"].split()))
    fn.__doc__ = "\n".join(lines)


_ABOUT = dict(_native.commands())
for _name in _ABOUT:
    _describe(globals()[_name], _name, _ABOUT[_name])


def replay(
    log: PathLike,
    *,
    config: PathLike | None = None,
    out: PathLike | None = None,
    decimate: int | None = None,
    min_distance: float | None = None,
    usbl: str | None = None,
    compare_recorded: bool = False,
    reference_lever_arm: tuple[float, float, float] | None = None,
) -> dict[str, Any]:
    """Runs a log through the navigation core, as ``auvnav replay --json``.

    config: configuration TOML (``[navigation]``, optional ``[initial]``); default the log's own.
    out: write the solutions and diagnostics (MCAP, or CSV when the name ends in .csv).
    decimate: write every Nth solution (default 1).
    min_distance: distance travelled beyond which points enter the error/distance figure (m,
    default 100).
    usbl: fuse the USBL fixes with this coupling (``"loose"`` or ``"tight"``).
    compare_recorded: compare with the solutions the log recorded on ``nav/solution``.
    reference_lever_arm: where the log's reference sits from the IMU (x, y, z in body axes, m);
    the reference is moved to the IMU before it starts and scores the navigation.
    """
    return _document(
        _native.replay(
            _fspath(log),
            None if config is None else _fspath(config),
            None if out is None else _fspath(out),
            decimate,
            min_distance,
            usbl,
            compare_recorded,
            None if reference_lever_arm is None else tuple(reference_lever_arm),
        )
    )


def simulate(
    scenario: str,
    out: PathLike,
    *,
    effects: Mapping[str, float | list[float]] | None = None,
    seed: int = 1,
    duration: float | None = None,
    clean: bool = False,
) -> dict[str, Any]:
    """Simulates a scenario (built-in name or file) into a log, as ``auvnav sim --json``.

    effects: simulator effects by name (``auvnav.effects()``), in their units, on top of the
    scenario's own (or of ideal sensors with ``clean=True``).
    """
    return _document(
        _native.simulate(scenario, _fspath(out), dict(effects or {}), seed, duration, clean)
    )


def perturb(
    log: PathLike,
    out: PathLike,
    effects: Mapping[str, float | list[float]],
    *,
    seed: int = 1,
) -> dict[str, Any]:
    """Applies named effects to a recorded log's sensor messages, as ``auvnav perturb --json``."""
    return _document(_native.perturb(_fspath(log), _fspath(out), dict(effects), seed))


def effects() -> list[dict[str, Any]]:
    """The effect vocabulary (``auvnav sim --list-effects``): name, unit, components, range,
    default and description of every effect."""
    rows: list[dict[str, Any]] = _document(_native.effects())["rows"]
    return rows
