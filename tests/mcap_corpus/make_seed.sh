#!/bin/sh
# Makes tests/mcap_corpus/seed.mcap, the good record the corrupted-MCAP
# corpus is generated from (see mod.rs): a short simulated DC step test.
#
# seed.mcap is a contract version 1 record (log_time from the test start,
# events as motorbench.Event), kept as the fixture that proves version 1
# still reads and replays (tests/e2e/record_v2.rs). motorbench writes
# version 2 since, so the script builds the last version 1 motorbench
# (V1_COMMIT) in a temporary worktree and runs it there.
# Run from the repository root: tests/mcap_corpus/make_seed.sh
set -eu
V1_COMMIT=4bee226e59e33d48dcd77d1bac247c664778702f
out=$(mktemp -d)
trap 'git worktree remove --force "$out/src" 2>/dev/null || true; rm -rf "$out"' EXIT
git worktree add --detach "$out/src" "$V1_COMMIT" >/dev/null
(cd "$out/src" && cargo run --quiet -- run --config tests/mcap_corpus/seed.toml \
    --out "$out/rec" --quiet --no-diagnose >/dev/null)
cp "$out"/rec/*.mcap tests/mcap_corpus/seed.mcap
ls -l tests/mcap_corpus/seed.mcap
