#!/usr/bin/env bash
# CPU time of the DC diagnosis per record and per recorded sample, on the
# embedded default's record (`motorbench run`: 8 levels and a coast-down)
# and on the same plan with its levels repeated 2 and 4 times (records
# about twice and four times as long). Each record is made once by
# `motorbench run --no-diagnose`, then diagnosed `ROUNDS` times by
# `motorbench diagnose`; the median user+system CPU time is printed (the
# diagnosis runs its fits on every core, so CPU time, not wall time, is
# the measure of its work).
#
#   benches/diagnosis_cpu.sh [ROUNDS]     (default 3)
#
# MOTORBENCH=path/to/motorbench times another build (e.g. an older one)
# instead of the release binary the script builds.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
rounds="${1:-3}"
cargo build --release --locked --bin motorbench --example peers
peers="$root/target/release/examples/peers"
MOTORBENCH="${MOTORBENCH:-$root/target/release/motorbench}"

work="$root/target/diagnosis-cpu"
mkdir -p "$work"
levels="60, 248, 60, 154, 248, 107, 201, 60"
# A repeat starts at 107 V: the plan ends on the level it starts with, and
# a level may not repeat the one before it (as benches/common/mod.rs).
repeat="107, 248, 60, 154, 248, 107, 201, 60"
printf '%-6s %9s %8s %12s %14s\n' length segments samples "CPU (s)" "CPU/sample (us)"
for times in 1 2 4; do
  dir="$work/x$times"
  if ! ls "$dir"/*.mcap >/dev/null 2>&1; then
    rep="$levels"
    for ((k = 1; k < times; k++)); do rep="$rep, $repeat"; done
    sed "s/^levels_V = .*/levels_V = [$rep]/" config/sim-dc.toml > "$work/x$times.toml"
    "$MOTORBENCH" run --config "$work/x$times.toml" --no-diagnose --out "$dir" > /dev/null
  fi
  record="$(ls "$dir"/*.mcap | head -1)"
  cpu=()
  for ((r = 0; r < rounds; r++)); do
    t="$( { /usr/bin/time -f '%U %S' "$MOTORBENCH" diagnose --kind dc_step --json "$record" > "$work/x$times.json"; } 2>&1 | tail -1)"
    cpu+=("$(echo "$t" | awk '{print $1 + $2}')")
  done
  median="$(printf '%s\n' "${cpu[@]}" | sort -g | awk '{a[NR]=$1} END{print a[int((NR+1)/2)]}')"
  read -r segments samples < <("$peers" record-size "$record")
  per_sample="$(awk -v c="$median" -v n="$samples" 'BEGIN{printf "%.1f", c / n * 1e6}')"
  printf '%-6s %9s %8s %12s %14s\n' "${times}x" "$segments" "$samples" "$median" "$per_sample"
done
