#!/usr/bin/env python3
"""K and Ra of `motorbench identify` against the truth of blind suites.

For every DC case of each suite (made by `scripts/blind-benchmark.sh`, or
`motorbench blind generate` plus `scripts/blind-gem.sh`), runs
`motorbench identify --kind dc-step --json` on the case's files and takes
K and Ra from the method the report names `best` (the identification the
report uses). Compares them with the truth file's nominal K and Ra.

Effects that bias K or Ra by their physics (a brush drop or heating
changes the apparent Ra, armature reaction the apparent K, a lagging
sensor both) are listed apart: the bar (K within 1 %, Ra within 3 %)
applies to `none` and the effects that leave the electrical equation
alone (coulomb_friction, inductance_saturation, shaft_compliance).

    scripts/dc_accuracy.py [SUITE ...] [--bin PATH] [--cases]

SUITE defaults to every target/blind/seed-*/ directory. `--cases` also
prints one line per case (errors, method, plan, setup).
"""

import argparse
import glob
import json
import os
import subprocess
import sys
from collections import defaultdict

K_BAR = 0.01
RA_BAR = 0.03
BIASING = {"brush_drop", "thermal_drift", "armature_reaction", "sensor_lag"}


def identify(binary, suite, entry):
    files = [os.path.join(suite, f) for f in entry["files"]]
    cmd = [binary, "identify", "--kind", "dc-step", "--json"]
    if entry.get("nameplate"):
        cmd += ["--nameplate", os.path.join(suite, entry["nameplate"])]
    out = subprocess.run(cmd + files, capture_output=True, text=True)
    if out.returncode != 0:
        return None, f"exit {out.returncode}: {out.stderr.strip()[:120]}"
    return json.loads(out.stdout), None


def params_of(report):
    best = report.get("best")
    method = report.get("methods", {}).get(best or "", {})
    params = method.get("params") or {}
    k = params.get("K", {}).get("value")
    ra = params.get("Ra", {}).get("value")
    return best, k, ra


def pct(values):
    if not values:
        return "-"
    values = sorted(values)
    med = values[len(values) // 2]
    return f"{100 * med:.2f}/{100 * values[-1]:.2f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("suites", nargs="*")
    ap.add_argument("--bin", default="target/release/motorbench")
    ap.add_argument("--cases", action="store_true")
    args = ap.parse_args()
    suites = args.suites or sorted(glob.glob("target/blind/seed-*/"))
    if not suites:
        sys.exit("dc_accuracy: no suite (run scripts/blind-benchmark.sh first)")
    for suite in suites:
        manifest = json.load(open(os.path.join(suite, "cases.json")))
        truth = dict(json.load(open(os.path.join(suite, "truth.json")))["cases"])
        groups = defaultdict(list)
        rest = []
        for entry in manifest["cases"]:
            if entry["kind"] != "dc_step":
                continue
            t = truth[entry["id"]]
            report, err = identify(args.bin, suite, entry)
            row = dict(id=entry["id"], effect=t["effect"], plan=t["plan"], source=t["source"])
            if report is None:
                row.update(method=None, k=None, ra=None, why=err)
            else:
                best, k, ra = params_of(report)
                kt, rt = t["nominal"]["K"], t["nominal"]["Ra"]
                row.update(
                    method=best,
                    k=None if k is None else (k - kt) / kt,
                    ra=None if ra is None else (ra - rt) / rt,
                    why=None,
                )
            if args.cases:
                setup = " ".join(f"{k}={v:g}" for k, v in sorted(t.get("setup", {}).items()))
                ke = "-" if row["k"] is None else f"{100 * row['k']:+.2f}%"
                re = "-" if row["ra"] is None else f"{100 * row['ra']:+.2f}%"
                print(
                    f"{suite} {row['id']} {row['source'][:3]} {row['plan']:13} "
                    f"{row['effect']:22} K {ke:>8} Ra {re:>8} {row['method'] or row['why']} {setup}"
                )
            (rest if t["effect"] in BIASING else groups[(t["source"], t["plan"])]).append(row)
            if t["effect"] not in BIASING:
                groups[(t["source"], "all")].append(row)
        print(f"\n{suite}: none and effects that leave K, Ra unbiased")
        print(
            f"{'source':20} {'plan':14} {'cases':>5} {'K 1%':>5} {'Ra 3%':>6} {'both':>5} "
            f"{'|K| med/max %':>14} {'|Ra| med/max %':>15}  methods"
        )
        for (source, plan), rows in sorted(groups.items()):
            got = [r for r in rows if r["k"] is not None and r["ra"] is not None]
            k_ok = sum(abs(r["k"]) <= K_BAR for r in got)
            ra_ok = sum(abs(r["ra"]) <= RA_BAR for r in got)
            both = sum(abs(r["k"]) <= K_BAR and abs(r["ra"]) <= RA_BAR for r in got)
            methods = defaultdict(int)
            for r in rows:
                methods[r["method"] or "refused"] += 1
            print(
                f"{source:20} {plan:14} {len(rows):5} {k_ok:5} {ra_ok:6} {both:5} "
                f"{pct([abs(r['k']) for r in got]):>14} {pct([abs(r['ra']) for r in got]):>15}  "
                + ",".join(f"{m}:{n}" for m, n in sorted(methods.items()))
            )
        print(f"{suite}: effects that bias K or Ra (reported, no bar)")
        for r in sorted(rest, key=lambda r: (r["effect"], r["source"])):
            ke = "-" if r["k"] is None else f"{100 * r['k']:+.2f}%"
            re = "-" if r["ra"] is None else f"{100 * r['ra']:+.2f}%"
            print(f"  {r['id']} {r['source']:20} {r['plan']:13} {r['effect']:18} K {ke:>8} Ra {re:>8}")


if __name__ == "__main__":
    main()
