#!/usr/bin/env python3
"""The DC diagnosis's noise floor against the truth, on the blind suites.

For every DC case of each suite (made by `scripts/blind-benchmark.sh`),
runs `motorbench diagnose --json` and compares the report's estimated
`gap.noise_floor` with the floor the generator knows (`truth.json`,
`noise_floor`: the NRMSE of its own noise). Prints the median ratio, the
cases beyond the given bounds (with their plan, effect and verdict), and
the ratio's spread per source. The figures docs/diagnosis-dc.md quotes for
the floor's clipping come from this script.

    scripts/noise_floor_check.py [SUITE ...] [--bin PATH] [--low 0.6] [--high 2.0]
"""

import argparse
import glob
import json
import os
import statistics
import subprocess
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suites", nargs="*")
    ap.add_argument("--bin", default="target/release/motorbench")
    ap.add_argument("--low", type=float, default=0.6, help="list cases whose ratio is below this")
    ap.add_argument("--high", type=float, default=2.0, help="list cases whose ratio is above this")
    args = ap.parse_args()
    suites = args.suites or sorted(glob.glob("target/blind/seed-*/"))
    if not suites:
        sys.exit("no suites: run scripts/blind-benchmark.sh first")
    rows = []
    for suite in suites:
        cases = json.load(open(os.path.join(suite, "cases.json")))["cases"]
        truth = dict(json.load(open(os.path.join(suite, "truth.json")))["cases"])
        for case in cases:
            if case["kind"] != "dc_step":
                continue
            files = [os.path.join(suite, f) for f in case["files"]]
            out = subprocess.run(
                [args.bin, "diagnose", "--kind", "dc_step", "--json"] + files,
                capture_output=True,
                text=True,
            )
            t = truth[case["id"]]
            if out.returncode != 0:
                print(f"{suite} {case['id']}: exit {out.returncode}: {out.stderr.strip()[:160]}")
                continue
            d = json.loads(out.stdout)
            ratio = d["gap"]["noise_floor"] / t["noise_floor"]
            rows.append((ratio, suite, case["id"], t.get("source", "motorbench"), t.get("plan"),
                         t.get("effect"), d["verdict"]["effect"]))
    if not rows:
        sys.exit("no DC cases")
    print(f"{len(rows)} DC records: estimated floor / true floor, median {statistics.median(r[0] for r in rows):.2f}, "
          f"lowest {min(r[0] for r in rows):.2f}, highest {max(r[0] for r in rows):.2f}")
    for source in sorted({r[3] for r in rows}):
        ratios = [r[0] for r in rows if r[3] == source]
        print(f"  {source:<20} {len(ratios):>4} records, median {statistics.median(ratios):.2f}")
    for r in sorted(rows):
        if r[0] < args.low or r[0] > args.high:
            print(f"  {r[0]:6.2f}  {r[1]} {r[2]} {r[3]} {r[4]} truth {r[5]} verdict {r[6]}")


if __name__ == "__main__":
    main()
