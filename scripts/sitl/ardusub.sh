#!/usr/bin/env bash
# ArduSub SITL for auvnav's closed-loop checks: builds it once into a cache outside the repository
# (recording the commit it was built from) and runs it.
#
#   scripts/sitl/ardusub.sh build     build (or find) the cached SITL; prints the binary's path
#   scripts/sitl/ardusub.sh path      print the cached binary's path, exit 3 when it is not built
#   scripts/sitl/ardusub.sh run ARGS  run the cached SITL with ARGS after its own defaults
#
# Sources: git repositories under $AUVNAV_ARDUPILOT_MIRRORS laid out as OWNER+NAME/repo (bare),
# else GitHub. The ArduPilot commit is ArduSub 4.7.0-dev, the one docs/operations.md reports;
# each submodule is placed at the commit that commit pins.
# Cache: ${AUVNAV_SITL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/auvnav/ardusub}/<commit>/
set -euo pipefail

ARDUPILOT_COMMIT=90700977c553d2dfd95a305acf1c3e098e4d9477
# The upstream history without its size limit: the same commits as ArduPilot/ardupilot.
ARDUPILOT_REPO=blitzy-public-samples/ardupilot-blitzy
cache_root=${AUVNAV_SITL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/auvnav/ardusub}
dir=$cache_root/$ARDUPILOT_COMMIT
binary=$dir/src/build/sitl/bin/ardusub

repository() { # OWNER/NAME -> a URL or path git can clone
    local mirror=${AUVNAV_ARDUPILOT_MIRRORS:-}/${1/\//+}/repo
    if [[ -n "${AUVNAV_ARDUPILOT_MIRRORS:-}" && -d "$mirror" ]]; then
        echo "$mirror"
    else
        echo "https://github.com/$1.git"
    fi
}

checkout() { # OWNER/NAME COMMIT DEST
    local from
    from=$(repository "$1")
    rm -rf "$3"
    mkdir -p "$(dirname "$3")"
    if [[ -d "$from" ]]; then
        # A mirror may lack large binary files (firmware images, photos) that SITL does not use:
        # the tree is written file by file and the missing ones are listed, not fatal.
        git clone -q --shared --no-checkout "$from" "$3"
        git -C "$3" update-ref --no-deref HEAD "$2"
        git -C "$3" read-tree HEAD
        git -C "$3" checkout-index -a -f 2> "$3.missing" || true
        if [[ -s "$3.missing" ]]; then
            echo "ArduSub SITL: $(grep -c . "$3.missing") files of $1 are not in the mirror" \
                "(listed in $3.missing)" >&2
        fi
    else
        git init -q "$3"
        git -C "$3" fetch -q --depth 1 "$from" "$2"
        git -C "$3" -c advice.detachedHead=false checkout -q "$2"
    fi
}

pinned() { # SUPERPROJECT PATH -> the commit the superproject pins at PATH
    git -C "$1" ls-tree HEAD "$2" | awk '{ print $3 }'
}

build() {
    if [[ -x "$binary" && -f "$dir/COMMIT" ]]; then
        echo "$binary"
        return
    fi
    mkdir -p "$dir"
    local src=$dir/src
    echo "ArduSub SITL: checking out ArduPilot $ARDUPILOT_COMMIT into $src" >&2
    checkout "$ARDUPILOT_REPO" "$ARDUPILOT_COMMIT" "$src"
    local module
    for module in ArduPilot/waf:modules/waf ArduPilot/mavlink:modules/mavlink \
        ArduPilot/littlefs:modules/littlefs dronecan/libcanard:modules/DroneCAN/libcanard \
        dronecan/DSDL:modules/DroneCAN/DSDL dronecan/dronecan_dsdlc:modules/DroneCAN/dronecan_dsdlc \
        dronecan/pydronecan:modules/DroneCAN/pydronecan; do
        local name=${module%%:*} path=${module#*:}
        echo "ArduSub SITL: $path from $name" >&2
        checkout "$name" "$(pinned "$src" "$path")" "$src/$path"
    done
    checkout ArduPilot/pymavlink "$(pinned "$src/modules/mavlink" pymavlink)" \
        "$src/modules/mavlink/pymavlink"

    echo "ArduSub SITL: Python build environment in $dir/venv" >&2
    python3 -m venv "$dir/venv"
    "$dir/venv/bin/pip" install -q 'empy==3.3.4' pexpect future lxml pymavlink dronecan pyserial
    (
        cd "$src"
        export PATH=$dir/venv/bin:$PATH
        # lwIP's pinned commit is not needed: SITL's MAVLink ports are plain sockets.
        ./waf configure --board sitl --no-submodule-update --disable-networking >&2
        ./waf sub -j"$(nproc)" >&2
    )
    {
        echo "ardupilot $ARDUPILOT_COMMIT"
        echo "built $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(uname -srm)"
    } > "$dir/COMMIT"
    echo "$binary"
}

case "${1:-}" in
build) build ;;
path)
    if [[ -x "$binary" && -f "$dir/COMMIT" ]]; then
        echo "$binary"
    else
        echo "ArduSub SITL is not built: run scripts/sitl/ardusub.sh build" >&2
        exit 3
    fi
    ;;
run)
    shift
    [[ -x "$binary" ]] || { echo "ArduSub SITL is not built: run $0 build" >&2; exit 3; }
    exec "$binary" --model vectored --defaults "$dir/src/Tools/autotest/default_params/sub.parm" "$@"
    ;;
*)
    sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
    ;;
esac
