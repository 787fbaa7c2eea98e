#!/usr/bin/env python3
"""Blind IM cases from a plant motorbench did not write: motulator.

Adds `im_slip_sweep` cases to a blind suite directory made by `motorbench
blind generate` (or a new one): each record as contract CSV files under
cases/mot-NN/ with its nameplate, the case in cases.json, the truth in
truth.json, in the suite's own format (src/diagnose/blind/suite.rs and
files.rs). `motorbench blind score DIR` then scores them with the rest and
lists them as source `motulator`.

The plant
---------
motulator's `InductionMachine`: the Γ-equivalent model in stationary
coordinates, peak-valued space vectors, per phase of the star-equivalent
machine, fluxes as states:

    dpsi_s/dt = u_s - R_s i_s
    dpsi_r/dt = -R_r i_r + j n_p w_M psi_r
    i_r = (psi_r - psi_s)/L_ell,  i_m = psi_s/L_s(|psi_s|) - i_r
    i_s = (i_m + G_c u_s)/(1 + G_c R_s)

interconnected by motulator's own `System` with its `ExternalRotorSpeed`
(the dynamometer holds the speed: a stiff, speed-controlled load) and a
sinusoidal, balanced voltage source (a small subsystem here: the grid, not
an inverter, so no PWM), integrated by scipy's `solve_ivp` (DOP853,
rtol 1e-10), the integrator motulator's own `Simulation` calls.

Each operating point starts from the steady state of the nominal machine
(no saturation, no core loss: what is known before the test) with the rotor
held at its speed, and is simulated in blocks of four whole periods until
four consecutive periods' mean power and rms current each agree with the
period before within 1e-9 (relative): the plant's own effect settles
through motulator's dynamics, and the transient is skipped. Then the meter
averages over a whole number of periods (5-25, drawn per case), sampled at
200 points per period: the rms of each phase current (the mean over the
three phases), the three-phase power sum(u_k i_k), the shaft torque (with a
torque sensor). The result is checked against the phasor steady state of
the same Γ model, solved here (the time domain must agree within 1e-6);
that phasor solution is used for nothing else but the noise floor below.

Effects (only what motulator simulates itself):

- `none`: constant L_s and G_c = 0 (motulator's linear model);
- `main_flux_saturation`: L_s(psi) = L_su/(1 + (psi/psi_half)^S), the form of
  motulator's saturated-machine examples; S 5-9, L_s 8-30 % below L_su at
  the rated stator flux. Plans always hold a second supply voltage;
- `iron_loss`: motulator's core-loss conductance G_c in parallel with the
  magnetising branch (across u_s - R_s i_s), 1.2-3.5 % of the rating at
  rated voltage.

Truth parameters, the contract's convention
--------------------------------------------
The contract's nominal circuit is the T circuit per phase of the winding as
connected, in ohm at the test frequency, leakage split Xs = Xr (motorbench's
convention; a sweep cannot split it). Without saturation the Γ model and the
T model with any leakage split have the same terminal behaviour. With
Γ parameters (R_s, R_r, L_ell, L_s) of the star equivalent and the equal
split L_ss = L_rs = l (T model: L_s = L_m + l, L_r = L_m + l):

    L_m = L_s sqrt(L_s/(L_s + L_ell)),   l = L_s - L_m
    R_r(T) = R_r (L_m/L_s)^2 = R_r L_s/(L_s + L_ell)

(from the Γ transform gamma = L_m/L_s: L_ell = (L_s L_r - L_m^2) L_s/L_m^2,
R_r(Γ) = R_r(T)/gamma^2), then Xs = Xr = w l, Xm = w L_m, Rs = R_s,
Rr = R_r(T), each times k = 1 for a star winding and k = 3 for delta (a
delta phase carries line voltage and line current/sqrt(3): its impedance is
three times the star equivalent's). With saturation the nominal circuit is
the unsaturated one (L_s = L_su), as the own generator declares it. The core
loss is given as the Γ model's Rfe = k/G_c, and as the T circuit's Rfe
across E that draws the same loss at no load, k/G_c * L_s/(L_s + L_ell).

Plans and meters
----------------
A rating 0.75-45 kW (log-uniform), 2-8 poles, 50 Hz at 400/230/690 V or
60 Hz at 460/230/575 V, star or delta; inverse-Γ per-unit elements drawn
(r_s 0.01-0.06, r_R 0.01-0.05 falling with size; l_sigma 0.12-0.25;
l_M 1.6-4.0) and converted by motulator's own `from_inv_gamma_pars`.
Plans: `sweep` (quadratic spacing to locked rotor), `log-sweep` (log
spacing to locked rotor) or `load-curve` (linear spacing to a slip of
0.25-0.7, stopping short of locked rotor), 12-45 points, the lowest slip
0.001-0.015, ascending or descending, one to three supply voltages (rated,
then 55-90 % of the previous; saturation cases two or three). Slip from
the speed as read (0.01 rpm). Meters: noise of 0.03-0.5 % of reading
on current, 0.05-1 % on power, 0.02-0.2 % on voltage, plus 0-0.05 % of the
range; autoranging (the decade above the reading) or a fixed range per sweep
(1-2-5 above the sweep's largest value), 4000, 20 000 or 200 000 counts;
the supply wanders 0.05-0.2 % from point to point. Some cases carry a
torque sensor (0.1-0.3 % of its range).

`truth.noise_floor` is the NRMSE of the readings against the true plant at
the voltage and slip as read (the contract's y-hat takes the measured
input), mean over line current and input power; the plant's value at the
read input is the simulated value times the ratio of the phasor steady
states at the read and the true input.
"""

