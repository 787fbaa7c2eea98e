"""The Python peer of motorbench's double-cage induction-machine fit.

The same least-squares problem, solved the way an engineer would with
numpy and scipy: the equivalent circuit (Rs, Xs, Xm, Rr1, Rr2, Xr1, Xr2)
in log-parameters, current and three-phase input power predicted per
operating point (vectorised over the points), relative residuals, fitted
by scipy.optimize.least_squares (method "lm", MINPACK, analytic-free
forward differences) from each of the same classical starts; the best
start is then refitted with its residuals rescaled by its own prediction
and whitened by their 2x2 covariance, as motorbench does. The leakage
split is left as fitted on both sides.

Usage: im_fit.py problem.json  (written by `peers im-fit`); prints one JSON
line: the time of the fit (the problem read beforehand, the fastest of
three in this process), the circuit, and its current and power at every
point (the answer compared: the circuit itself is one of a family).
"""

import json
import sys
import time

import numpy as np
import scipy.optimize

# Parameter order of the problem file: Rs, Xs, Xm, Rr1, Rr2, Xr1, Xr2.

# Repetitions in one process, the fastest reported (as on motorbench's side).
REPEATS = 3


def predict(theta, slip, v):
    rs, xs, xm, rr1, rr2, xr1, xr2 = theta
    y_rotor = slip / (rr1 + 1j * slip * xr1) + slip / (rr2 + 1j * slip * xr2)
    y_ag = -1j / xm + y_rotor
    z = rs + 1j * xs + 1.0 / y_ag
    y = 1.0 / z
    return v * np.abs(y), 3.0 * v * v * y.real


class Problem:
    def __init__(self, d):
        self.slip = np.array(d["slip"])
        self.v = np.array(d["voltage"])
        self.i = np.array(d["current"])
        self.p = np.array(d["power"])
        rms = lambda a: np.sqrt(np.mean(a * a))
        self.ri, self.rp = rms(self.i), rms(self.p)
        self.scale_i = np.maximum(np.abs(self.i), 1e-3 * self.ri)
        self.scale_p = np.maximum(np.abs(self.p), 1e-3 * self.rp)
        self.l_inv = np.eye(2)

    def raw(self, x):
        i, p = predict(np.exp(x), self.slip, self.v)
        return (i - self.i) / self.scale_i, (p - self.p) / self.scale_p

    def residuals(self, x):
        if not np.all(x < 700.0):
            return np.full(2 * len(self.slip), 1e100)
        ri, rp = self.raw(x)
        l = self.l_inv
        r = np.concatenate([l[0, 0] * ri, l[1, 0] * ri + l[1, 1] * rp])
        return r if np.all(np.isfinite(r)) else np.full(len(r), 1e100)


def solve(problem, x0, tol, evaluations):
    # motorbench's bound counts residual evaluations (each with its
    # Jacobian); MINPACK's counts the forward differences' calls too.
    sol = scipy.optimize.least_squares(
        problem.residuals, x0, method="lm", ftol=tol, xtol=tol, gtol=1e-15,
        max_nfev=evaluations * (len(x0) + 1),
    )
    return sol.x, float(np.sum(sol.fun**2))


def whitening(ri, rp, dof):
    a = max(np.sum(ri * ri) / dof, 1e-24)
    b = max(np.sum(rp * rp) / dof, 1e-24)
    c = np.sum(ri * rp) / dof
    l00 = np.sqrt(a)
    l10 = c / l00
    l11 = np.sqrt(max(b - l10 * l10, 1e-6 * b))
    return np.array([[1.0 / l00, 0.0], [-l10 / (l00 * l11), 1.0 / l11]])


def fit(d):
    problem = Problem(d)
    results = [solve(problem, np.log(s), 1e-8, d["screen_bound"]) for s in d["starts"]]
    best = min(results, key=lambda r: r[1])[0]
    # Stage B: scale by the best fit's prediction, whiten, refit.
    i, p = predict(np.exp(best), problem.slip, problem.v)
    problem.scale_i = np.maximum(np.abs(i), 1e-3 * problem.scale_i)
    problem.scale_p = np.maximum(np.abs(p), 1e-3 * problem.scale_p)
    ri, rp = problem.raw(best)
    problem.l_inv = whitening(ri, rp, max(len(problem.slip) - len(best), 1))
    x, _ = solve(problem, best, 1e-12, d["bound"])
    theta = np.exp(x)
    rs, xs, xm, rr1, rr2, xr1, xr2 = theta
    # Canonical cage order: cage 1 the outer one (smaller Xr/Rr).
    if xr1 / rr1 > xr2 / rr2:
        theta = np.array([rs, xs, xm, rr2, rr1, xr2, xr1])
    return theta, len(results)


def main():
    d = json.load(open(sys.argv[1]))
    seconds = float("inf")
    for _ in range(REPEATS):
        clock = time.perf_counter()
        theta, starts = fit(d)
        seconds = min(seconds, time.perf_counter() - clock)
    i, p = predict(theta, np.array(d["slip"]), np.array(d["voltage"]))
    print(json.dumps({"seconds": seconds, "params": theta.tolist(), "starts": starts,
                      "prediction": np.concatenate([i, p]).tolist()}))


if __name__ == "__main__":
    main()
