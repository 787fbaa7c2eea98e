#!/usr/bin/env bash
# motorbench against the Python peers an engineer would otherwise script
# (numpy, scipy, the `mcap` package), row by row on the same data,
# alternating runs: see BENCHMARKS.md for what each row times and the
# latest figures.
#
#   benches/peers/compare.sh            5 rounds per row
#   benches/peers/compare.sh --quick    2 rounds per row
#   benches/peers/compare.sh ROW...     only those rows (dc_fit, im_fit,
#                                       mcap_write, mcap_read)
#
# Installs the peers in their own venv (target/peers-venv, from
# benches/peers/requirements.txt), builds motorbench in release, and pins
# the peers' BLAS to one thread (OPENBLAS_NUM_THREADS=1): motorbench's fits
# run on one thread too, and a multi-threaded BLAS on a shared 2-core
# machine only adds noise.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
rounds=5
rows=()
for a in "$@"; do
  case "$a" in
    --quick) rounds=2 ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) rows+=("$a") ;;
  esac
done

venv="$root/target/peers-venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r benches/peers/requirements.txt

cargo build --release --locked --bin motorbench --example peers

export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
echo "peers: $("$venv/bin/python" -c 'import numpy, scipy, mcap, sys; print("Python", sys.version.split()[0], "numpy", numpy.__version__, "scipy", scipy.__version__, "mcap", mcap.__version__)'), OPENBLAS_NUM_THREADS=$OPENBLAS_NUM_THREADS"
echo "machine: $(getconf _NPROCESSORS_ONLN) cores, $(uname -m), load average $(cut -d" " -f1-3 /proc/loadavg)"
only=()
if [ ${#rows[@]} -gt 0 ]; then only=(--only "${rows[@]}"); fi
exec "$venv/bin/python" benches/peers/compare.py \
  --peers "$root/target/release/examples/peers" \
  --motorbench "$root/target/release/motorbench" \
  --work "$root/target/peers-work" \
  --rounds "$rounds" "${only[@]}"