import argparse
import json
import math
import os
import sys
import time
from types import SimpleNamespace

import numpy as np
from scipy.integrate import solve_ivp

from blind_suite import Suite

from importlib.metadata import version

from motulator.common.model._base import System
from motulator.common.utils._utils import complex2abc
from motulator.drive.model import (
    ExternalRotorSpeed,
    InductionMachine,
    InductionMachineInvGammaPars,
    InductionMachinePars,
)

SOURCE = "motulator"
VERSION = version("motulator")
SAMPLES = 200  # meter samples per period
SETTLE_TOL = 1e-9
CHECK_TOL = 1e-6
MAX_PERIODS = 600
PLANS = ["sweep", "log-sweep", "load-curve"]


def log_uniform(rng, lo, hi):
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


# %% The supply: a balanced sinusoidal voltage source as a motulator subsystem.
class SineSource:
    """Ideal three-phase sinusoidal source, u = U exp(j w t) (peak phase)."""

    def __init__(self, amplitude, w):
        self.inp = None
        self.state = None
        self.amplitude = amplitude
        self.w = w
        self.out = SimpleNamespace(u_c_ab=complex(amplitude))
        self._history = {}

    def set_states(self, state_list, index):
        return index

    def set_outputs(self, t):
        self.out.u_c_ab = self.amplitude * np.exp(1j * self.w * t)

    def rhs(self, t):
        return []

    def init_state_history(self):
        self._history = {}

    def extend_state_history(self, sol_y, index):
        return index


