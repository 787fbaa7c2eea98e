#!/usr/bin/env python3
"""A current sensor with an offset: take every `dc_step` case of blind
suites, add a share of its largest current reading to every current
reading (a Hall sensor's zero), and see what `motorbench identify` says of
the record as it is and with the offset: whether it warns that the
voltage equation leaves a constant, and K of the best method and of the
warning (the fit that takes the constant up) against the suite's truth.

    scripts/current_offset.py [--motorbench BIN] [--share 0.03] SUITE...

SUITE is a blind suite (`motorbench blind generate`, `scripts/blind-gem.sh`)
with its `truth.json`. Prints one line per case and a summary per suite
and effect; the figures docs/identification-dc.md quotes. Standard library
only.
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import tempfile

SAID = "current reading offset by about"


def identify(mb, files):
    """(best K, the warning's K or None), or None where identify fails."""
    try:
        d = json.loads(subprocess.run([mb, "identify", "--kind", "dc_step", "--json"] + files,
                                      capture_output=True, text=True, timeout=300).stdout)
        best = d["methods"][d["best"]]["params"]["K"]["value"]
    except (ValueError, KeyError, TypeError, subprocess.TimeoutExpired):
        return None
    warned = [w for w in d["warnings"] if SAID in w]
    k = float(re.search(r"K = (\S+)", warned[0]).group(1)) if warned else None
    return best, k


def shifted(src, dst, offset):
    """`src` with `offset` added to its armature_current_A column."""
    column = None
    with open(src) as f, open(dst, "w") as g:
        for line in f:
            if line.startswith("#"):
                g.write(line)
                continue
            cells = line.rstrip("\n").split(",")
            if column is None:
                column = cells.index("armature_current_A")
            else:
                cells[column] = repr(float(cells[column]) + offset)
            g.write(",".join(cells) + "\n")


def peak_current(files):
    peak, column = 0.0, None
    for path in files:
        column = None
        with open(path) as f:
            for line in f:
                if line.startswith("#"):
                    continue
                cells = line.rstrip("\n").split(",")
                if column is None:
                    column = cells.index("armature_current_A")
                else:
                    peak = max(peak, abs(float(cells[column])))
    return peak


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motorbench", default=os.path.join(here, "..", "target", "release", "motorbench"))
    ap.add_argument("--share", type=float, default=0.03, help="offset as a share of the largest current")
    ap.add_argument("suites", nargs="+")
    a = ap.parse_args()
    for suite in a.suites:
        cases = json.load(open(os.path.join(suite, "cases.json")))["cases"]
        truth = dict(json.load(open(os.path.join(suite, "truth.json")))["cases"])
        tally = {}
        for case in cases:
            if case["kind"] != "dc_step":
                continue
            t = truth[case["id"]]
            files = [os.path.join(suite, f) for f in case["files"]]
            offset = a.share * peak_current(files)
            with tempfile.TemporaryDirectory() as tmp:
                moved = []
                for f in files:
                    moved.append(os.path.join(tmp, os.path.basename(f)))
                    shifted(f, moved[-1], offset)
                before, after = identify(a.motorbench, files), identify(a.motorbench, moved)
            k = t["nominal"]["K"]
            err = lambda v: None if v is None else 100 * (v / k - 1)
            row = tally.setdefault(t["effect"], {"n": 0, "clean_warned": 0, "warned": 0, "best": [], "taken_up": []})
            row["n"] += 1
            line = f"{os.path.basename(suite)} {case['id']} {t['effect']}"
            if before is None or after is None:
                print(line, "identify failed")
                continue
            row["clean_warned"] += before[1] is not None
            row["warned"] += after[1] is not None
            row["best"].append(abs(err(after[0])))
            if after[1] is not None:
                row["taken_up"].append(abs(err(after[1])))
            print(f"{line} clean_warned={before[1] is not None} warned={after[1] is not None} "
                  f"K_best={err(after[0]):+.2f}% K_taken_up="
                  + ("-" if after[1] is None else f"{err(after[1]):+.2f}%"))
        print(f"summary {os.path.basename(suite)} share={a.share}")
        for effect, r in sorted(tally.items()):
            med = lambda v: f"{statistics.median(v):.2f}%" if v else "-"
            print(f"  {effect:22s} cases {r['n']:2d}  warned clean {r['clean_warned']:2d}  "
                  f"warned offset {r['warned']:2d}  median |K| error best {med(r['best'])}  "
                  f"taken up {med(r['taken_up'])}")


if __name__ == "__main__":
    main()
