#!/usr/bin/env bash
# Runs every decoder fuzz target for a bounded time and reports the executions and the outcome.
# Usage: scripts/fuzz.sh [seconds per target, default 60]. Needs a nightly toolchain and
# cargo-fuzz (`cargo install cargo-fuzz`). Seeds come from ../shared/protocols when present.
set -euo pipefail
seconds="${1:-60}"
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root/drivers/fuzz"
shared="$root/../shared/protocols"
declare -A seeds=(
  [pd0]="$shared/rdi_pd0"
  [wldvl]="$shared/waterlinked_dvl"
  [kvh1750]="$shared/kvh_1750"
  [xsens]="$shared/xsens_mtdata2"
  [seatrac]="$shared/seatrac_usbl"
  [nortek]="$shared/nortek_dvl"
  [can_dbc]=""
)
status=0
for target in pd0 wldvl kvh1750 xsens seatrac nortek can_dbc; do
  corpus="corpus/$target"
  mkdir -p "$corpus"
  if [ -d "${seeds[$target]}" ]; then
    for f in "${seeds[$target]}"/*; do
      # A leading chunk-size byte, then the sample.
      { printf '\x40'; head -c 65536 "$f"; } > "$corpus/seed-$(basename "$f")"
    done
  fi
  log="$(mktemp)"
  if cargo +nightly fuzz run "$target" "$corpus" -- -max_total_time="$seconds" -max_len=70000 -print_final_stats=1 >"$log" 2>&1; then
    execs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || true)"
    echo "$target: ${execs:-?} executions in ${seconds} s, no crash"
  else
    echo "$target: CRASH (see $log)"
    tail -30 "$log"
    status=1
  fi
done
exit $status
