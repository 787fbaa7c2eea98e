#!/usr/bin/env bash
# Add motulator induction-machine cases to a blind suite
# (scripts/blind_motulator.py), in motulator's venv
# (scripts/motulator-python.sh).
#
#   scripts/blind-motulator.sh --out SUITE [--seed N] [--cases M]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
exec "$here/motulator-python.sh" "$here/blind_motulator.py" "$@"
