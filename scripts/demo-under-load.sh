#!/usr/bin/env bash
# Runs `auvnav demo` (real processes on pseudo-terminals) N times in a row while other processes
# keep every core busy, and counts the runs whose replay of the recording is byte-identical to the
# live solution.
#
#   scripts/demo-under-load.sh [RUNS] [-- extra demo options]
#
# Needs the release binaries (cargo build --release). Prints one line per run and a summary; exits
# 3 when a run did not reproduce (or did not stop cleanly), 0 otherwise.
set -euo pipefail
runs=${1:-20}
shift || true
[ "${1:-}" = "--" ] && shift
here=$(cd "$(dirname "$0")/.." && pwd)
auvnav=${AUVNAV:-$here/target/release/auvnav}
[ -x "$auvnav" ] || { echo "no $auvnav: run cargo build --release first" >&2; exit 2; }
cores=$(nproc)
load=()
for _ in $(seq "$cores"); do
    (while :; do :; done) &
    load+=($!)
done
trap 'kill "${load[@]}" 2>/dev/null || true' EXIT
out=$(mktemp -d)
identical=0
for i in $(seq "$runs"); do
    if "$auvnav" demo --json --out "$out/run$i" "$@" >"$out/run$i.json" 2>"$out/run$i.err"; then
        identical=$((identical + 1))
        figures=""
        if command -v python3 >/dev/null; then
            figures=$(python3 - "$out/run$i.json" <<'PY' || true
import json, sys
v = json.load(open(sys.argv[1]))
p = v.get("phases") or {}
a = p.get("alignment") or {}
u = p.get("usbl") or {}
e = u.get("error") or {}
parts = []
if a.get("aligned_after_s") is not None:
    parts.append(f"aligned after {a['aligned_after_s']:.1f} s, heading error {a['heading_error_at_aligned_deg']:+.3f} deg")
if e:
    parts.append(f"USBL {u['fused']} fused / {u['rejected']} rejected ({u['outliers_simulated']} outliers), "
                 f"RMS {e['horizontal_error_rms_m']:.2f} m, end {e['horizontal_error_final_m']:.2f} m")
for s in v.get("stamp_errors") or []:
    l, late = s["against_line_us"], s["emulator_late_us"]
    parts.append(f"{s['kind'].upper()} stamp - line p50/p99 {l['p50']:+.0f}/{l['p99']:+.0f} us "
                 f"(emulator late p99 {late['p99']:.0f} us)")
parts.append(f"{v['wall_s']:.1f} s wall")
print("; ".join(parts))
PY
)
        fi
        echo "run $i: byte-identical; $figures"
    else
        echo "run $i: NOT reproduced (see $out/run$i.json, $out/run$i.err)"
    fi
done
echo "$identical of $runs runs byte-identical with $cores busy-loop processes on $cores cores"
[ "$identical" -eq "$runs" ] || exit 3
rm -rf "$out"