class Plant:
    """motulator's induction machine on a sinusoidal supply at a held speed."""

    def __init__(self, par, f):
        self.par = par
        self.w = 2 * math.pi * f
        self.machine = InductionMachine(par)
        self.mech = ExternalRotorSpeed()
        self.source = SineSource(0.0, self.w)
        m, s, src = self.machine, self.mech, self.source
        self.system = System(
            [src, m, s],
            {(m, "u_s_ab"): (src, "u_c_ab"), (m, "w_M"): (s, "w_M"), (s, "tau_M"): (m, "tau_M")},
        )

    def operating_point(self, u_peak, slip, periods, nominal):
        """Steady state by simulation, then the meter's averages over `periods`.

        The simulation starts from the steady state of the `nominal` machine
        (no saturation, no core loss: what one knows before the test) with
        the rotor at its held speed; the plant's own effect then settles
        through motulator's dynamics. Returns (line current rms, three-phase
        power, torque, periods to settle)."""
        self.source.amplitude = u_peak
        w_m = (1.0 - slip) * self.w / self.par.n_p
        self.mech.set_external_rotor_speed(w_m)
        T = 2 * math.pi / self.w
        a = 1.0 / nominal.L_s + 1j * self.w * slip / (nominal.R_r + 1j * self.w * slip * nominal.L_ell)
        i_s = u_peak * a / (1j * self.w + a * nominal.R_s)
        psi_s = (u_peak - nominal.R_s * i_s) / (1j * self.w)
        psi_r = psi_s * nominal.R_r / (nominal.R_r + 1j * self.w * slip * nominal.L_ell)
        y = np.array([psi_s, psi_r, 0j], dtype=complex)
        t = 0.0
        prev = None
        settled = None
        block = 4
        while t < MAX_PERIODS * T:
            sol = self._run(t, y, block)
            y = sol.y[:, -1]
            t += block * T
            agree = True
            for now in self._averages(sol, block):
                agree &= prev is not None and all(
                    abs(a - b) <= SETTLE_TOL * max(abs(b), 1e-12) for a, b in zip(now[:2], prev[:2])
                )
                prev = now
            if agree:
                settled = t
                break
        if settled is None:
            raise RuntimeError(f"no steady state within {MAX_PERIODS} periods at slip {slip}")
        sol = self._run(t, y, periods)
        i_rms, p, tau = (float(np.mean([r[j] for r in self._averages(sol, periods)])) for j in range(3))
        return i_rms, p, tau, settled / T

    def _run(self, t0, y0, periods):
        T = 2 * math.pi / self.w
        n = periods * SAMPLES
        t_eval = t0 + np.arange(n + 1) * (T / SAMPLES)
        sol = solve_ivp(
            self.system.rhs, (t0, t_eval[-1]), y0, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=t_eval
        )
        if sol.status != 0:
            raise RuntimeError(sol.message)
        return sol

    def _averages(self, sol, periods):
        """Per period: (rms line current averaged over phases, power, torque)."""
        t = sol.t[:-1]
        u = self.source.amplitude * np.exp(1j * self.w * t)
        st = SimpleNamespace(psi_s_ab=sol.y[0, :-1], psi_r_ab=sol.y[1, :-1])
        i_s, _, tau = self.machine.compute_outputs(st, SimpleNamespace(u_s_ab=u, w_M=0.0))
        i_abc = np.array(complex2abc(i_s))
        u_abc = np.array(complex2abc(u))
        out = []
        for k in range(periods):
            sl = slice(k * SAMPLES, (k + 1) * SAMPLES)
            rms = np.mean(np.sqrt(np.mean(i_abc[:, sl] ** 2, axis=1)))
            p = np.mean(np.sum(u_abc[:, sl] * i_abc[:, sl], axis=0))
            out.append((rms, p, float(np.mean(np.real(tau[sl])))))
        return out


def phasor(par, w, u_peak, slip):
    """Steady state of the same Γ model on a sinusoid (for the check and the floor).

    Returns (line current rms, power, torque, |psi_s|)."""
    L_s = par.L_s

    def solve(psi):
        ls = L_s(psi) if callable(L_s) else L_s
        a = 1.0 / ls + 1j * w * slip / (par.R_r + 1j * w * slip * par.L_ell)
        i_s = u_peak * (a / (1j * w) + par.G_c) / (1.0 + par.G_c * par.R_s + a * par.R_s / (1j * w))
        psi_s = (u_peak - par.R_s * i_s) / (1j * w)
        return i_s, psi_s, a

    if callable(L_s):
        lo, hi = 0.0, abs(u_peak) / w * 1.5
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if abs(solve(mid)[1]) > mid:
                lo = mid
            else:
                hi = mid
        psi = 0.5 * (lo + hi)
    else:
        psi = 0.0
    i_s, psi_s, a = solve(psi)
    i_m = psi_s * a
    tau = 1.5 * par.n_p * np.imag(i_m * np.conj(psi_s))
    return abs(i_s) / math.sqrt(2), 1.5 * np.real(u_peak * np.conj(i_s)), tau, abs(psi_s)


