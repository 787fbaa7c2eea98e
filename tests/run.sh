#!/usr/bin/env bash
# The whole test suite, from a fresh clone: installs what the tests need
# (the Python peers that read our files), then format, lint and every test.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v python3 >/dev/null 2>&1 || ! python3 -m pip --version >/dev/null 2>&1; then
    echo "== installing python3 and pip"
    if [ "$(id -u)" -eq 0 ]; then SUDO=""; else SUDO="sudo"; fi
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq python3 python3-pip
fi
if ! command -v systemd-analyze >/dev/null 2>&1; then
    echo "== installing systemd's tools (systemd-analyze verifies the unit)"
    if [ "$(id -u)" -eq 0 ]; then SUDO=""; else SUDO="sudo"; fi
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq systemd
fi
echo "== installing the Python test peers and readers (tests/python/requirements.txt)"
python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore \
    -r tests/python/requirements.txt

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy (warnings are errors)"
cargo clippy --workspace --all-targets --locked -- -D warnings
echo "== cargo build --release (the diagnosis tests run the optimised binary)"
cargo build --release --locked --bin motorbench
echo "== cargo test"
cargo test --workspace --locked

echo "== SocketCAN round trip (needs kernel CAN and vcan0)"
if [ -e /sys/class/net/vcan0 ]; then
    cargo test --locked --test socketcan -- --ignored
else
    echo "SocketCAN round trip DID NOT RUN: this kernel offers no vcan0 (it is reported as ignored above, not passed)"
fi
