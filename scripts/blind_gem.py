#!/usr/bin/env python3
"""Blind DC cases from a plant motorbench did not write: gym-electric-motor.

Adds cases to a blind suite directory made by `motorbench blind generate`
(or a new one): the record as contract CSV files under cases/gem-NN/, the
case in cases.json, the truth in truth.json, in the suite's own format
(src/diagnose/blind/suite.rs and files.rs). `motorbench blind score DIR`
then scores them with the rest and lists them as source
`gym-electric-motor`.

The plant is gem's DcPermanentlyExcitedMotor on a PolynomialStaticLoad,
fed by gem's ContFourQuadrantConverter from an IdealVoltageSupply, solved
by gem's ScipyOdeSolver (dopri5) at gem's step of 0.1 ms:

    l_a di/dt = u - r_a i - psi_e w          T = psi_e i
    (j_rotor + j_load) dw/dt = T - (a sign(w) + b w + c sign(w) w^2)

so the contract's parameters are K = psi_e, Ra = r_a, La = l_a,
J = j_rotor + j_load, f = b, Tst = a (c = 0 here). The converter's
interlocking time t_il lowers its output by 2 u_sup t_il / tau sign(i)
(two half bridges, each by t_il/tau of the supply). A drive logs the
voltage it commands, so that drop never reaches the record: the effect is
a voltage drop that follows the current's sign, which the contract names
`brush_drop` (Vb = 2 u_sup t_il / tau, i0 -> 0). With t_il = 0 the
record is the nominal model: truth `none`.

Readings: the command (ADC), the current through a 1-20 kHz sensor
(first order, at most 3 % of tau_e so that it is no sensor lag), and the
speed from a 100-10 000-line encoder or a filtered tachometer, with
10-16-bit ADCs. Plans: a staircase (holds 2-12 time constants), ramps,
a PRBS, or a PI speed loop whose output is the voltage; every record ends
with a 0 V short (the converter's zero vector), a braking step.
"""

import argparse
import json
import math
import os
import sys

import numpy as np

from blind_suite import Suite

import gym_electric_motor.physical_systems as ps
from gym_electric_motor.physical_systems.converters import ContFourQuadrantConverter
from gym_electric_motor.physical_systems.electric_motors import DcPermanentlyExcitedMotor
from gym_electric_motor.physical_systems.mechanical_loads import PolynomialStaticLoad
from gym_electric_motor.physical_systems.solvers import ScipyOdeSolver
from gym_electric_motor.physical_systems.voltage_supplies import IdealVoltageSupply

SOURCE = "gym-electric-motor"
DT = 5e-4  # record sample interval (2 kHz)
TAU = 1e-4  # gem's step (10 kHz PWM period)
SUB = int(round(DT / TAU))
PLANS = ["staircase", "ramp", "prbs", "speed_loop"]

# Families: gem's default PM motor (60 V, 97 A) and two smaller ones.
FAMILIES = [
    dict(r_a=16e-3, l_a=19e-6, psi_e=0.165, j_rotor=0.025, u=60.0, i=97.0, a=0.2, b=2e-3),
    dict(r_a=1.0, l_a=2e-3, psi_e=0.05, j_rotor=3e-5, u=24.0, i=4.0, a=4e-3, b=1e-5),
    dict(r_a=0.5, l_a=1e-3, psi_e=0.11, j_rotor=3e-4, u=48.0, i=10.0, a=0.015, b=4e-5),
]


def log_uniform(rng, lo, hi):
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


def draw_motor(rng):
    fam = FAMILIES[rng.integers(len(FAMILIES))]
    m = {k: fam[k] * math.exp(rng.uniform(-0.3, 0.3)) for k in ("r_a", "psi_e", "j_rotor", "a", "b")}
    j = m["j_rotor"] * (1.0 + rng.uniform(0.0, 1.0))  # rotor plus load
    tau_m = m["r_a"] * j / (m["psi_e"] ** 2 + m["r_a"] * m["b"])
    zeta = rng.uniform(0.25, 0.9) if rng.random() < 0.5 else log_uniform(rng, 1.2, 4.0)
    tau_e = min(max(tau_m / (4.0 * zeta * zeta), 2 * TAU), 0.2)
    m["l_a"] = m["r_a"] * tau_e
    m["j_load"] = j - m["j_rotor"]
    m["u_sup"] = fam["u"] * (m["psi_e"] / fam["psi_e"]) / 0.8
    m["i_rated"] = fam["i"]
    return m