# %% Machine, plan, meters.
def draw_machine(rng):
    power = log_uniform(rng, 750.0, 45e3)
    poles = int(rng.choice([2, 4, 4, 4, 6, 8]))
    if rng.random() < 0.55:
        f, line_v = 50.0, float(rng.choice([400.0, 400.0, 230.0, 690.0]))
    else:
        f, line_v = 60.0, float(rng.choice([460.0, 460.0, 230.0, 575.0]))
    connection = "star" if rng.random() < 0.5 else "delta"
    size = math.log10(power / 750.0) / math.log10(45e3 / 750.0)  # 0 .. 1
    eff = 0.78 + 0.16 * size + rng.uniform(-0.02, 0.02)
    pf = rng.uniform(0.76, 0.89)
    line_i = power / (math.sqrt(3) * line_v * eff * pf)
    v_ph = line_v / math.sqrt(3)  # star equivalent
    z = v_ph / line_i
    w = 2 * math.pi * f
    r_s = log_uniform(rng, 0.01, 0.06) * (1.0 - 0.5 * size)
    r_R = log_uniform(rng, 0.01, 0.05) * (1.0 - 0.4 * size)
    inv = InductionMachineInvGammaPars(
        n_p=poles // 2,
        R_s=r_s * z,
        R_R=r_R * z,
        L_sgm=rng.uniform(0.12, 0.25) * z / w,
        L_M=rng.uniform(1.6, 4.0) * z / w,
    )
    gamma = InductionMachinePars.from_inv_gamma_pars(inv)
    return dict(
        power=power, poles=poles, f=f, line_v=line_v, connection=connection, line_i=line_i, pf=pf,
        R_s=gamma.R_s, R_r=gamma.R_r, L_ell=gamma.L_ell, L_s=gamma.L_s, n_p=gamma.n_p,
        inv=dict(R_s=inv.R_s, R_R=inv.R_R, L_sgm=inv.L_sgm, L_M=inv.L_M),
    )


class Meter:
    """Noise (of reading and of range) and the resolution of a display."""

    def __init__(self, rel, counts, fixed_range, range_share):
        self.rel = rel
        self.counts = counts
        self.fixed = fixed_range  # None: autoranging
        self.range_share = range_share

    def range(self, x):
        if self.fixed is not None:
            return self.fixed
        return 10.0 ** math.ceil(math.log10(max(abs(x), 1e-9)))

    def step(self, x):
        return self.range(x) / self.counts

    def read(self, rng, x):
        noisy = x + rng.normal(0.0, self.rel * abs(x) + self.range_share * self.range(x))
        q = self.step(noisy)
        return round(noisy / q) * q


