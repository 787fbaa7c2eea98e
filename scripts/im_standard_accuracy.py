#!/usr/bin/env python3
"""The standard tests' circuit against a plant motorbench did not write.

For each seed and each plant effect (`none`, `iron_loss`,
`main_flux_saturation`, both), draws a machine as
`scripts/blind_motulator.py` does, simulates with motulator the four
standard tests a motor lab takes — a DC winding-resistance reading, a
no-load test at several voltages (the rotor free, slip not measured), a
locked-rotor test at reduced voltage and a load test at rated voltage —
reads them through meters, writes them as the contract's CSV files and
runs `motorbench identify --json` on them. Then compares the `joint` and
the `standard_tests` circuits with the plant's, element by element, and
prints a table per method and effect: the median and the largest relative
error, and how often the 95 % interval covers the truth.

The plan varies per case: 6-12 no-load voltages from 25-40 % up to
105-120 % of rated, 3-6 locked-rotor readings at 40-110 % of rated
current, 8-20 load points up to 1.2-1.8 times the rated slip, meters of
0.05-0.3 % (current, power) and 0.02-0.1 % (voltage) of reading, friction
and windage of 0.4-1.5 % of the rating, star or delta.

The plant's truth in the contract's T circuit (Xs = Xr) is the one of
`scripts/blind_motulator.py`'s docstring. With saturation, `Xm` is what
the noise-free no-load reading at rated voltage shows by the classical
formula `E²/(Q − I²·Xs)` (what both methods report), and
`Xm_unsaturated` the T circuit's unsaturated `Xm`, `saturation_exponent`
motulator's exponent `S` (the same curve's, on the stator flux). motulator's core loss
sits across the stator flux (the Γ circuit's node); its truth here is the
T circuit's `Rfe` across `E` that draws the same loss at no load.

    scripts/motulator-python.sh scripts/im_standard_accuracy.py \\
        [--seeds 1 2 3] [--bin target/release/motorbench] [--keep DIR]
"""

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blind_motulator as bm  # noqa: E402  (the plant, its machines and meters)
from motulator.drive.model import InductionMachinePars  # noqa: E402

EFFECTS = ["none", "iron_loss", "main_flux_saturation", "saturation_and_iron_loss"]
KEYS = ["Rs", "Xs", "Xr", "Rr", "Xm", "Xm_unsaturated", "saturation_exponent", "Rfe", "Pfw"]


