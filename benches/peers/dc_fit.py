"""The Python peer of motorbench's DC output-error fit.

What an engineer would script with numpy and scipy: the DC motor
(Ra, La, K, J, f, Tst) discretised exactly with a zero-order hold
(scipy.linalg.expm of the augmented matrix), simulated from the measured
voltage on every fitted segment, and fitted by
scipy.optimize.least_squares (method "lm", MINPACK) to the noise-weighted
current and speed residuals, in log-parameters, from the same start values.

The simulation is vectorised: while the rotor turns one way the model is
linear, so each segment runs through scipy.signal.lfilter over the
eigen-modes of the 2-state system; only a start from rest (until the
rotor breaks away) and a segment whose speed crosses zero run sample by
sample in Python.

Usage: dc_fit.py problem.json  (written by `peers dc-fit`); prints one JSON
line: the fit's time (the problem read beforehand) and the optimum.
"""

import json
import math
import sys
import time

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.signal

REFUSED = 1e30
MAX_LN = 25.0

# Repetitions in one process, the fastest reported (as on motorbench's side).
REPEATS = 3


def zoh(p, dt):
    """Exact step of the driven motor: state [i, w, theta], inputs [U, Tst*dir]."""
    ra, la, k, j, f, _ = p
    m = np.zeros((5, 5))
    m[:3, :3] = [[-ra / la, -k / la, 0.0], [k / j, -f / j, 0.0], [0.0, 1.0, 0.0]]
    m[:3, 3:] = [[1.0 / la, 0.0], [0.0, -1.0 / j], [0.0, 0.0]]
    e = scipy.linalg.expm(m * dt)
    return e[:3, :3], e[:3, 3:]


def steady_state(p, u):
    ra, _, k, _, f, tst = p
    d = k * k + ra * f
    current = (f * u + k * tst * math.copysign(1.0, u)) / d
    speed = (u - ra * current) / k
    if speed * u > 0.0:
        return current, speed
    return u / ra, 0.0


def scalar_step(p, a, b, decay, i, w, u):
    ra, _, k, _, _, tst = p
    if w != 0.0:
        d = math.copysign(1.0, w)
    elif tst == 0.0:
        d = 1.0
    elif abs(k * i) > tst:
        d = math.copysign(1.0, k * i)
    else:
        i_ss = u / ra
        return i_ss + (i - i_ss) * decay, 0.0, 0.0
    t = tst * d
    ni = a[0, 0] * i + a[0, 1] * w + b[0, 0] * u + b[0, 1] * t
    nw = a[1, 0] * i + a[1, 1] * w + b[1, 0] * u + b[1, 1] * t
    dth = a[2, 0] * i + a[2, 1] * w + b[2, 0] * u + b[2, 1] * t
    return ni, (0.0 if nw * d < 0.0 else nw), dth


def linear_run(a, b, i0, w0, u, t):
    """States after each input of u (rotor turning one way, torque t):
    current, speed, and the angle moved over each step."""
    a2, b2 = a[:2, :2], b[:2, :]
    lam, v = np.linalg.eig(a2)
    vi = np.linalg.inv(v)
    g = vi @ (b2 @ np.vstack([u, np.full_like(u, t)]))
    z0 = vi @ np.array([i0, w0])
    z = np.empty((2, len(u)), dtype=complex)
    for m in range(2):
        z[m] = scipy.signal.lfilter([1.0], [1.0, -lam[m]], g[m], zi=[lam[m] * z0[m]])[0]
    x = (v @ z).real
    prev_i = np.concatenate(([i0], x[0, :-1]))
    prev_w = np.concatenate(([w0], x[1, :-1]))
    dth = a[2, 0] * prev_i + a[2, 1] * prev_w + b[2, 0] * u + b[2, 1] * t
    return x[0], x[1], dth


def simulate(p, seg):
    """Simulated current and speed reading (mean over the interval)."""
    a, b = zoh(p, seg["dt"])
    decay = math.exp(-seg["dt"] / (p[1] / p[0]))
    u = seg["u"]
    n = len(u)
    cur, spd = np.empty(n), np.empty(n)
    start = seg["start"]
    inv_dt = 1.0 / seg["dt"]
    if start == "rest":
        i, w, dth = scalar_step(p, a, b, decay, 0.0, 0.0, u[0])
        cur[0], spd[0] = i, dth * inv_dt
    elif "settled" in start:
        i, w = steady_state(p, start["settled"])
        cur[0], spd[0] = i, w
    else:
        i, w = start["state"]
        cur[0], spd[0] = i, w
    k = 1
    # Held at rest until the torque breaks the rotor away: sample by sample.
    while k < n and w == 0.0:
        i, w, dth = scalar_step(p, a, b, decay, i, w, u[k])
        cur[k], spd[k] = i, dth * inv_dt
        k += 1
    if k < n:
        d = math.copysign(1.0, w)
        ci, cw, dth = linear_run(a, b, i, w, u[k:], p[5] * d)
        if np.all(cw * d >= 0.0):
            cur[k:], spd[k:] = ci, dth * inv_dt
        else:
            # The speed reverses or stops: sample by sample.
            for m in range(k, n):
                i, w, dth = scalar_step(p, a, b, decay, i, w, u[m])
                cur[m], spd[m] = i, dth * inv_dt
    return cur, spd


def valid(p):
    return all(math.isfinite(v) for v in p) and min(p[:4]) > 0.0 and min(p[4:]) >= 0.0


def residuals(x, ref, segs, w, rows):
    if not np.all(np.abs(x) <= MAX_LN):
        return np.full(rows, REFUSED)
    p = ref * np.exp(x)
    if not valid(p):
        return np.full(rows, REFUSED)
    out = []
    for seg in segs:
        ci, cw = simulate(p, seg)
        r = np.empty(2 * len(ci))
        r[0::2] = (ci - seg["i"]) * w[0]
        r[1::2] = (cw - seg["w"]) * w[1]
        out.append(r)
    r = np.concatenate(out)
    if not np.all(np.isfinite(r)):
        return np.full(rows, REFUSED)
    return r


def main():
    doc = json.load(open(sys.argv[1]))
    segs = []
    for s in doc["segments"]:
        t = np.array(s["time"])
        segs.append(
            {
                "dt": (t[-1] - t[0]) / (len(t) - 1),
                "u": np.array(s["voltage"]),
                "i": np.array(s["current"]),
                "w": np.array(s["speed"]),
                "start": s["start"],
            }
        )
    ref = np.array(doc["start"])
    w = [1.0 / doc["sigma"][0], 1.0 / doc["sigma"][1]]
    rows = 2 * sum(len(s["u"]) for s in segs)
    seconds = float("inf")
    for _ in range(REPEATS):
        clock = time.perf_counter()
        sol = scipy.optimize.least_squares(
            residuals,
            np.zeros(6),
            method="lm",
            ftol=1e-9,
            xtol=1e-10,
            gtol=1e-10,
            args=(ref, segs, w, rows),
        )
        seconds = min(seconds, time.perf_counter() - clock)
    params = (ref * np.exp(sol.x)).tolist()
    print(json.dumps({"seconds": seconds, "params": params, "evaluations": int(sol.nfev)}))


if __name__ == "__main__":
    main()
