"""How a test's zeros are chosen, measured on the springs — a lead for `rig identify`'s tare.

    pip install numpy scipy && python3 scripts/springs_zero_rules.py [DATA_DIR]

One simple model for every rule (a linear spring with offset plus 11 stop operators with
non-negative weights, fitted by NNLS on the fit test), so that only the zeros differ. Fit on
the first test of each spring and amplitude, held out the second; "before" is the linear
spring with offset fitted on the fit test, on the held-out test as measured (as in
docs/IDENTIFY.md). Three rules for the held-out test's zeros:

- rest:  each test's torque and deflection zeros are the means over the rest it starts with
         (`rig identify --rest-tare`);
- state: no zeros subtracted; the rest is a *state* of the loop: each test starts with its
         stop operators at a common fraction λ of their widths, chosen so that the model
         passes through the test's rest point; only what the loop cannot hold there (|λ| > 1)
         is taken as a torque zero;
- state + continuity: as state, and where the encoder was zeroed at the test's start (its
         first reading is 0, as on 9 Mar) the held-out test's deflection is read in the fit
         test's frame shifted by where the fit test's last branch reaches zero torque (the
         next test is zeroed where this one left the spring).

The figures this printed (Nov 2026): medians of before/after over the 24 pairs 2.32 (rest),
2.83 (state), 3.40 (state + continuity); smallest 0.88, 0.54, 0.54. `rig identify` now reads
rests this way by default (agents/model/src/identify/states.rs, with its whole effect library
and selection: 4.28× on the same pairs, docs/IDENTIFY.md).
"""
import glob
import os
import sys

import numpy as np
from scipy.optimize import nnls

D = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
    os.path.dirname(__file__), "..", "..", "shared", "data", "sea-torsion-springs")
REST = (0.5, 4.5)  # s: the springs rest for their first 5 s


def load(f):
    d = np.genfromtxt(f, delimiter=",", skip_header=1)
    return d[:, 1], d[:, 3], np.radians(d[:, 4])


def rest(t, tau, x):
    m = (t > REST[0]) & (t < REST[1])
    return tau[m].mean(), x[m].mean()


def stop(x, r, s0):
    """The stop operator of half-width r from state s0: s ← clamp(s + Δx, −r, r)."""
    y = np.empty_like(x)
    s, xp = s0, x[0]
    for i, xi in enumerate(x):
        s = min(max(s + xi - xp, -r), r)
        xp = xi
        y[i] = s
    return y


def design(x, rs, lam):
    """Columns: ±1, ±x (any sign), stop operators (weights ≥ 0: loading above unloading)."""
    one = np.ones_like(x)
    return np.column_stack([one, -one, x, -x] + [stop(x, r, lam * r) for r in rs])


def widths(x, n=11):
    span = np.max(np.abs(x - np.median(x)))
    return np.linspace(0, span, n + 1)[1:] * 0.9


def lam_for(w, rs, x_r, tau_r):
    """The state fraction λ putting the model through (x_r, τ_r); the excess beyond |λ| = 1."""
    c, k, ws = w[0] - w[1], w[2] - w[3], w[4:]
    h = float(np.sum(ws * rs))
    e = tau_r - c - k * x_r
    if h <= 0:
        return 0.0, e
    lam = e / h
    if abs(lam) <= 1:
        return lam, 0.0
    lam = float(np.sign(lam))
    return lam, e - lam * h


def fit_state(t, x, y, iters=3):
    rs = widths(x)
    tr, xr = rest(t, y, x)
    lam, w = 0.0, None
    for _ in range(iters):
        w, _ = nnls(design(x, rs, lam), y)
        lam, _ = lam_for(w, rs, xr, tr)
    return rs, w, lam


def end_zero(x, rs, w, lam):
    """Where the fit test's last branch, continued, reaches zero torque [rad]."""
    c, k, ws = w[0] - w[1], w[2] - w[3], w[4:]
    s = np.array([stop(x, r, lam * r)[-1] for r in rs])
    xe = x[-1]
    tau = c + k * xe + ws @ s
    step = -np.sign(tau) * 1e-6
    for _ in range(200_000):
        s = np.clip(s + step, -rs, rs)
        xe += step
        if np.sign(c + k * xe + ws @ s) != np.sign(tau):
            break
    return xe


def main():
    files = sorted(glob.glob(os.path.join(D, "kt-*.csv")),
                   key=lambda f: int(os.path.basename(f).split("-")[3]))
    pairs = {}
    for f in files:
        n = os.path.basename(f).split("-")
        pairs.setdefault((int(n[4]), float(n[1])), []).append(f)
    ratios = {"rest": [], "state": [], "state + continuity": []}
    print("spring  T[N·m]  before[N·m]  rest  state  state+continuity")
    for (spring, amp), (ff, fh) in sorted(pairs.items()):
        t1, y1, x1 = load(ff)
        t2, y2, x2 = load(fh)
        k, c = np.polyfit(x1, y1, 1)
        before = np.sqrt(np.mean((y2 - (k * x2 + c)) ** 2))
        rmse = lambda p: np.sqrt(np.mean((y2 - p) ** 2))
        # rest: tare both tests from their rests
        (tf, xf), (th, xh) = rest(t1, y1, x1), rest(t2, y2, x2)
        rs = widths(x1 - xf)
        w, _ = nnls(design(x1 - xf, rs, 0.0), y1 - tf)
        r_rest = before / rmse(design(x2 - xh, rs, 0.0) @ w + th)
        # state, and state + continuity
        rs, w, lam1 = fit_state(t1, x1, y1)
        lam, shift = lam_for(w, rs, xh, th)
        r_state = before / rmse(design(x2, rs, lam) @ w + shift)
        zeroed = abs(x2[0]) < 1e-4
        xs = x2 + end_zero(x1, rs, w, lam1) if zeroed else x2
        lam, shift = lam_for(w, rs, rest(t2, y2, xs)[1], th)
        r_cont = before / rmse(design(xs, rs, lam) @ w + shift)
        for key, r in zip(ratios, (r_rest, r_state, r_cont)):
            ratios[key].append(r)
        print(f"{spring:6d}  {amp:6.1f}  {before:11.3f}  {r_rest:4.2f}  {r_state:5.2f}  {r_cont:5.2f}")
    for key, v in ratios.items():
        print(f"{key}: median {np.median(v):.2f}, smallest {np.min(v):.2f}")


if __name__ == "__main__":
    main()
