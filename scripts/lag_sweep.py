#!/usr/bin/env python3
"""Replays logs with a DVL installation at a range of DVL time offsets and prints each log's
horizontal position and velocity error RMS against its reference (`auvnav replay --json`).

It shows what the navigation error against a log's reference says about the DVL lag, beside
what `auvnav discover` finds from the residuals: docs/discovery.md ("What no installation can
do against this reference") used it on the 13 Snapir segments:

    scripts/lag_sweep.py /tmp/sn/s{1..13}.mcap --lever-arm=-0.078,-0.012,0.204 \
        --mount=0,-0.064,-0.28 --depth-lever-arm=1.82,0.008,-0.005 \
        --reference-lever-arm=1.77,0.02,0.12

Standard library only; the `auvnav` binary is taken from $AUVNAV or the PATH.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor


def triple(text):
    values = [float(x) for x in text.split(",")]
    if len(values) != 3:
        raise argparse.ArgumentTypeError("three comma-separated numbers")
    return values


def config(offset, args):
    return (
        "[navigation]\n"
        f"depth_lever_arm_m = {args.depth_lever_arm}\n"
        "[navigation.dvl]\n"
        f"mount_deg = {args.mount}\n"
        f"scale_factor = {args.scale}\n"
        f"lever_arm_m = {args.lever_arm}\n"
        f"time_offset_s = {offset}\n"
        'source = "lag_sweep.py"\n'
    )


def replay(job):
    log, offset, args = job
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
        f.write(config(offset, args))
        path = f.name
    try:
        cmd = [args.auvnav, "replay", log, "--config", path, "--json"]
        if args.reference_lever_arm:
            cmd += ["--reference-lever-arm", ",".join(map(str, args.reference_lever_arm))]
        out = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if out.returncode != 0:
            return None
        a = json.loads(out.stdout).get("accuracy") or {}
        return a.get("horizontal_error_rms_m"), a.get("horizontal_velocity_error_rms_m_s")
    finally:
        os.unlink(path)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("logs", nargs="+")
    p.add_argument("--from", dest="start", type=float, default=0.0, help="first offset (s)")
    p.add_argument("--to", type=float, default=-1.2, help="last offset (s)")
    p.add_argument("--step", type=float, default=0.05, help="offset step (s)")
    p.add_argument("--lever-arm", type=triple, default=[0.0, 0.0, 0.0])
    p.add_argument("--mount", type=triple, default=[0.0, 0.0, 0.0], help="roll,pitch,yaw (deg)")
    p.add_argument("--scale", type=float, default=1.0)
    p.add_argument("--depth-lever-arm", type=triple, default=[0.0, 0.0, 0.0])
    p.add_argument("--reference-lever-arm", type=triple)
    p.add_argument("--auvnav", default=os.environ.get("AUVNAV", "auvnav"))
    args = p.parse_args()
    n = int(round(abs(args.to - args.start) / args.step)) + 1
    sign = 1.0 if args.to >= args.start else -1.0
    offsets = [round(args.start + sign * k * args.step, 6) for k in range(n)]
    jobs = [(log, o, args) for o in offsets for log in args.logs]
    with ThreadPoolExecutor(os.cpu_count() or 1) as ex:
        results = list(ex.map(replay, jobs))
    names = [os.path.basename(log) for log in args.logs]
    print("offset_s  " + "  ".join(f"{n:>9}" for n in names) + "  geomean_m  mean_vel_mm_s")
    for i, o in enumerate(offsets):
        row = results[i * len(args.logs) : (i + 1) * len(args.logs)]
        if any(r is None or r[0] is None for r in row):
            print(f"{o:8.3f}  (a replay failed)", file=sys.stderr)
            continue
        geo = math.exp(sum(math.log(r[0]) for r in row) / len(row))
        vel = 1e3 * sum(r[1] or 0.0 for r in row) / len(row)
        cells = "  ".join(f"{r[0]:9.2f}" for r in row)
        print(f"{o:8.3f}  {cells}  {geo:9.3f}  {vel:13.1f}")


if __name__ == "__main__":
    main()
