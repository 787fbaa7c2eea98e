#!/usr/bin/env python3
"""Perturb blind-suite records the way real records go wrong, run
`motorbench identify` and `motorbench diagnose` on each, and count what no
user should see: a panic, an exit code other than a result (0), bad input
(2) or "nothing applies" (4), a report that `scripts/report_check.py`
faults (a `null` where a number belongs, which is how a NaN reaches the
JSON, or a value outside its physical range), a run longer than the bound
(identify 3 s, diagnose 30 s), a hang (120 s). Refusals are listed with
their message, so that each can be read for whether a user can act on
it. `report_check.py` checks the suites' records as they are; this
script, the same records gone wrong.

    scripts/robustness_sweep.py [--motorbench BIN] [--seed N] [--trials M]
                                [--only KIND] SUITE...

SUITE is a blind suite (`motorbench blind generate`, `scripts/blind-gem.sh`,
`scripts/blind-motulator.sh`), read through its `cases.json`: `dc_step`
cases get DC perturbations, `im_slip_sweep` cases IM ones.
Exit status 1 when any defect was found. Standard library only.
"""
import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from report_check import findings  # noqa: E402  (the checks of a report, shared)


def read(path):
    lines = open(path).read().splitlines()
    comments = [l for l in lines if l.startswith("#")]
    body = [l for l in lines if not l.startswith("#")]
    return comments, body[0], [l.split(",") for l in body[1:]]


