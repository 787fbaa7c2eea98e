#!/usr/bin/env bash
# Add gym-electric-motor cases to a blind suite (scripts/blind_gem.py),
# in a venv of its own (target/venv-gem, created on first use; never the
# system's Python).
#
#   scripts/blind-gem.sh --out SUITE [--seed N] [--cases M]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
venv="${GEM_VENV:-$root/target/venv-gem}"
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c 'import gym_electric_motor' 2>/dev/null; then
    python3 -m venv "$venv" || {
        echo "blind-gem: python3 -m venv failed; install python3-venv" >&2
        exit 2
    }
    "$venv/bin/pip" install --quiet gym-electric-motor==3.0.3
fi
exec "$venv/bin/python" "$root/scripts/blind_gem.py" "$@"
