#!/usr/bin/env python3
"""Time loading a record into pandas two ways (docs/data-contract.md#export).

1. The loop a Python user writes with the `mcap` package: every message
   through `json.loads`, one column per sample topic, then a DataFrame.
2. `motorbench export REC --format parquet`, then `pd.read_parquet`.

Both give one float column per /sensor/ and /command/ channel. Prints the
seconds of each (best of --repeat runs) and the ratio.

Usage: python3 scripts/export_vs_python.py [--motorbench BIN] [--repeat N] REC.mcap
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import pandas as pd
from mcap.reader import make_reader


def python_loop(path):
    """The `mcap` + `json.loads` loop: a DataFrame of every sample topic."""
    columns = {}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            if channel.topic.startswith(("/sensor/", "/command/")):
                col = columns.setdefault(channel.topic, ([], []))
                col[0].append(message.log_time)
                col[1].append(json.loads(message.data)["value"])
    series = {}
    for topic, (t, v) in columns.items():
        s = pd.Series(v, index=t)
        # A command written twice at one instant: keep the last.
        series[topic] = s[~s.index.duplicated(keep="last")]
    return pd.DataFrame(series)


def export_then_read(binary, path, out_dir):
    """`motorbench export --format parquet`, then one `pd.read_parquet`."""
    subprocess.run(
        [binary, "export", path, "--format", "parquet", "--out", out_dir],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    stem = os.path.splitext(os.path.basename(path))[0]
    return pd.read_parquet(os.path.join(out_dir, stem + ".parquet"))


def best_of(n, f):
    times = []
    for _ in range(n):
        start = time.perf_counter()
        result = f()
        times.append(time.perf_counter() - start)
    return min(times), result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("record")
    parser.add_argument("--motorbench", default="target/release/motorbench")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    size = os.path.getsize(args.record)
    t_py, df_py = best_of(args.repeat, lambda: python_loop(args.record))
    with tempfile.TemporaryDirectory() as out:
        t_ex, df_ex = best_of(args.repeat, lambda: export_then_read(args.motorbench, args.record, out))
    samples = int(df_py.notna().sum().sum())
    print(f"record: {args.record} ({size / 1e6:.1f} MB, {samples} samples)")
    print(f"mcap + json.loads loop: {t_py:.2f} s ({len(df_py)} rows x {df_py.shape[1]} columns)")
    print(f"motorbench export + pd.read_parquet: {t_ex:.2f} s ({len(df_ex)} rows x {df_ex.shape[1]} columns)")
    print(f"ratio: {t_py / t_ex:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
