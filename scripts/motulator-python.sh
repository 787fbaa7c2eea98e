#!/usr/bin/env bash
# Run a Python script in motulator's venv (target/venv-motulator, created
# on first use; never the system's Python). motulator 0.18.0 needs Python
# 3.12 or later: the first of $MOTULATOR_PYTHON, python3.13, python3.12,
# python3, or a pyenv install that is recent enough.
#
#   scripts/motulator-python.sh SCRIPT.py [ARG...]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
venv="${MOTULATOR_VENV:-$root/target/venv-motulator}"
pin="motulator==0.18.0"
recent() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 12))' 2>/dev/null; }
if [ ! -x "$venv/bin/python" ] || ! recent "$venv/bin/python" ||
    ! "$venv/bin/python" -c 'import importlib.metadata as m, sys; sys.exit(m.version("motulator") != sys.argv[1])' "${pin#*==}" 2>/dev/null; then
    python=""
    for candidate in ${MOTULATOR_PYTHON:-} python3.13 python3.12 python3 \
        "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.1[2-9]*/bin/python3; do
        if command -v "$candidate" >/dev/null 2>&1 && recent "$candidate"; then
            python="$candidate"
            break
        fi
    done
    if [ -z "$python" ]; then
        echo "motulator-python: $pin needs Python 3.12 or later; none found (set MOTULATOR_PYTHON)" >&2
        exit 2
    fi
    rm -rf "$venv"
    "$python" -m venv "$venv" || {
        echo "motulator-python: $python -m venv failed; install its venv module" >&2
        exit 2
    }
    "$venv/bin/pip" install --quiet "$pin"
fi
exec "$venv/bin/python" "$@"
