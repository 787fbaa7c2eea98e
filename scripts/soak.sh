#!/usr/bin/env bash
# Soak: start `motorbench serve` on the simulated DC rig (and, with --im,
# the simulated induction-machine rig too, in the same daemon), run N tests
# back to back through the HTTP API (alternating over the rigs), and after
# each sample the daemon's RSS, threads and open descriptors
# (scripts/soak.py). Prints the RSS slope per test over the second half and
# the fd and thread counts first vs last. See docs/reliability.md.
#
#   scripts/soak.sh [--tests N] [--minutes M] [--im] [--full] [--work DIR]
#                   [--bin PATH] [--python PATH]
#
# The daemon paces simulated rigs at the wall clock (there is no virtual
# time through the API), so by default each test is shortened with a
# `[test]` override: DC a 60 V -> 248 V step without coast-down, IM one
# supply voltage, 100 V (at 400 V the locked-rotor points heat the winding
# estimate to its 130 C limit in about 18 back-to-back sweeps, a correct
# trip), at 6 slip points with 1 s cool-downs. A tripped rig is reset. --full runs the
# configurations' own plans (about 10 s DC, minutes IM).
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
tests=1000
minutes=""
im=0
full=0
work=""
script_name=soak
. "$here/bench-tools.sh"
while [ $# -gt 0 ]; do
    case "$1" in
    --tests) tests="$2"; shift 2 ;;
    --minutes) minutes="$2"; shift 2 ;;
    --im) im=1; shift ;;
    --full) full=1; shift ;;
    --bin | --python | --work) declare "${1#--}=$2"; shift 2 ;;
    -h | --help) sed -n 2,16p "$0"; exit 0 ;;
    *) echo "soak: unknown option $1" >&2; exit 2 ;;
    esac
done
require_tools
[ -n "$work" ] || work="$(mktemp -d -t motorbench-soak.XXXXXX)"
mkdir -p "$work/records"

configs=(--config "$root/config/sim-dc-daemon.toml")
rigs=(--rig sim-dc-daemon)
overrides=()
if [ "$full" = 0 ]; then
    overrides+=(--override 'sim-dc-daemon={"levels_V": [60, 248], "coastdown": false}')
fi
if [ "$im" = 1 ]; then
    configs+=(--config "$root/config/sim-im.toml")
    rigs+=(--rig sim-im)
    if [ "$full" = 0 ]; then
        overrides+=(--override 'sim-im={"voltages_V": [100], "points": 6, "cooldown_s": 1}')
    fi
fi

"$bin" serve "${configs[@]}" --records "$work/records" --listen 127.0.0.1:0 \
    > "$work/serve.out" 2> "$work/serve.log" &
pid=$!
trap 'kill -TERM $pid 2>/dev/null || true; wait $pid 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do
    grep -q '^listening on ' "$work/serve.out" 2>/dev/null && break
    sleep 0.1
done
url=$(sed -n 's/^listening on //p' "$work/serve.out")
[ -n "$url" ] || { echo "soak: the daemon announced no address" >&2; cat "$work/serve.log" >&2; exit 1; }
echo "daemon pid $pid at $url; work dir $work"

limit=()
[ -z "$minutes" ] || limit=(--minutes "$minutes")
"$python" "$here/soak.py" --url "$url" --pid "$pid" "${rigs[@]}" "${overrides[@]}" \
    --tests "$tests" "${limit[@]}" --csv "$work/soak.csv"
echo "per-test samples: $work/soak.csv; daemon log: $work/serve.log"
