"""The fleet module on a local Dask cluster of worker processes on loopback."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time

import pytest

import auvnav
import auvnav.fleet

distributed = pytest.importorskip("dask.distributed")


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _without_wall(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k != "wall_s"}


def test_a_distributed_alignment_study_equals_the_command_line_run_for_run(cli, client):
    runs, seconds, seed = 12, 300, 41
    distributed_report = auvnav.fleet.montecarlo(
        client, "align", runs=runs, seconds=seconds, seed=seed, per_run=True
    )
    out = subprocess.run(
        [cli, "align", "--runs", str(runs), "--seconds", str(seconds), "--seed", str(seed),
         "--per-run", "--json"],
        check=True, capture_output=True, text=True,
    )
    single = json.loads(out.stdout)
    assert distributed_report["per_run"] == single["per_run"]
    assert _without_wall(distributed_report) == _without_wall(single)


@pytest.mark.parametrize(
    "study,options",
    [
        ("usbl", {"runs": 3, "seconds": 150, "settle_s": 30, "seed": 5}),
        ("nees", {"runs": 3, "seconds": 60, "seed": 9}),
        ("discover_trials", {"hidden": 2, "null": 1, "per_run": True}),
    ],
)
def test_the_other_studies_equal_the_single_process_runner(client, study, options):
    distributed_report = auvnav.fleet.montecarlo(client, study, **options)
    single = getattr(auvnav, study)(**options)
    assert _without_wall(distributed_report) == _without_wall(single)


def test_a_worker_killed_mid_study_is_replaced_and_the_result_is_unchanged(client):
    options = {"runs": 24, "seconds": 1200, "seed": 301, "per_run": True}
    expected = auvnav.align(**options)
    result: dict = {}

    def study() -> None:
        result["report"] = auvnav.fleet.montecarlo(client, "align", **options)

    thread = threading.Thread(target=study)
    thread.start()
    # Wait until a worker is running a run of the study, then kill its process.
    victim = None
    deadline = time.monotonic() + 120
    while victim is None and time.monotonic() < deadline:
        busy = {w: keys for w, keys in client.processing().items() if keys}
        if busy:
            victim = next(iter(busy))
        else:
            time.sleep(0.01)
    assert victim is not None, "no run was ever processing"
    pids = client.run(os.getpid, workers=[victim])
    os.kill(pids[victim], signal.SIGKILL)
    thread.join(timeout=600)
    assert not thread.is_alive(), "the study did not finish after a worker was killed"
    assert victim not in client.scheduler_info()["workers"]
    report = result["report"]
    assert report["per_run"] == expected["per_run"]
    assert _without_wall(report) == _without_wall(expected)


def test_replaying_many_logs_gathers_one_row_per_log(client, tmp_path):
    logs = []
    for seed in (1, 2, 3):
        path = tmp_path / f"voyage_{seed}.mcap"
        auvnav.simulate("lawnmower", path, duration=90, seed=seed)
        logs.append(path)
    table = auvnav.fleet.map_logs(client, "replay", logs, min_distance=20)
    assert list(table["path"]) == [str(p) for p in logs]
    for path, row in zip(logs, table.itertuples()):
        alone = auvnav.replay(path, min_distance=20)
        assert row.report["accuracy"] == alone["accuracy"]
    assert "accuracy.horizontal_error_final_m" in table.columns
    with pytest.raises(ValueError, match="operation"):
        auvnav.fleet.map_logs(client, "rm -rf", logs)