def slowest_tau(m):
    j = m["j_rotor"] + m["j_load"]
    tm = m["r_a"] * j / (m["psi_e"] ** 2 + m["r_a"] * m["b"])
    te = m["l_a"] / m["r_a"]
    disc = tm * tm - 4 * tm * te
    return (2 * te if disc < 0 else 2 * tm * te / (tm - math.sqrt(disc))), tm, te


class DeadTimeFourQuadrantConverter(ContFourQuadrantConverter):
    """gem's continuous 4QC with each half bridge discounted by its own current.

    gem 3.0.3's ContFourQuadrantConverter passes the motor current to both
    of its half bridges; the second one carries the opposite current, so
    their interlocking discounts (each t_il/tau sign(i)) cancel and the
    record holds no drop at all (measured: the steady levels of every
    interlocking case balance u = Ra i + K w to within the noise). Here the
    second half bridge sees -i, as the bridge's own i_sup already does, and
    the output loses 2 t_il/tau sign(i) of the supply.
    """

    def convert(self, i_out, t):
        return [self._subconverters[0].convert(i_out, t)[0] - self._subconverters[1].convert([-i_out[0]], t)[0]]


def build_system(m, t_il):
    motor = DcPermanentlyExcitedMotor(
        motor_parameter=dict(r_a=m["r_a"], l_a=m["l_a"], psi_e=m["psi_e"], j_rotor=m["j_rotor"]),
        nominal_values=dict(omega=1e4, torque=1e4, i=1e5, u=m["u_sup"]),
        limit_values=dict(omega=1e4, torque=1e4, i=1e5, u=m["u_sup"]),
    )
    load = PolynomialStaticLoad(
        load_parameter=dict(a=m["a"], b=m["b"], c=0.0, j_load=m["j_load"]),
        limits=dict(omega=1e4),
    )
    system = ps.DcMotorSystem(
        converter=DeadTimeFourQuadrantConverter(tau=TAU, interlocking_time=t_il),
        motor=motor,
        load=load,
        supply=IdealVoltageSupply(m["u_sup"]),
        ode_solver=ScipyOdeSolver(),
        tau=TAU,
    )
    system.reset()
    return system


def levels(rng, top):
    while True:
        lv = [top * rng.uniform(*((0.2, 0.5) if n == 0 else (0.7, 1.0) if n == 4 else (0.2, 1.0))) for n in range(5)]
        apart = all(0.15 <= abs(b - a) / top <= 0.6 for a, b in zip(lv, lv[1:]))
        if apart and any(b < a for a, b in zip(lv, lv[1:])):
            return lv


