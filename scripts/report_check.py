#!/usr/bin/env python3
"""Physical answers only: every report of the blind suites, checked.

For every case of each suite (made by `scripts/blind-benchmark.sh`), runs
`motorbench identify --json` and `motorbench diagnose --json` and checks
each report for:

- a missing number (`null` where the contract puts a value: serde writes
  a NaN as `null`), outside the keys that are optional by the contract
  (`ci95` of an undetermined parameter, `reason`, `best`, ...);
- a parameter outside its physical range, judged by its unit: resistances,
  inductances, reactances, inertias and the torque constant > 0; friction
  and torque >= 0 (identified values, and a verdict's corrected values);
  a share of a whole (the DC saturation's `La_floor`, the shaft's
  `r_motor`) within [0, 1];
- an NRMSE above 1 reported as a result (a method's fit or held-out
  score, the nominal model's, the verdict's gap before or after; a
  candidate's is a comparison and may exceed 1): a model worse than the
  readings' mean is a fit that failed, which the report must say instead
  of scoring it;
- a run that took longer than the bound (`--max-seconds`, default 5 s).

Prints one line per finding and a summary per suite and source; exit 1
when anything was found.

    scripts/report_check.py [SUITE ...] [--bin PATH] [--max-seconds S]
"""

import argparse
import glob
import json
import os
import subprocess
import sys
import time

POSITIVE = {"ohm", "H", "kg*m^2", "V*s/rad", "N*m/A"}
NON_NEGATIVE = {"N*m", "N*m*s/rad", "N*m*s^2/rad^2", "W"}
NRMSE_KEYS = {"fit_nrmse", "validation_nrmse", "gap_before", "gap_after"}
SHARES = {"La_floor", "r_motor"}
OPTIONAL = {"ci95", "reason", "best", "validation_nrmse", "params", "region", "verdict"}


def run(cmd):
    t0 = time.monotonic()
    out = subprocess.run(cmd, capture_output=True, text=True)
    return out, time.monotonic() - t0


def findings(report, where):
    found = []

    def walk(x, path):
        if isinstance(x, dict):
            unit = x.get("unit")
            for key in ("value", "corrected", "nominal"):
                v = x.get(key)
                if unit is None or not isinstance(v, (int, float)):
                    continue
                if unit in POSITIVE and not v > 0:
                    found.append(f"{where}: {path}.{key} = {v} {unit} (must be > 0)")
                if unit in NON_NEGATIVE and not v >= 0:
                    found.append(f"{where}: {path}.{key} = {v} {unit} (must be >= 0)")
                if path.rsplit(".", 1)[-1] in SHARES and not 0 <= v <= 1:
                    found.append(f"{where}: {path}.{key} = {v} (a share: must lie in [0, 1])")
            for k, v in x.items():
                # A candidate's held-out NRMSE compares it with the nominal
                # model (a candidate worse than the mean is just a bad one);
                # the results are the methods', the nominal's and the verdict's.
                scored = ".candidates[" not in path
                if scored and k in NRMSE_KEYS and isinstance(v, (int, float)) and v > 1.0:
                    found.append(f"{where}: {path}.{k} = {v} (an NRMSE above 1: a failed fit scored)")
                if v is None and k not in OPTIONAL:
                    found.append(f"{where}: {path}.{k} is null (a NaN?)")
                walk(v, f"{path}.{k}")
        elif isinstance(x, list):
            for i, v in enumerate(x):
                walk(v, f"{path}[{i}]")

    walk(report, "")
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suites", nargs="*")
    ap.add_argument("--bin", default="target/release/motorbench")
    ap.add_argument("--max-seconds", type=float, default=5.0)
    args = ap.parse_args()
    suites = args.suites or sorted(glob.glob("target/blind/seed-*/"))
    if not suites:
        sys.exit("no suites: run scripts/blind-benchmark.sh first")
    bad = 0
    for suite in suites:
        cases = json.load(open(os.path.join(suite, "cases.json")))["cases"]
        # The plant that made each case, as the truth names it (own,
        # gym-electric-motor, motulator).
        truth_path = os.path.join(suite, "truth.json")
        sources = {}
        if os.path.exists(truth_path):
            sources = {k: t.get("source", "motorbench") for k, t in json.load(open(truth_path))["cases"]}
        stats = {}
        for case in cases:
            source = sources.get(case["id"], "motorbench")
            files = [os.path.join(suite, f) for f in case["files"]]
            extra = []
            if case.get("nameplate"):
                extra = ["--nameplate", os.path.join(suite, case["nameplate"])]
            s = stats.setdefault(source, {"reports": 0, "findings": 0, "slowest": 0.0})
            for verb in ("identify", "diagnose"):
                out, secs = run([args.bin, verb, "--kind", case["kind"], "--json"] + extra + files)
                where = f"{suite} {case['id']} {verb}"
                s["slowest"] = max(s["slowest"], secs)
                found = []
                if secs > args.max_seconds:
                    found.append(f"{where}: took {secs:.1f} s (bound {args.max_seconds} s)")
                if out.returncode == 0:
                    s["reports"] += 1
                    found += findings(json.loads(out.stdout), where)
                elif out.returncode not in (4,):
                    found.append(f"{where}: exit {out.returncode}: {out.stderr.strip()[:160]}")
                for f in found:
                    print(f)
                s["findings"] += len(found)
                bad += len(found)
        for source, s in sorted(stats.items()):
            print(
                f"{suite} {source}: {s['reports']} reports, {s['findings']} findings, "
                f"slowest run {s['slowest']:.2f} s"
            )
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
