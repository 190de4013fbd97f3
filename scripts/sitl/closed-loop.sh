#!/usr/bin/env bash
# ArduSub SITL flying on auvnav, in one command: builds ArduSub SITL once (cached outside the
# repository, see ardusub.sh) and auvnav's release binaries, then runs the closed loop and prints
# its figures (closed_loop.py says what it checks).
#
#   scripts/sitl/closed-loop.sh [--out DIR] [--json] [closed_loop.py options]
#   scripts/sitl/closed-loop.sh --if-built ...   skip (exit 0, saying so) when SITL is not built
#
# AUVNAV_PROFILE=dev uses the debug build (what CI's tests built) instead of a release build.
# Exit status: 0 every check passed, 1 a check failed.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)

if [[ "${1:-}" == "--if-built" ]]; then
    shift
    if ! binary=$("$here/ardusub.sh" path 2>/dev/null); then
        echo "closed loop skipped: ArduSub SITL is not built on this machine" \
            "(scripts/sitl/ardusub.sh build needs the ArduPilot sources; see docs/operations.md)"
        exit 0
    fi
else
    binary=$("$here/ardusub.sh" build)
fi
sitl=$(dirname "$(dirname "$(dirname "$(dirname "$binary")")")") # …/src/build/sitl/bin/ardusub
venv=$(dirname "$sitl")/venv

profile=${AUVNAV_PROFILE:-release}
bins=$root/target/$([[ "$profile" == dev ]] && echo debug || echo "$profile")
(cd "$root" && cargo build --workspace --profile "$profile" --bin auvnav --bin auvnavd --bin auvnav-imu \
    --bin auvnav-dvl --bin auvnav-mavlink >&2)

exec "$venv/bin/python" "$here/closed_loop.py" \
    --ardusub "$binary" \
    --sitl-defaults "$sitl/Tools/autotest/default_params/sub.parm" \
    --parm "$root/deploy/ardusub-auvnav.parm" \
    --bin "$bins" \
    --out "$root/target/sitl-closed-loop" \
    "$@"
