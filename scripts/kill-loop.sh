#!/usr/bin/env bash
# Kill loop: run `motorbench run --realtime` (the embedded simulated DC rig,
# or --config) again and again and SIGKILL it at a random time spread over
# the whole run (test, identification, diagnosis, report writing). After
# each kill the record must replay (`motorbench replay`, up to its last
# flushed chunk) and open in the Python `mcap` package; scripts/kill_check.py
# measures what the kill lost; then `motorbench recover` finishes the cut
# record and the Python seeking (indexed) reader must open it. See docs/reliability.md.
#
#   scripts/kill-loop.sh [--kills N] [--seed S] [--work DIR] [--config TOML]
#                        [--bin PATH] [--python PATH] [--daemon [--im]]
#
# --daemon kills the daemon instead (scripts/kill_daemon.py): `motorbench
# serve` on config/sim-dc-daemon.toml (--im: and config/sim-im.toml, the
# rigs alternating), a test started through the API, SIGKILL at a random
# time, a restart on the same records directory, then the index, the
# records and the rig state are checked.
#
# --bin defaults to target/release/motorbench, --python to python3 (it
# needs the `mcap` package, tests/python/requirements.txt). A reference run
# first measures how long an uninterrupted run and its test take.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
kills=50
seed=1
work=""
config=()
daemon=0
im=()
script_name=kill-loop
. "$here/bench-tools.sh"
while [ $# -gt 0 ]; do
    case "$1" in
    --kills) kills="$2"; shift 2 ;;
    --seed) seed="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    --config) config=(--config "$2"); shift 2 ;;
    --bin) bin="$2"; shift 2 ;;
    --python) python="$2"; shift 2 ;;
    --daemon) daemon=1; shift ;;
    --im) im=(--im); shift ;;
    -h|--help) sed -n 2,20p "$0"; exit 0 ;;
    *) echo "kill-loop: unknown option $1" >&2; exit 2 ;;
    esac
done
require_tools mcap
[ -n "$work" ] || work="$(mktemp -d -t motorbench-kill-loop.XXXXXX)"
mkdir -p "$work"
if [ "$daemon" = 1 ]; then
    exec "$python" "$here/kill_daemon.py" --bin "$bin" --python "$python" --work "$work" \
        --kills "$kills" --seed "$seed" "${im[@]}"
fi
check="$here/kill_check.py"
results="$work/results.jsonl"
: > "$results"
now_ns() { date +%s%N; }

# Reference: one uninterrupted run.
t0=$(now_ns)
"$bin" run --realtime --quiet "${config[@]}" --out "$work/reference" > "$work/reference.out" 2>&1 || true
t1=$(now_ns)
run_ms=$(( (t1 - t0) / 1000000 ))
ref=$(ls "$work"/reference/*.mcap | head -n1)
test_end_s=$("$python" "$check" check "$ref" --kill-unix-ns 0 --test-end-s 1e9 |
    "$python" -c 'import json,sys; print(json.load(sys.stdin)["last_sample_t_s"])')
echo "reference run: ${run_ms} ms wall clock, test ${test_end_s} s of data; work dir $work"

RANDOM=$seed
for i in $(seq 1 "$kills"); do
    out="$work/kill-$i"
    mkdir -p "$out"
    delay_ms=$(( (RANDOM * 32768 + RANDOM) % run_ms ))
    delay_s=$(printf '%d.%03d' $((delay_ms / 1000)) $((delay_ms % 1000)))
    "$bin" run --realtime --quiet "${config[@]}" --out "$out" > "$out/run.out" 2>&1 &
    pid=$!
    sleep "$delay_s"
    if kill -0 "$pid" 2>/dev/null; then
        kill_ns=$(now_ns)
        kill -KILL "$pid" 2>/dev/null || true
        status=killed
    else
        kill_ns=$(now_ns)
        status=finished
    fi
    wait "$pid" 2>/dev/null || true
    rec=$(ls "$out"/*.mcap 2>/dev/null | head -n1 || true)
    files=$(cd "$out" && ls | grep -v '^run.out$' | sed 's/^.*-[0-9]\{8\}T[0-9]\{6\}Z//' | tr '\n' ' ')
    if [ -z "$rec" ]; then
        printf '{"i":%d,"delay_s":%s,"status":"%s","record":false,"files":"%s"}\n' \
            "$i" "$delay_s" "$status" "$files" >> "$results"
        echo "kill $i at ${delay_s} s: no record"
        continue
    fi
    set +e
    "$bin" replay --no-diagnose "$rec" > "$out/replay.out" 2> "$out/replay.err"
    rc=$?
    set -e
    info=$("$python" "$check" check "$rec" --kill-unix-ns "$kill_ns" --test-end-s "$test_end_s")
    # Finish the cut record for indexed readers (the cut file is kept as
    # RECORD.damaged), then open it with the seeking reader.
    set +e
    "$bin" recover "$rec" > "$out/recover.out" 2>&1
    recover_rc=$?
    set -e
    after=$("$python" "$check" recovered "$rec")
    info="${info%\}}, \"recover_rc\": $recover_rc, ${after#\{}"
    printf '{"i":%d,"delay_s":%s,"status":"%s","record":true,"replay_rc":%d,"files":"%s",%s\n' \
        "$i" "$delay_s" "$status" "$rc" "$files" "${info#\{}" >> "$results"
    echo "kill $i at ${delay_s} s: replay exit $rc; $info"
done

echo
"$python" "$check" summary "$results"
echo "results: $results"
