#!/bin/sh
# Makes tests/mcap_corpus/seed.mcap, the good record the corrupted-MCAP
# corpus is generated from (see mod.rs): a short simulated DC step test.
# Run from the repository root: tests/mcap_corpus/make_seed.sh
set -eu
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cargo run --quiet -- run --config tests/mcap_corpus/seed.toml --out "$out" \
    --quiet --no-diagnose >/dev/null
cp "$out"/*.mcap tests/mcap_corpus/seed.mcap
ls -l tests/mcap_corpus/seed.mcap
