"""A fleet's logs and auvnav's Monte Carlo studies on a Dask cluster.

Why Dask (``dask.distributed``): it is pure Python on top of the interpreter the analysts already
use, starts a local cluster of worker processes in a second (``LocalCluster``) and the same code
runs on a laptop, an HPC allocation (dask-jobqueue) or Kubernetes; the scheduler reschedules the
tasks of a worker that dies, and its dashboard and ``distributed.progress`` show progress. Ray
would also do, but brings its own object store and daemons — a heavy dependency for what is here
a map over logs and a map over run indices.

- :func:`map_logs` applies one operation (``replay``, ``smooth``, ``discover``,
  ``calibrate_dvl``, ...) to each log as a task and gathers the reports into one table.
- :func:`montecarlo` runs a study (``align``, ``usbl``, ``nees``, ``discover_trials``: the
  hidden-effect trials of ``auvnav bench discover``) with every run a task: the run
  index fixes its seed, so the per-run results and the report are those of the single-machine
  runner (``auvnav align --runs N``), bit for bit, whatever the number of workers, and a run lost
  with a killed worker is simply run again.

Example::

    from dask.distributed import Client, LocalCluster
    import auvnav.fleet

    with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
        table = auvnav.fleet.map_logs(client, "replay", logs)
        report = auvnav.fleet.montecarlo(client, "align", runs=220, per_run=True)
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Iterable, Sequence
from typing import Any

import pandas as pd

import auvnav

from . import _native

#: Operations :func:`map_logs` applies to each log (one log per task).
OPERATIONS = ("replay", "smooth", "discover", "calibrate_dvl", "calibrate_mag")


def run_on_log(operation: str, log: str, options: dict[str, Any]) -> dict[str, Any]:
    """One operation on one log (a task's body)."""
    if operation not in OPERATIONS:
        raise ValueError(f"operation {operation!r}: expected one of {', '.join(OPERATIONS)}")
    fn = getattr(auvnav, operation)
    result: dict[str, Any] = fn(log, **options)
    return result


def _key(prefix: str) -> str:
    return f"auvnav-{prefix}-{uuid.uuid4().hex[:12]}"


def map_logs(
    client: Any,
    operation: str,
    logs: Iterable[auvnav.PathLike],
    *,
    options_per_log: Sequence[dict[str, Any]] | None = None,
    progress: bool = False,
    retries: int = 1,
    **options: Any,
) -> pd.DataFrame:
    """Applies ``operation`` to every log, one Dask task per log, and gathers the reports into one
    table: a row per log, its ``path`` first, then the report's fields flattened
    (``accuracy.horizontal_error_final_m``) and the whole report in the ``report`` column. Options
    apply to every log; ``options_per_log`` adds each log's own (an output path, say). A log whose
    operation fails raises its error here.
    """
    paths = [os.fspath(p) for p in logs]
    per_log = list(options_per_log) if options_per_log is not None else [{} for _ in paths]
    if len(per_log) != len(paths):
        raise ValueError(f"{len(per_log)} option sets for {len(paths)} logs")
    prefix = _key(operation)
    futures = [
        client.submit(
            run_on_log,
            operation,
            path,
            {**options, **extra},
            key=f"{prefix}-{k}",
            retries=retries,
            pure=False,
        )
        for k, (path, extra) in enumerate(zip(paths, per_log))
    ]
    if progress:
        from dask.distributed import progress as show

        show(futures)
    reports = client.gather(futures)
    table = pd.json_normalize(reports)
    table.insert(0, "path", paths)
    table["report"] = reports
    return table


def _study_run(study: str, k: int, options: dict[str, Any]) -> bytes:
    run: bytes = _native.study_run(study, k, options)
    return run


def montecarlo(
    client: Any,
    study: str,
    *,
    progress: bool = False,
    retries: int = 1,
    **options: Any,
) -> dict[str, Any]:
    """Runs the Monte Carlo ``study`` (``align``, ``usbl``, ``nees`` or ``discover_trials``; the
    options are the command's, e.g. ``runs=220, seed=1, per_run=True``) with one Dask task per
    run, and returns its report, as ``auvnav.<study>(**options)`` does on one machine.
    ``wall_s`` is the cluster's.
    """
    if study not in _native.studies():
        raise ValueError(f"study {study!r}: expected one of {', '.join(_native.studies())}")
    options = {k: v for k, v in options.items() if v is not None}
    runs = _native.study_runs(study, options)
    start = time.perf_counter()
    prefix = _key(study)
    futures = [
        client.submit(_study_run, study, k, options, key=f"{prefix}-{k}", retries=retries, pure=False)
        for k in range(runs)
    ]
    if progress:
        from dask.distributed import progress as show

        show(futures)
    results = client.gather(futures)
    report: dict[str, Any] = auvnav._document(
        _native.study_report(study, results, time.perf_counter() - start, options)
    )
    return report