def slip_for_torque(par, w, u, torque):
    """The slip below breakdown where the plant's torque is `torque`."""
    lo, hi = 0.0, 0.2
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if bm.phasor(par, w, u, mid)[2] < torque:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def make(seed, effect, out):
    rng = np.random.default_rng([seed, EFFECTS.index(effect)])
    mc = bm.draw_machine(rng)
    w = 2 * math.pi * mc["f"]
    u_rated = math.sqrt(2 / 3) * mc["line_v"]
    par = InductionMachinePars(n_p=mc["n_p"], R_s=mc["R_s"], R_r=mc["R_r"], L_ell=mc["L_ell"], L_s=mc["L_s"])
    nominal_par = InductionMachinePars(n_p=mc["n_p"], R_s=mc["R_s"], R_r=mc["R_r"], L_ell=mc["L_ell"], L_s=mc["L_s"])
    L_su = mc["L_s"]
    if effect in ("main_flux_saturation", "saturation_and_iron_loss"):
        drop, S = rng.uniform(0.08, 0.3), rng.uniform(5.0, 9.0)
        L_su = mc["L_s"] / (1 - drop)
        psi_half = u_rated / w / (drop / (1 - drop)) ** (1 / S)
        par.L_s = lambda psi: L_su / (1 + (psi / psi_half) ** S)
    if effect in ("iron_loss", "saturation_and_iron_loss"):
        par.G_c = rng.uniform(0.012, 0.035) * mc["power"] / (1.5 * u_rated**2)
    plant = bm.Plant(par, mc["f"])
    periods = int(rng.integers(5, 16))
    m_i = bm.Meter(bm.log_uniform(rng, 5e-4, 3e-3), 20000.0, None, 0.0)
    m_p = bm.Meter(bm.log_uniform(rng, 5e-4, 3e-3), 20000.0, None, 0.0)
    m_v = bm.Meter(bm.log_uniform(rng, 2e-4, 1e-3), 20000.0, None, 0.0)
    pfw = rng.uniform(0.004, 0.015) * mc["power"]
    t_fw = pfw / (w / mc["n_p"])

    def meter(v_frac, slip):
        u = u_rated * v_frac
        i, p, tau, _ = plant.operating_point(u, slip, periods, nominal_par)
        return m_v.read(rng, mc["line_v"] * v_frac), m_i.read(rng, i), m_p.read(rng, p), tau

    d = os.path.join(out, f"{effect}-{seed}")
    os.makedirs(d, exist_ok=True)
    f = mc["f"]
    # DC reading between two line terminals: 2·R_s of the star equivalent
    # for either connection.
    with open(f"{d}/dc.csv", "w") as fh:
        fh.write("# motorbench segment 0 kind=im_dc_resistance label=dc\ndc_voltage_V,dc_current_A\n")
        for c in (0.3, 0.5, 0.7):
            i = c * mc["line_i"]
            fh.write(f"{2 * mc['R_s'] * i * (1 + rng.normal(0, 5e-4)):.6g},{i * (1 + rng.normal(0, 5e-4)):.6g}\n")
    n_nl = int(rng.integers(6, 13))
    nl = np.linspace(rng.uniform(1.05, 1.2), rng.uniform(0.25, 0.4), n_nl)
    with open(f"{d}/no_load.csv", "w") as fh:
        fh.write("# motorbench segment 1 kind=im_no_load label=no load\n")
        fh.write("line_voltage_V,line_current_A,input_power_W,frequency_Hz\n")
        for k in nl:
            v, i, p, _ = meter(k, slip_for_torque(par, w, u_rated * k, t_fw))
            fh.write(f"{v:.6g},{i:.6g},{p:.6g},{f}\n")
    z1 = bm.phasor(par, w, u_rated, 1.0)[0]
    with open(f"{d}/locked.csv", "w") as fh:
        fh.write("# motorbench segment 2 kind=im_locked_rotor label=locked rotor\n")
        fh.write("line_voltage_V,line_current_A,input_power_W,frequency_Hz\n")
        for c in np.linspace(rng.uniform(0.4, 0.6), rng.uniform(0.9, 1.1), int(rng.integers(3, 7))):
            v, i, p, _ = meter(c * mc["line_i"] / z1, 1.0)
            fh.write(f"{v:.6g},{i:.6g},{p:.6g},{f}\n")
    s_rated = slip_for_torque(par, w, u_rated, mc["power"] / (w / mc["n_p"] * 0.97))
    with open(f"{d}/load.csv", "w") as fh:
        fh.write("# motorbench segment 3 kind=im_slip_sweep label=load\n")
        fh.write("slip,line_voltage_V,line_current_A,input_power_W,frequency_Hz\n")
        for s in np.linspace(0.1, rng.uniform(1.2, 1.8), int(rng.integers(8, 21))) * s_rated:
            v, i, p, _ = meter(1.0, s)
            fh.write(f"{s:.6g},{v:.6g},{i:.6g},{p:.6g},{f}\n")
    plate = {"power_W": round(mc["power"]), "voltage_V": mc["line_v"], "current_A": round(mc["line_i"], 1),
             "poles": mc["poles"], "frequency_Hz": f, "connection": mc["connection"]}
    with open(f"{d}/nameplate.json", "w") as fh:
        json.dump(plate, fh)

    # The truth, per phase of the winding as connected.
    k = 1.0 if mc["connection"] == "star" else 3.0
    L_ell = mc["L_ell"]
    L_m = L_su * math.sqrt(L_su / (L_su + L_ell))
    leak = L_su - L_m
    rs, xs = k * mc["R_s"], k * w * leak
    truth = {"Rs": rs, "Xs": xs, "Xr": xs, "Rr": k * mc["R_r"] * L_su / (L_su + L_ell),
             "Xm_unsaturated": k * w * L_m, "Pfw": pfw}
    if callable(par.L_s):
        truth["saturation_exponent"] = S
    if par.G_c:
        truth["Rfe"] = k / par.G_c * L_su / (L_su + L_ell)
    # Xm as the noise-free no-load reading at rated voltage shows it.
    i_pk, p, _, _ = bm.phasor(par, w, u_rated, slip_for_torque(par, w, u_rated, t_fw))
    v_ph = mc["line_v"] if k == 3.0 else mc["line_v"] / math.sqrt(3)
    i_ph = i_pk / math.sqrt(3) if k == 3.0 else i_pk
    p_ph = p / 3
    q_ph = math.sqrt(max((v_ph * i_ph) ** 2 - p_ph**2, 0.0))
    cur = complex(p_ph / v_ph, -q_ph / v_ph)
    e = v_ph - cur * complex(rs, xs)
    truth["Xm"] = abs(e) ** 2 / (q_ph - i_ph**2 * xs)
    return d, truth


