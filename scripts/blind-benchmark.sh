#!/usr/bin/env bash
# The wide blind benchmark: for each seed, motorbench's own suite plus
# gym-electric-motor (DC) and motulator (IM) cases, scored together (the
# score lists own and third-party cases apart, per plan). Prints the figures
# docs/diagnosis-dc.md and docs/diagnosis-im.md quote. Generated suites go to
# target/blind/ (kept out of git).
#
#   scripts/blind-benchmark.sh [SEED ...]     (default: 20261121 7 2024)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(20261121 7 2024)
cargo build --release --quiet
bin="$root/target/release/motorbench"
mkdir -p target/blind
for seed in "${seeds[@]}"; do
    suite="target/blind/seed-$seed"
    rm -rf "$suite"
    "$bin" blind generate --out "$suite" --seed "$seed"
    scripts/blind-gem.sh --out "$suite" --seed "$seed" 2>/dev/null
    scripts/blind-motulator.sh --out "$suite" --seed "$seed"
    "$bin" blind score "$suite" | tee "target/blind/seed-$seed.txt"
done
