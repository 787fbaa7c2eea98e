#!/usr/bin/env bash
# CPU time of `motorbench diagnose --json` on every case of blind suites,
# one case at a time (user + system time of the process): the slowest
# cases and the total, per suite and over all. The figures of
# docs/diagnosis-im.md (Bounds) and BENCHMARKS.md ("The induction
# machine's diagnosis") come from it.
#
#   benches/case_cpu.sh SUITE...      (suites of `motorbench blind generate`,
#                                      scripts/blind-gem.sh, scripts/blind-motulator.sh)
#
# MOTORBENCH=path/to/motorbench times another build instead of the
# release binary the script builds.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ $# -eq 0 ]; then
    echo "usage: benches/case_cpu.sh SUITE..." >&2
    exit 2
fi
if [ -z "${MOTORBENCH:-}" ]; then
    (cd "$root" && cargo build --release --locked --bin motorbench)
    MOTORBENCH="$root/target/release/motorbench"
fi
all=$(mktemp)
took=$(mktemp)
trap 'rm -f "$all" "$took"' EXIT
for suite in "$@"; do
    suite="$(cd "$suite" && pwd)"
    # id, kind, nameplate or -, files: one line per case of the manifest.
    python3 - "$suite/cases.json" <<'PY' |
import json, sys
for c in json.load(open(sys.argv[1]))["cases"]:
    print(c["id"], c["kind"], c.get("nameplate") or "-", " ".join(c["files"]))
PY
    while read -r id kind plate files; do
        args=(diagnose --kind "$kind" --json)
        [ "$plate" != "-" ] && args+=(--nameplate "$plate")
        # shellcheck disable=SC2086 # the files are one word each
        (cd "$suite" && /usr/bin/time -f "%U %S" -o "$took" "$MOTORBENCH" "${args[@]}" $files \
            >/dev/null 2>&1) || true
        cpu=$(awk '{print $1 + $2}' "$took")
        echo "$(basename "$suite") $id $cpu" >>"$all"
    done
done
echo "slowest:"
sort -k3 -g -r "$all" | head -5
awk '{ n += 1; s += $3 } END { printf "%d cases, %.1f s of CPU in all\n", n, s }' "$all"
