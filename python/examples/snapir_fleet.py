"""The Snapir AUV segments on a local Dask cluster: import, replay, discover, replay again with
what discovery found, and plot the navigation error against distance before and after.

    python snapir_fleet.py --data ../shared/data/snapir-auv --out snapir-example --workers 2

Writes into --out: the logs, the solutions (CSV), each segment's discovered configuration,
``error_vs_distance.png``, and ``summary.json`` (per segment: the end error before and after).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from dask.distributed import Client, LocalCluster  # noqa: E402

import auvnav  # noqa: E402
import auvnav.fleet  # noqa: E402

EARTH_RADIUS_M = 6_371_000.0


def error_against_distance(log: pathlib.Path, solutions_csv: pathlib.Path) -> pd.DataFrame:
    """Horizontal error of the solutions against the log's reference (truth channel), and the
    distance the reference travelled, at every reference epoch the solutions cover."""
    truth = auvnav.read_log(log)["truth"]
    sol = pd.read_csv(solutions_csv)
    t_sol = sol["time_ns"].to_numpy() * 1e-9
    t = truth["time_s"].to_numpy()
    inside = (t >= t_sol[0]) & (t <= t_sol[-1])
    truth = truth[inside]
    t = t[inside]
    lat = np.interp(t, t_sol, sol["latitude_rad"].to_numpy())
    lon = np.interp(t, t_sol, sol["longitude_rad"].to_numpy())
    ref_lat = truth["latitude_rad"].to_numpy()
    ref_lon = truth["longitude_rad"].to_numpy()
    north = (lat - ref_lat) * EARTH_RADIUS_M
    east = (lon - ref_lon) * EARTH_RADIUS_M * np.cos(ref_lat)
    step_n = np.diff(ref_lat) * EARTH_RADIUS_M
    step_e = np.diff(ref_lon) * EARTH_RADIUS_M * np.cos(ref_lat[1:])
    distance = np.concatenate([[0.0], np.cumsum(np.hypot(step_n, step_e))])
    return pd.DataFrame({"distance_m": distance, "horizontal_error_m": np.hypot(north, east)})


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="the Snapir data set directory")
    p.add_argument("--out", default="snapir-example", help="output directory")
    p.add_argument("--segments", default="1-13", help="segments, e.g. 1-13 or 2,4,7")
    p.add_argument("--workers", type=int, default=2, help="local Dask worker processes")
    a = p.parse_args()
    if "-" in a.segments:
        first, last = (int(x) for x in a.segments.split("-"))
        segments = list(range(first, last + 1))
    else:
        segments = [int(x) for x in a.segments.split(",")]
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()

    logs = []
    for s in segments:
        log = out / f"segment_{s:02}.mcap"
        auvnav.import_snapir(a.data, segment=s, out=log)
        logs.append(log)
    print(f"imported {len(logs)} segments")

    cluster = LocalCluster(
        n_workers=a.workers, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    )
    with cluster, Client(cluster) as client:
        before = auvnav.fleet.map_logs(
            client, "replay", logs,
            options_per_log=[{"out": log.with_suffix(".nominal.csv")} for log in logs],
        )
        found = auvnav.fleet.map_logs(
            client, "discover", logs,
            options_per_log=[{"write_config": log.with_suffix(".discovered.toml")} for log in logs],
        )
        configs = [log.with_suffix(".discovered.toml") for log in logs]
        after = auvnav.fleet.map_logs(
            client, "replay", logs,
            options_per_log=[
                {"out": log.with_suffix(".discovered.csv"), "config": c if c.exists() else None}
                for log, c in zip(logs, configs)
            ],
        )

    fig, ax = plt.subplots(figsize=(9, 5))
    rows = []
    for k, (s, log) in enumerate(zip(segments, logs)):
        e0 = error_against_distance(log, log.with_suffix(".nominal.csv"))
        e1 = error_against_distance(log, log.with_suffix(".discovered.csv"))
        colour = plt.cm.tab20(k % 20)
        ax.plot(e0["distance_m"], e0["horizontal_error_m"], color=colour, lw=0.8, ls=":")
        ax.plot(e1["distance_m"], e1["horizontal_error_m"], color=colour, lw=1.2, label=f"{s}")
        effects = [e["name"] for e in found["report"][k]["effects"]]
        rows.append(
            {
                "segment": s,
                "distance_m": float(e0["distance_m"].iloc[-1]),
                "end_error_nominal_m": float(e0["horizontal_error_m"].iloc[-1]),
                "end_error_discovered_m": float(e1["horizontal_error_m"].iloc[-1]),
                "replay_final_error_nominal_m": before["report"][k]["accuracy"][
                    "horizontal_error_final_m"
                ],
                "replay_final_error_discovered_m": after["report"][k]["accuracy"][
                    "horizontal_error_final_m"
                ],
                "effects": effects,
            }
        )
    ax.set_xlabel("distance travelled (m)")
    ax.set_ylabel("horizontal error against the reference (m)")
    ax.set_title("Snapir segments: nominal model (dotted) and discovered model (solid)")
    ax.legend(title="segment", fontsize="small", ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "error_vs_distance.png", dpi=120)

    table = pd.DataFrame(rows)
    print(table.drop(columns=["effects"]).to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    worse = table[table["end_error_discovered_m"] > table["end_error_nominal_m"]]
    print(f"{len(worse)} of {len(table)} segments end worse with the discovered model")
    summary = {
        "format_version": 1,
        "segments": rows,
        "workers": a.workers,
        "wall_s": time.perf_counter() - started,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    assert all(math.isfinite(r["end_error_discovered_m"]) for r in rows)
    print(f"wrote {out / 'error_vs_distance.png'} and {out / 'summary.json'}")


if __name__ == "__main__":
    main()
