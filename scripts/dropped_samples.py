#!/usr/bin/env python3
"""A logger that drops samples: take every `dc_step` case of blind suites,
drop a share of its samples at random (one at a time, so that a few drops
fall side by side as they do on a real link), and compare what `motorbench
identify` and `motorbench diagnose` say of the dropped record with what
they say of the whole one: the diagnosis's verdict (right against the
suite's truth), the best method, and its K and Ra against the truth.

    scripts/dropped_samples.py [--motorbench BIN] [--share 0.02] [--seed 7]
                               SUITE...

SUITE is a blind suite (`motorbench blind generate`, `scripts/blind-gem.sh`)
with its `truth.json`. Prints one line per case and a summary per suite;
the figures docs/identification-dc.md quotes. Standard library only.
"""
import argparse
import json
import os
import random
import statistics
import subprocess
import tempfile


def run(mb, files):
    """identify's best K and Ra and diagnose's verdict, or what failed."""
    out = {}
    try:
        d = json.loads(subprocess.run([mb, "identify", "--kind", "dc_step", "--json"] + files,
                                      capture_output=True, text=True, timeout=300).stdout)
        p = d["methods"][d["best"]]["params"]
        out.update(best=d["best"], K=p["K"]["value"], Ra=p["Ra"]["value"])
    except (ValueError, KeyError, TypeError, subprocess.TimeoutExpired):
        out["best"] = None
    try:
        d = json.loads(subprocess.run([mb, "diagnose", "--kind", "dc_step", "--json"] + files,
                                      capture_output=True, text=True, timeout=300).stdout)
        out["verdict"] = d["verdict"]["effect"]
    except (ValueError, KeyError, TypeError, subprocess.TimeoutExpired):
        out["verdict"] = None
    return out


def drop(src, dst, share, rng):
    """`src` with each data row after the first two dropped at `share`."""
    rows = 0
    with open(src) as f, open(dst, "w") as g:
        for line in f:
            if not line.startswith("#"):
                rows += 1
                if rows > 3 and rng.random() < share:
                    continue
            g.write(line)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motorbench", default=os.path.join(here, "..", "target", "release", "motorbench"))
    ap.add_argument("--share", type=float, default=0.02, help="share of the samples dropped")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("suites", nargs="+")
    a = ap.parse_args()
    for suite in a.suites:
        rng = random.Random(a.seed)
        cases = json.load(open(os.path.join(suite, "cases.json")))
        cases = cases if isinstance(cases, list) else cases["cases"]
        truth = dict((k, v) for k, v in json.load(open(os.path.join(suite, "truth.json")))["cases"])
        tally = {"cases": 0, "whole": 0, "dropped": 0, "same": 0}
        dk, dra = [], []
        with tempfile.TemporaryDirectory() as tmp:
            for c in (c for c in cases if c["kind"] == "dc_step"):
                files = [os.path.join(suite, f) for f in c["files"]]
                dropped = []
                for f in files:
                    dst = os.path.join(tmp, c["id"] + "-" + os.path.basename(f))
                    drop(f, dst, a.share, rng)
                    dropped.append(dst)
                t = truth[c["id"]]
                whole, cut = run(a.motorbench, files), run(a.motorbench, dropped)
                tally["cases"] += 1
                tally["whole"] += whole["verdict"] == t["effect"]
                tally["dropped"] += cut["verdict"] == t["effect"]
                tally["same"] += whole["verdict"] == cut["verdict"]
                err = lambda r, k: 100 * (r[k] / t["nominal"][k] - 1) if k in r else float("nan")
                if "K" in whole and "K" in cut:
                    dk.append(abs(err(cut, "K") - err(whole, "K")))
                    dra.append(abs(err(cut, "Ra") - err(whole, "Ra")))
                print(f"{c['id']:8} {t['effect']:22} whole {str(whole['verdict']):22} {str(whole['best']):15} "
                      f"K {err(whole, 'K'):+7.2f}% Ra {err(whole, 'Ra'):+7.2f}% | dropped "
                      f"{str(cut['verdict']):22} {str(cut['best']):15} K {err(cut, 'K'):+7.2f}% "
                      f"Ra {err(cut, 'Ra'):+7.2f}%", flush=True)
        med = lambda v: statistics.median(v) if v else float("nan")
        print(f"{suite}: {tally['cases']} DC cases, {a.share:.0%} of the samples dropped: verdicts right "
              f"{tally['whole']} whole, {tally['dropped']} dropped, {tally['same']} the same; "
              f"K and Ra moved by a median {med(dk):.3f} % and {med(dra):.3f} % "
              f"(largest {max(dk, default=float('nan')):.2f} % and {max(dra, default=float('nan')):.2f} %)")


if __name__ == "__main__":
    main()
