#!/usr/bin/env bash
# The whole test suite, from a fresh clone: installs what the tests need
# (the Python peers that read our files, in a virtual environment under
# target/), then format, lint (clippy, warnings as errors) and every test.
# Runs the tests under cargo-nextest where it is installed (one process
# per test, both cores busy to the end), else under `cargo test`; either
# way every test runs.
set -euo pipefail
cd "$(dirname "$0")/.."

apt_install() {
    if [ "$(id -u)" -eq 0 ]; then SUDO=""; else SUDO="sudo"; fi
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq "$@"
}

# A stock Debian python refuses a bare `pip install` (PEP 668): the test
# packages go into target/test-venv, whose interpreter the tests are told
# of through MOTORBENCH_PYTHON (tests/common/python.rs).
if ! command -v python3 >/dev/null 2>&1 || ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
    echo "== installing python3 and its venv module"
    apt_install python3 python3-venv
fi
if ! command -v systemd-analyze >/dev/null 2>&1; then
    echo "== installing systemd's tools (systemd-analyze verifies the unit)"
    apt_install systemd
fi
if ! command -v chromium >/dev/null 2>&1; then
    echo "== installing Chromium (Debian's package): the status page's test drives it headless"
    apt_install chromium
fi
venv=target/test-venv
stamp="$venv/requirements.txt"
if ! cmp -s tests/python/requirements.txt "$stamp" || [ ! -x "$venv/bin/python3" ]; then
    echo "== installing the Python test peers and readers into $venv (tests/python/requirements.txt)"
    rm -rf "$venv"
    python3 -m venv "$venv"
    "$venv/bin/python3" -m pip install --quiet --disable-pip-version-check \
        -r tests/python/requirements.txt
    cp tests/python/requirements.txt "$stamp"
fi
MOTORBENCH_PYTHON="$PWD/$venv/bin/python3"
export MOTORBENCH_PYTHON

echo "== cargo fmt --check"
cargo fmt --all -- --check
# One build of every target, linted as it compiles: clippy's driver
# compiles the workspace's own crates (as `cargo clippy` has it do, through
# RUSTC_WORKSPACE_WRAPPER) with warnings as errors, and the tests below
# reuse what it built. `cargo clippy` itself would check every dependency
# a second time (metadata only), which was a third of a fresh run.
export RUSTC_WORKSPACE_WRAPPER=clippy-driver
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
# Every analysis in a test works on one core: the runner keeps both busy
# with two tests, and the tests that poll a served rig on the wall clock
# must not be starved by a diagnosis spread over both.
export MOTORBENCH_THREADS=1
# A CI run builds once from nothing: incremental compilation's caches
# would only cost time there.
if [ "${CI:-}" = "true" ]; then
    export CARGO_INCREMENTAL=0
fi
echo "== cargo build --all-targets, linted by clippy (warnings are errors)"
cargo build --workspace --all-targets --locked
if cargo nextest --version >/dev/null 2>&1; then
    echo "== cargo nextest run (every test target), then the doc tests"
    cargo nextest run --workspace --locked --no-fail-fast
    cargo test --workspace --locked --doc
else
    echo "== cargo test"
    cargo test --workspace --locked
fi

echo "== SocketCAN round trip (needs kernel CAN and vcan0)"
if [ -e /sys/class/net/vcan0 ]; then
    cargo test --locked --test e2e -- --ignored socketcan::
else
    echo "SocketCAN round trip DID NOT RUN: this kernel offers no vcan0 (it is reported as ignored above, not passed)"
fi