def one_two_five_above(x):
    d = 10.0 ** math.floor(math.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * d >= x:
            return m * d
    return 10.0 * d


def draw_meter(rng, rel, fixed_top):
    counts = float(rng.choice([4000.0, 20000.0, 200000.0]))
    fixed = one_two_five_above(1.05 * fixed_top) if rng.random() < 0.4 else None
    return Meter(log_uniform(rng, *rel), counts, fixed, rng.uniform(0.0, 5e-4))


def make_case(rng, effect, plan):
    mc = draw_machine(rng)
    w = 2 * math.pi * mc["f"]
    u_rated = math.sqrt(2.0 / 3.0) * mc["line_v"]  # peak phase voltage, star equivalent
    psi_nom = u_rated / w
    par = InductionMachinePars(n_p=mc["n_p"], R_s=mc["R_s"], R_r=mc["R_r"], L_ell=mc["L_ell"], L_s=mc["L_s"])
    nominal_par = InductionMachinePars(n_p=mc["n_p"], R_s=mc["R_s"], R_r=mc["R_r"], L_ell=mc["L_ell"], L_s=mc["L_s"])
    effect_params = {}
    regions = []
    if effect == "main_flux_saturation":
        drop = rng.uniform(0.08, 0.3)
        S = rng.uniform(5.0, 9.0)
        L_su = mc["L_s"] / (1.0 - drop)
        psi_half = psi_nom / (drop / (1.0 - drop)) ** (1.0 / S)
        par.L_s = lambda psi, L_su=L_su, psi_half=psi_half, S=S: L_su / (1.0 + (psi / psi_half) ** S)
        mc["L_s"] = L_su  # the nominal (unsaturated) inductance
        regions = ["low_slip"]
    elif effect == "iron_loss":
        frac = rng.uniform(0.012, 0.035)
        par.G_c = frac * mc["power"] / (1.5 * u_rated**2)
        regions = ["low_slip"]
    plant = Plant(par, mc["f"])

    # The plan.
    n_volt = int(rng.integers(2, 4)) if effect == "main_flux_saturation" else int(rng.integers(1, 4))
    volts = [mc["line_v"]]
    for _ in range(1, n_volt):
        volts.append(max(volts[-1] * rng.uniform(0.55, 0.9), 0.45 * mc["line_v"]))
    n_pts = int(rng.integers(12, 46))
    s_min = log_uniform(rng, 0.001, 0.015)
    x = np.linspace(0.0, 1.0, n_pts)
    if plan == "sweep":
        slips = s_min + (1.0 - s_min) * x * x
    elif plan == "log-sweep":
        slips = s_min * (1.0 / s_min) ** x
    else:
        slips = s_min + (rng.uniform(0.25, 0.7) - s_min) * x
    gap = np.diff(slips)
    jitter = rng.uniform(-0.15, 0.15, n_pts)
    for k in range(1, n_pts - 1):
        slips[k] += jitter[k] * min(gap[k - 1], gap[k])
    descending = rng.random() < 0.3
    if descending:
        slips = slips[::-1]
    periods = int(rng.integers(5, 26))
    torque_sensor = rng.random() < 0.4
    wander = rng.uniform(5e-4, 2e-3)
    rpm_step = 0.01
    n_sync = 60.0 * mc["f"] / mc["n_p"]

    # Simulate every point (the true input), then the meters.
    sim = []
    settle = []
    worst = 0.0
    for seg, v in enumerate(volts):
        for s in slips:
            v_true = v * (1.0 + rng.normal(0.0, wander))
            u = math.sqrt(2.0 / 3.0) * v_true
            i, p, tau, n_settle = plant.operating_point(u, s, periods, nominal_par)
            pi, pp, pt, _ = phasor(par, w, u, s)
            worst = max(worst, abs(i / pi - 1), abs(p - pp) / max(abs(pp), 1e-3 * pi * u))
            sim.append((seg, v_true, s, i, p, tau, pi, pp))
            settle.append(n_settle)
    if worst > CHECK_TOL:
        raise RuntimeError(f"time domain and phasor steady state differ by {worst:.2e}")
    top_i = max(r[3] for r in sim)
    top_p = max(abs(r[4]) for r in sim)
    top_t = max(abs(r[5]) for r in sim)
    m_i = draw_meter(rng, (3e-4, 5e-3), top_i)
    m_p = draw_meter(rng, (5e-4, 1e-2), top_p)
    m_v = draw_meter(rng, (2e-4, 2e-3), mc["line_v"])
    m_t = Meter(0.0, 20000.0, one_two_five_above(1.05 * top_t), rng.uniform(1e-3, 3e-3))

    sweeps = {}
    meas_i, meas_p, clean_i, clean_p = [], [], [], []
    for seg, v_true, s, i, p, tau, pi, pp in sim:
        li = m_i.read(rng, i)
        lp = m_p.read(rng, p)
        lv = m_v.read(rng, v_true)
        n_read = round((1.0 - s) * n_sync / rpm_step) * rpm_step
        s_read = min(max(1.0 - n_read / n_sync, 0.0), 1.0)
        tq = m_t.read(rng, tau) if torque_sensor else None
        # The plant at the input as read: the simulated value times the
        # phasor ratio (read input over true input).
        ri, rp, _, _ = phasor(par, w, math.sqrt(2.0 / 3.0) * lv, s_read)
        clean_i.append(i * ri / pi)
        clean_p.append(p * rp / pp if abs(pp) > 0 else rp)
        meas_i.append(li)
        meas_p.append(lp)
        sweeps.setdefault(seg, []).append((s_read, lv, li, lp, tq, mc["f"]))

    def nrmse(y, c):
        y, c = np.asarray(y), np.asarray(c)
        spread = np.sum((y - y.mean()) ** 2)
        return math.sqrt(np.sum((y - c) ** 2) / spread) if spread > 0 else 0.0

    floor = 0.5 * (nrmse(meas_i, clean_i) + nrmse(meas_p, clean_p))

    # Truth in the contract's convention (see the module's docstring).
    k = 1.0 if mc["connection"] == "star" else 3.0
    L_s, L_ell = mc["L_s"], mc["L_ell"]
    L_m = L_s * math.sqrt(L_s / (L_s + L_ell))
    leak = L_s - L_m
    nominal = {
        "Rs": k * mc["R_s"],
        "Xs": k * w * leak,
        "Xm": k * w * L_m,
        "Rr": k * mc["R_r"] * L_s / (L_s + L_ell),
        "Xr": k * w * leak,
    }
    emf_scale = 1.0 if mc["connection"] == "star" else math.sqrt(3.0)  # star-phase -> winding-phase voltage
    if effect == "main_flux_saturation":
        _, _, _, psi_rated = phasor(par, w, u_rated, slips.min())
        effect_params = {
            "Xm_drop_at_rated_voltage": drop,
            "saturation_exponent": S,
            "psi_half_Vs": psi_half,
            "Es_gamma_V": emf_scale * w * psi_half / math.sqrt(2.0),
            "Es_T_equivalent_V": emf_scale * w * psi_half / math.sqrt(2.0) * L_m / L_s,
            "Xm_unsaturated_ohm": nominal["Xm"],
            "Ls_drop_at_rated_flux_measured": 1.0 - par.L_s(psi_rated) / L_su,
            "motulator_L_su_H": L_su,
        }
    elif effect == "iron_loss":
        effect_params = {
            "iron_loss_at_rated_voltage_fraction_of_rating": frac,
            "Rfe_gamma_ohm": k / par.G_c,
            "Rfe_T_equivalent_ohm": k / par.G_c * L_s / (L_s + L_ell),
            "motulator_G_c_S": par.G_c,
        }
    noise = {
        "line_current": math.sqrt(np.mean([(m_i.rel * x + m_i.range_share * m_i.range(x)) ** 2 for x in clean_i])),
        "input_power": math.sqrt(np.mean([(m_p.rel * abs(x) + m_p.range_share * m_p.range(x)) ** 2 for x in clean_p])),
    }
    quant = {
        "line_current": max(m_i.step(x) for x in meas_i),
        "input_power": max(m_p.step(x) for x in meas_p),
        "line_voltage": m_v.step(mc["line_v"]),
    }
    setup = {
        "points_per_sweep": float(n_pts),
        "sweeps": float(len(volts)),
        "lowest_slip": float(s_min),
        "highest_slip": float(max(slips)),
        "descending": float(descending),
        "meter_periods": float(periods),
        "torque_sensor": float(torque_sensor),
        "supply_wander": wander,
        "current_meter_rel": m_i.rel,
        "power_meter_rel": m_p.rel,
        "voltage_meter_rel": m_v.rel,
        "current_meter_counts": m_i.counts,
        "power_meter_counts": m_p.counts,
        "current_meter_fixed_range": float(m_i.fixed or 0.0),
        "power_meter_fixed_range": float(m_p.fixed or 0.0),
        "settle_periods_max": float(max(settle)),
        "time_vs_phasor_max_rel": worst,
        "rating_W": mc["power"],
        "motulator_R_s_ohm": mc["R_s"],
        "motulator_R_r_ohm": mc["R_r"],
        "motulator_L_ell_H": mc["L_ell"],
        "motulator_L_s_H": mc["L_s"],
    }
    truth = {
        "effect": effect,
        "effect_params": effect_params,
        "nominal": nominal,
        "noise": noise,
        "quantisation": quant,
        "noise_floor": floor,
        "regions": regions,
        "source": SOURCE,
        "plan": plan,
        "setup": setup,
    }
    rated_rpm = round((1.0 - 0.03) * n_sync)
    nameplate = {
        "power_W": round(mc["power"] / 10.0) * 10.0,
        "voltage_V": mc["line_v"],
        "current_A": round(mc["line_i"] * 10.0) / 10.0,
        "speed_rpm": float(rated_rpm),
        "poles": mc["poles"],
        "frequency_Hz": mc["f"],
        "connection": mc["connection"],
        "power_factor": round(mc["pf"] * 100.0) / 100.0,
    }
    return sweeps, nameplate, truth, torque_sensor


def write_case(suite, cid, sweeps, nameplate, torque):
    rel = os.path.join("cases", cid)
    os.makedirs(os.path.join(suite, rel), exist_ok=False)
    files = []
    for seg, rows in sorted(sweeps.items()):
        name = os.path.join(rel, f"sweep-{seg}.csv")
        with open(os.path.join(suite, name), "w") as f:
            f.write(f"# motorbench segment {seg} kind=im_slip_sweep label=sweep {seg}\n")
            cols = "slip,line_voltage_V,line_current_A,input_power_W" + (",torque_Nm" if torque else "") + ",frequency_Hz"
            f.write(cols + "\n")
            for s, v, i, p, t, fr in rows:
                vals = [s, v, i, p] + ([t] if torque else []) + [fr]
                f.write(",".join(f"{float(x):.10g}" for x in vals) + "\n")
        files.append(name)
    plate = os.path.join(rel, "nameplate.json")
    with open(os.path.join(suite, plate), "w") as f:
        json.dump(nameplate, f, indent=2)
    return {"id": cid, "kind": "im_slip_sweep", "files": files, "nameplate": plate}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="the suite directory (created, or added to)")
    ap.add_argument("--seed", type=int, default=20261121)
    ap.add_argument("--cases", type=int, default=12, help="motulator cases to add")
    args = ap.parse_args()
    suite = Suite(args.out, args.seed, "mot-", "motulator")
    rng = np.random.default_rng([args.seed, 0x6D6F74])
    # A third none, a third each effect motulator simulates.
    cycle = ["none", "main_flux_saturation", "iron_loss"]
    effects = [cycle[n % 3] for n in range(args.cases)]
    rng.shuffle(effects)
    start = time.time()
    for n, effect in enumerate(effects):
        cid = f"mot-{n + 1:02}"
        plan = PLANS[n % len(PLANS)]
        case_rng = np.random.default_rng([args.seed, 0x6D6F74, n])
        t0 = time.time()
        sweeps, plate, t, torque = make_case(case_rng, effect, plan)
        suite.add(write_case(args.out, cid, sweeps, plate, torque), t)
        points = sum(len(r) for r in sweeps.values())
        print(
            f"{cid}: {plan} {effect}, {points} points, floor {t['noise_floor']:.2e}, {time.time() - t0:.1f} s",
            file=sys.stderr,
        )
    suite.save()
    print(f"{len(effects)} motulator {VERSION} cases added to {args.out} in {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