def dc_perturb(kind, header, rows, segment, rng):
    """A DC segment as a real record may come: units, glitches, gaps."""
    c = header.split(",")
    it, iv, ii = c.index("time_s"), c.index("armature_voltage_V"), c.index("armature_current_A")
    iw = c.index(next(x for x in c if x.startswith("speed")))
    r = [list(x) for x in rows]
    scale = {"current_mA": (ii, 1000.0), "time_ms": (it, 1000.0), "speed_rpm": (iw, 30 / 3.141592653589793)}
    if kind in scale:
        col, f = scale[kind]
        for x in r:
            x[col] = repr(float(x[col]) * f)
    elif kind == "short":
        r = r[: max(3, len(r) // 50)]
    elif kind == "decimated":
        r = r[::20]
    elif kind == "speed_glitch":
        for _ in range(3):
            x = r[rng.randrange(len(r))]
            x[iw] = repr(float(x[iw]) * 50 + 1000)
    elif kind == "dropout":
        k = rng.randrange(len(r))
        r = r[:k] + r[k + len(r) // 10:]
    elif kind == "quantised":
        for x in r:
            x[ii] = repr(round(float(x[ii]) / 0.05) * 0.05)
            x[iw] = repr(float(round(float(x[iw]))))
    elif kind == "current_offset":
        for x in r:
            x[ii] = repr(float(x[ii]) + 0.3)
    elif kind == "time_jitter":
        for x in r:
            x[it] = repr(float(x[it]) + rng.uniform(-1e-5, 1e-5))
    elif kind == "flat_first_segment" and segment == 0:
        for x in r:
            x[iv] = r[0][iv]
    elif kind == "nan_cell":
        r[rng.randrange(len(r))][ii] = "nan"
    elif kind == "empty_cell":
        r[rng.randrange(len(r))][iw] = ""
    return r


def im_perturb(kind, header, rows, segment, rng):
    """An IM sweep (or a no-load or locked-rotor test beside it, which has
    no slip column) as a real record may come: units, scatter, slips."""
    c = header.split(",")
    ii, ip, iv = (c.index(k) for k in ("line_current_A", "input_power_W", "line_voltage_V"))
    isl = c.index("slip") if "slip" in c else None
    r = [list(x) for x in rows]
    if isl is None and kind in ("slip_error", "slip_not_measured"):
        return r
    if kind == "outlier":
        x = r[rng.randrange(len(r))]
        j = rng.choice([ii, ip])
        x[j] = repr(float(x[j]) * rng.choice([0.5, 1.5, 3.0]))
    elif kind == "scatter_5pct":
        for x in r:
            x[ii] = repr(float(x[ii]) * (1 + rng.gauss(0, 0.05)))
            x[ip] = repr(float(x[ip]) * (1 + rng.gauss(0, 0.05)))
    elif kind == "half_dropped":
        r = [x for x in r if rng.random() > 0.5] or r[:3]
    elif kind == "shuffled":
        rng.shuffle(r)
    elif kind == "slip_error":
        for x in r:
            x[isl] = repr(min(1.0, max(0.0, float(x[isl]) + rng.gauss(0, 0.002))))
    elif kind == "duplicated":
        r = r + r
    elif kind == "power_halved":
        for x in r:
            x[ip] = repr(float(x[ip]) * 0.5)
    elif kind == "slip_not_measured":
        for x in r:
            x[isl] = "0"
    elif kind == "power_kW":
        for x in r:
            x[ip] = repr(float(x[ip]) / 1000)
    elif kind == "phase_voltage":
        for x in r:
            x[iv] = repr(float(x[iv]) / 3 ** 0.5)
    elif kind == "four_points":
        r = r[:: max(1, len(r) // 4)][:4]
    return r


DC_KINDS = ["current_mA", "time_ms", "speed_rpm", "short", "decimated", "speed_glitch", "dropout",
            "quantised", "current_offset", "time_jitter", "flat_first_segment", "nan_cell", "empty_cell"]
IM_KINDS = ["outlier", "scatter_5pct", "half_dropped", "shuffled", "slip_error", "duplicated",
            "power_halved", "slip_not_measured", "power_kW", "phase_voltage", "four_points"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suites", nargs="+")
    ap.add_argument("--motorbench", default=os.path.join(os.path.dirname(__file__), "..", "target", "release", "motorbench"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--trials", type=int, default=60)
    ap.add_argument("--only", help="one perturbation kind")
    a = ap.parse_args()
    rng = random.Random(a.seed)
    cases = []
    for suite in a.suites:
        for case in json.load(open(os.path.join(suite, "cases.json")))["cases"]:
            if case["kind"] in ("dc_step", "im_slip_sweep"):
                cases.append((suite, case))
    if not cases:
        sys.exit("no blind cases in " + ", ".join(a.suites))
    work = tempfile.mkdtemp(prefix="robustness-")
    defects = refusals = results = 0
    for t in range(a.trials):
        suite, case = rng.choice(cases)
        dc = case["kind"] == "dc_step"
        kinds = DC_KINDS if dc else IM_KINDS
        kind = a.only or rng.choice(kinds)
        if kind not in kinds:
            continue
        perturb = dc_perturb if dc else im_perturb
        files = []
        for segment, f in enumerate(case["files"]):
            comments, header, rows = read(os.path.join(suite, f))
            rows = perturb(kind, header, rows, segment, rng)
            out = os.path.join(work, f"{t}-{os.path.basename(f)}")
            with open(out, "w") as fh:
                fh.write("\n".join(comments + [header] + [",".join(x) for x in rows]) + "\n")
            files.append(out)
        extra = ["--nameplate", os.path.join(suite, case["nameplate"])] if case.get("nameplate") else []
        for command, bound in (("identify", 3.0), ("diagnose", 30.0)):
            t0 = time.time()
            name = f"{t} {kind} {suite} {case['id']} {command}"
            try:
                p = subprocess.run([a.motorbench, command, "--kind", case["kind"], "--json", *extra, *files],
                                   capture_output=True, text=True, timeout=120)
            except subprocess.TimeoutExpired:
                print(f"DEFECT {name}: no answer in 120 s")
                defects += 1
                continue
            dt = time.time() - t0
            bad = []
            if p.returncode not in (0, 2, 4):
                bad.append(f"exit {p.returncode}")
            if "panicked" in p.stderr:
                bad.append("panic")
            if p.returncode == 0:
                try:
                    bad += findings(json.loads(p.stdout), "report")
                except ValueError:
                    bad.append("output is not JSON")
            if dt > bound:
                bad.append(f"{dt:.1f} s (bound {bound:.0f} s)")
            if bad:
                defects += 1
                print(f"DEFECT {name}: {', '.join(bad)}: {p.stderr.strip()[-300:]}")
            elif p.returncode != 0:
                refusals += 1
                print(f"refused {name} (exit {p.returncode}): {p.stderr.strip()[-300:]}")
            else:
                results += 1
    print(f"{a.trials} perturbed records, {2 * a.trials} runs: {results} results, {refusals} refusals, "
          f"{defects} defects")
    sys.exit(1 if defects else 0)


if __name__ == "__main__":
    main()
