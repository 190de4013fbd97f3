"""What the Python layer and the cluster cost (a benchmark, not a test: docs/python.md).

    python overhead.py --cli target/release/auvnav --snapir ../shared/data/snapir-auv \
        --work /tmp/auvnav-bench [--repeat 5] [--align-runs 220]

1. Replay of an hour-long log: ``auvnav replay LOG --json`` against
   ``python -c "import auvnav; auvnav.replay(LOG)"``, whole processes, median of --repeat.
2. Discovery of the 13 Snapir segments: one after the other in one process against
   ``auvnav.fleet.map_logs(client, "discover", logs)`` on a local cluster of 2 worker processes
   (the cluster's start is reported apart).
3. The alignment Monte Carlo (--align-runs) on 2 workers against ``auvnav align --runs N
   --per-run --json``: wall times, and whether every run's result is identical.
Prints a JSON document.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import time

import auvnav
import auvnav.fleet


def timed(cmd: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - start


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cli", required=True, help="the auvnav binary (release build)")
    p.add_argument("--snapir", required=True, help="the Snapir data set directory")
    p.add_argument("--work", default="/tmp/auvnav-bench", help="scratch directory")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--align-runs", type=int, default=220)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()
    work = pathlib.Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    result: dict = {"format_version": 1}

    hour = work / "hour.mcap"
    if not hour.exists():
        auvnav.simulate("lawnmower", hour, duration=3600, seed=1)
    cli = [timed([a.cli, "replay", str(hour), "--json"]) for _ in range(a.repeat)]
    code = f"import auvnav; auvnav.replay({str(hour)!r})"
    py = [timed([sys.executable, "-c", code]) for _ in range(a.repeat)]
    result["replay_hour"] = {
        "cli_median_s": statistics.median(cli),
        "python_median_s": statistics.median(py),
        "python_over_cli": statistics.median(py) / statistics.median(cli),
    }
    print(json.dumps(result["replay_hour"]), file=sys.stderr)

    from dask.distributed import Client, LocalCluster

    logs = []
    for s in range(1, 14):
        log = work / f"segment_{s:02}.mcap"
        if not log.exists():
            auvnav.import_snapir(a.snapir, segment=s, out=log)
        logs.append(log)
    start = time.perf_counter()
    alone = [auvnav.discover(log) for log in logs]
    one_process = time.perf_counter() - start
    start = time.perf_counter()
    cluster = LocalCluster(
        n_workers=a.workers, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    )
    client = Client(cluster)
    client.wait_for_workers(a.workers)
    cluster_start = time.perf_counter() - start
    start = time.perf_counter()
    table = auvnav.fleet.map_logs(client, "discover", logs)
    on_cluster = time.perf_counter() - start
    same = [r["effects"] for r in table["report"]] == [r["effects"] for r in alone]
    result["discover_13_segments"] = {
        "one_process_s": one_process,
        "cluster_s": on_cluster,
        "cluster_start_s": cluster_start,
        "workers": a.workers,
        "speed_up": one_process / on_cluster,
        "same_effects": same,
    }
    print(json.dumps(result["discover_13_segments"]), file=sys.stderr)

    n = str(a.align_runs)
    start = time.perf_counter()
    out = subprocess.run(
        [a.cli, "align", "--runs", n, "--per-run", "--json"], check=True, capture_output=True
    )
    cli_s = time.perf_counter() - start
    single = json.loads(out.stdout)
    start = time.perf_counter()
    dist = auvnav.fleet.montecarlo(client, "align", runs=a.align_runs, per_run=True)
    cluster_s = time.perf_counter() - start
    result["align"] = {
        "runs": a.align_runs,
        "cli_s": cli_s,
        "cluster_s": cluster_s,
        "per_run_identical": dist["per_run"] == single["per_run"],
        "models_identical": dist["models"] == single["models"],
    }
    client.close()
    cluster.close()
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