def simulate(rng, m, plan, t_il, hold, sensors):
    """Run the plan on gem; returns segments of (label, [(t, u_cmd, i, i_sensed, w_mean, theta)])."""
    system = build_system(m, t_il)
    names = system.state_names
    i_idx, w_idx = names.index("i"), names.index("omega")
    u_sup = m["u_sup"]
    top = 0.8 * u_sup
    lv = levels(rng, top)
    n_hold = max(int(round(hold / DT)), 40)
    _, tm, te = slowest_tau(m)
    # PI speed loop from the datasheet values (within ±30 %): bandwidth gain/τm.
    gain = rng.uniform(1.5, 4.0)
    k_d, r_d, j_d = (m[k] * math.exp(rng.uniform(-0.3, 0.3)) for k in ("psi_e", "r_a", "j_rotor"))
    j_d *= 1.0 + m["j_load"] / m["j_rotor"]
    kp = gain / tm * r_d * j_d / k_d
    ki = kp / tm
    drives = []
    prev = 0.0
    if plan == "staircase":
        drives = [("level", l) for l in lv]
    elif plan == "ramp":
        share = rng.uniform(0.5, 1.0)
        for l in lv:
            drives.append(("ramp", (prev, l, max(int(n_hold * share), 1))))
            prev = l
    elif plan == "prbs":
        bit = max(n_hold // 5, 2)
        for l in lv[1:]:
            hi = max(l, 0.3 * top)
            bits = rng.random(n_hold // bit + 1) < 0.5
            drives.append(("prbs", (hi - 0.25 * top, hi, bits, bit)))
    else:
        drives = [("speed", 0.9 * l / m["psi_e"]) for l in lv]
    drives.append(("short", 0.0))

    state = dict(i=0.0, w=0.0, theta=0.0, i_f=0.0, w_f=0.0, integ=0.0, feedback=0.0, count=0.0)
    tau_i = sensors["current_tau"]
    tau_w = sensors.get("tach_tau")
    q_theta = sensors.get("q_theta")

    def filt(y, x0, x1, tau, h):
        # First order, exact for an input linear over the step.
        if tau is None:
            return x1
        a = math.exp(-h / tau)
        s = (x1 - x0) / h
        return x1 - s * tau + (y - x0 + s * tau) * a

    segments = []
    t = 0.0
    label_prev = "0 V"
    for kind, arg in drives:
        if kind == "short":
            j = m["j_rotor"] + m["j_load"]
            f = m["b"] + m["psi_e"] ** 2 / m["r_a"]
            w0 = max(state["w"], 1e-9)
            t_stop = j / f * math.log(1 + w0 * f / m["a"])
            n = int(round(min(t_stop + 0.2, 8.0) / DT))
            this = "0 V short"
        else:
            n = n_hold
            this = {
                "level": lambda: f"{arg:.1f} V",
                "ramp": lambda: f"ramp to {arg[1]:.1f} V",
                "prbs": lambda: f"PRBS {arg[0]:.1f}/{arg[1]:.1f} V",
                "speed": lambda: f"speed loop to {arg:.1f} rad/s",
            }[kind]()
        rows = []
        if segments:
            rows.append(segments[-1][1][-1])
        applied = state.get("applied", 0.0)
        for step in range(n):
            if kind == "level":
                u = arg
            elif kind == "ramp":
                a0, a1, ns = arg
                u = a0 + (a1 - a0) * min((step + 1) / ns, 1.0)
            elif kind == "prbs":
                lo, hi, bits, bit = arg
                u = hi if bits[step // bit] else lo
            elif kind == "speed":
                e = arg - state["feedback"]
                free = kp * e + ki * state["integ"]
                if abs(free) < 0.9 * u_sup or np.sign(free) != np.sign(e):
                    state["integ"] += e * DT
                u = min(max(kp * e + ki * state["integ"], -0.9 * u_sup), 0.9 * u_sup)
            else:
                u = 0.0
            applied = u
            theta0 = state["theta"]
            for _ in range(SUB):
                i0, w0 = state["i"], state["w"]
                x = system.simulate(np.array([u / u_sup]))
                i1 = float(x[i_idx] * system.limits[i_idx])
                w1 = float(x[w_idx] * system.limits[w_idx])
                state["theta"] += 0.5 * (w0 + w1) * TAU
                state["i_f"] = filt(state["i_f"], i0, i1, tau_i, TAU)
                state["w_f"] = filt(state["w_f"], w0, w1, tau_w, TAU) if tau_w else w1
                state["i"], state["w"] = i1, w1
            t += DT
            w_mean = (state["theta"] - theta0) / DT
            if q_theta:
                count = math.floor(state["theta"] / q_theta)
                state["feedback"] = (count - state["count"]) * q_theta / DT
                state["count"] = count
            elif tau_w:
                state["feedback"] = state["w_f"]
            else:
                state["feedback"] = w_mean
            rows.append((t, applied, state["i"], state["i_f"], w_mean, state["w_f"], state["theta"]))
        state["applied"] = applied
        segments.append((f"{label_prev} → {this}", rows))
        label_prev = this
    return segments


def nrmse(measured, clean):
    y = np.asarray(measured)
    c = np.asarray(clean)
    spread = np.sum((y - y.mean()) ** 2)
    return math.sqrt(np.sum((y - c) ** 2) / spread) if spread > 0 else 0.0


def make_case(rng, effect, plan):
    m = draw_motor(rng)
    tau_slow, tm, te = slowest_tau(m)
    hold_tau = log_uniform(rng, 2.0, 12.0)
    hold = min(max(hold_tau * tau_slow, 0.05), 1.5)
    bits = int(rng.integers(10, 17))
    adc = 2.0**bits
    bw = log_uniform(rng, 1e3, 2e4)
    current_tau = min(1.0 / (2 * math.pi * bw), 0.03 * te)
    sensors = dict(current_tau=current_tau)
    if rng.random() < 0.7:
        lines = round(log_uniform(rng, 100.0, 1e4))
        sensors["q_theta"] = 2 * math.pi / (4 * lines)
    else:
        sensors["tach_tau"] = min(log_uniform(rng, 1e-4, 1e-3), 0.01 * tm)
    t_il = 0.0
    effect_params = {}
    regions = []
    if effect == "brush_drop":
        # 1-4 % of the supply: 0.5-2 % of the PWM period per half bridge.
        t_il = TAU * rng.uniform(0.005, 0.02)
        vb = 2 * m["u_sup"] * t_il / TAU
        effect_params = {"Vb": vb, "i0": 0.0, "interlocking_time_s": t_il}
        regions = ["settled", "transient", "start_up"]
    segments = simulate(rng, m, plan, t_il, hold, sensors)

    u_sup = m["u_sup"]
    sigma_u = u_sup * rng.uniform(0.0005, 0.003)
    q_u = 1.5 * u_sup / adc
    amps = m["i_rated"]
    sigma_i = amps * rng.uniform(0.002, 0.01)
    q_i = 4.0 * amps / adc * rng.uniform(0.5, 2.0)
    w_top = max(r[4] for _, rows in segments for r in rows)
    sigma_w = w_top * rng.uniform(0.001, 0.005) if "tach_tau" in sensors else 0.0
    q_w = 1.5 * w_top / adc
    quant = lambda v, q: round(v / q) * q

    out = []
    floors = []
    last_count = 0.0
    for n, (label, rows) in enumerate(segments):
        seg = []
        clean_i, clean_w = [], []
        for k, (t, u, i, i_f, w_mean, w_f, theta) in enumerate(rows):
            if n > 0 and k == 0:
                seg.append(out[-1][1][-1])
                clean_i.append(out[-1][2][-1])
                clean_w.append(out[-1][3][-1])
                continue
            if "q_theta" in sensors:
                q = sensors["q_theta"]
                count = math.floor(theta / q)
                w_read = (count - last_count) * q / DT
                last_count = count
                w_clean = w_mean
            else:
                w_read = quant(w_f + rng.normal(0, sigma_w), q_w)
                w_clean = w_f
            seg.append((t, quant(u + rng.normal(0, sigma_u), q_u), quant(i_f + rng.normal(0, sigma_i), q_i), w_read))
            clean_i.append(i_f)
            clean_w.append(w_clean)
        floors.append(0.5 * (nrmse([r[2] for r in seg], clean_i) + nrmse([r[3] for r in seg], clean_w)))
        out.append((label, seg, clean_i, clean_w))
    truth = {
        "effect": effect,
        "effect_params": effect_params,
        "nominal": {
            "Ra": m["r_a"],
            "La": m["l_a"],
            "K": m["psi_e"],
            "J": m["j_rotor"] + m["j_load"],
            "f": m["b"],
            "Tst": m["a"],
        },
        "noise": {"armature_voltage": sigma_u, "armature_current": sigma_i, "speed": sigma_w},
        "quantisation": {
            "armature_voltage": q_u,
            "armature_current": q_i,
            "speed": sensors["q_theta"] / DT if "q_theta" in sensors else q_w,
        },
        "noise_floor": float(np.mean(floors)),
        "regions": regions,
        "source": SOURCE,
        "plan": plan,
        "setup": {
            "hold_s": hold,
            "hold_tau": hold / tau_slow,
            "zeta": 0.5 * math.sqrt(tm / te),
            "adc_bits": float(bits),
            "coast_short": 1.0,
            "current_bw_hz": 1.0 / (2 * math.pi * current_tau),
            **({"encoder_lines": 2 * math.pi / (4 * sensors["q_theta"])} if "q_theta" in sensors else {"tach_tau_s": sensors["tach_tau"]}),
            "gem_psi_e": m["psi_e"],
            "gem_interlocking_time_s": t_il,
            "gem_j_load": m["j_load"],
        },
    }
    return out, truth


def write_case(suite, cid, segs):
    rel = os.path.join("cases", cid)
    os.makedirs(os.path.join(suite, rel), exist_ok=False)
    files = []
    for n, (label, seg, _, _) in enumerate(segs):
        name = os.path.join(rel, f"segment-{n}.csv")
        with open(os.path.join(suite, name), "w") as f:
            f.write(f"# motorbench segment {n} kind=dc_step label={label}\n")
            f.write("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n")
            for t, u, i, w in seg:
                f.write(f"{t!r},{u!r},{i!r},{w!r}\n")
        files.append(name)
    return {"id": cid, "kind": "dc_step", "files": files, "nameplate": None}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="the suite directory (created, or added to)")
    ap.add_argument("--seed", type=int, default=20261121)
    ap.add_argument("--cases", type=int, default=15, help="gem cases to add")
    args = ap.parse_args()
    suite = Suite(args.out, args.seed, "gem-", "gem")
    rng = np.random.default_rng(args.seed)
    # Three fifths none, the rest the converter's interlocking (brush_drop).
    effects = ["none" if n % 5 < 3 else "brush_drop" for n in range(args.cases)]
    rng.shuffle(effects)
    for n, effect in enumerate(effects):
        cid = f"gem-{n + 1:02}"
        plan = PLANS[n % len(PLANS)]
        case_rng = np.random.default_rng([args.seed, n])
        segs, t = make_case(case_rng, effect, plan)
        suite.add(write_case(args.out, cid, segs), t)
        print(f"{cid}: {plan} {effect}", file=sys.stderr)
    suite.save()
    print(f"{len(effects)} gym-electric-motor cases added to {args.out}")


if __name__ == "__main__":
    main()