def run(binary, d):
    files = [os.path.join(d, n) for n in ("dc.csv", "no_load.csv", "locked.csv", "load.csv")]
    out = subprocess.run([binary, "identify", "--kind", "im_slip_sweep", *files, "--nameplate",
                          os.path.join(d, "nameplate.json"), "--json"], capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"{d}: exit {out.returncode}: {out.stderr.strip()[-400:]}")
    return json.loads(out.stdout)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[1, 2, 3])
    ap.add_argument("--bin", default="target/release/motorbench")
    ap.add_argument("--keep", help="write the cases here (else a temporary folder)")
    args = ap.parse_args()
    out = args.keep or tempfile.mkdtemp(prefix="im-standard-")
    rows = []  # (effect, method, key, relative error, covered)
    cases = []  # (effect, saturation chosen, rms %)
    for seed in args.seeds:
        for effect in EFFECTS:
            try:
                d, truth = make(seed, effect, out)
            except RuntimeError as e:  # the plant, not motorbench
                print(f"{effect:26s} seed {seed}: skipped, motulator: {e}", file=sys.stderr)
                shutil.rmtree(os.path.join(out, f"{effect}-{seed}"), ignore_errors=True)
                continue
            report = run(args.bin, d)
            warnings = report.get("warnings", [])
            chosen = any("joint: Xm falls with the voltage" in w for w in warnings)
            rms = next((float(w.split("residual ")[1].split(" %")[0]) for w in warnings
                        if w.startswith("joint: rms relative residual")), float("nan"))
            at_bound = any("joint: Rs" in w and "sits at its bound" in w for w in warnings)
            print(f"{effect:26s} seed {seed}: best {report.get('best')}, joint saturation "
                  f"{'yes' if chosen else 'no'}, rms {rms:.3f} %{', Rs at a bound' if at_bound else ''}",
                  file=sys.stderr)
            cases.append((effect, chosen, rms))
            for method in ("joint", "standard_tests"):
                params = (report["methods"].get(method) or {}).get("params") or {}
                for key in KEYS:
                    if key not in truth or key not in params:
                        continue
                    if key == "Xm_unsaturated" and method != "joint":
                        continue
                    p = params[key]
                    err = p["value"] / truth[key] - 1.0
                    ci = p.get("ci95")
                    covered = ci is not None and ci[0] <= truth[key] <= ci[1]
                    rows.append((effect, method, key, err, covered))
    print(f"cases in {out}\n")
    print("| effect | method | element | median error | largest error | interval covers |")
    print("| --- | --- | --- | --- | --- | --- |")
    for effect in EFFECTS:
        for method in ("joint", "standard_tests"):
            for key in KEYS:
                sel = [r for r in rows if r[0] == effect and r[1] == method and r[2] == key]
                if not sel:
                    continue
                errs = [abs(r[3]) for r in sel]
                print(f"| {effect} | {method} | {key} | {100 * statistics.median(errs):.2f} % | "
                      f"{100 * max(errs):.2f} % | {sum(r[4] for r in sel)}/{len(sel)} |")
    print()
    for effect in EFFECTS:
        sel = [c for c in cases if c[0] == effect]
        picked = sum(1 for c in sel if c[1])
        print(f"{effect}: joint took the saturation curve in {picked} of {len(sel)} cases; "
              f"rms residual {', '.join(f'{c[2]:.3f}' for c in sorted(sel, key=lambda c: c[2]))} %")


if __name__ == "__main__":
    main()
