#!/usr/bin/env python3
"""A third generator of test data for `rig identify` (docs/IDENTIFY.md, "Left"): a linear
spring with one effect, written from issue 11's words alone, with conventions the in-tree
plants (agents/model/tests/plants) do not share: triangle and chirp motions beside multi-sines
and ramps, a first-order sensor filter as the lag, log-uniform stiffness, uniform noise, and a
jump (torque step, encoder slip, stiffness step) at another instant in the held-out run unless
SAMEJUMP=1. Python's standard library only.

Usage: third-generator.py OUTDIR EFFECT SEED  -> OUTDIR/fit.csv, OUTDIR/ho.csv, OUTDIR/truth.txt
       third-generator.py --effects              -> the EFFECT names
"""
import math, random, sys, os
from generator_io import case_args, motion, write_case, write_run

EFFECTS = "none backlash hysteresis lag slip tstep drift kstep stop coulomb viscous ripple".split()
out, effect, seed = case_args("third-generator.py", EFFECTS)
rng = random.Random(1000 * seed + sum(map(ord, effect)))

k = math.exp(rng.uniform(math.log(30), math.log(2500)))  # N·m/rad
tau_pk = rng.uniform(1.5, 12.0)
phi_pk = tau_pk / k
rate = rng.choice([100, 250, 333, 500, 1000])
# each sample taken up to this fraction of a step off its slot (under 0.5 keeps the order)
JITTER = float(os.environ.get("JITTER", 0.1))
noise = rng.choice([0.003, 0.01, 0.02]) * tau_pk
counts = rng.choice([4096, 16384, 65536, 0])  # 0: not quantised
# a lab picks an encoder that resolves the deflection: at least 200 counts over the peak
while counts and phi_pk / (2 * math.pi / counts) < 200:
    counts = counts * 4 if counts < 65536 else 0
T = rng.uniform(20, 40)
rest = rng.uniform(1.0, 2.5)
truth = dict(effect=effect, k=k, tau_pk=tau_pk, phi_pk=phi_pk, rate=rate,
             noise=noise, counts=counts, T=T)



# effect parameters (drawn once: fit and held-out runs share the plant)
p = {}
if effect == "backlash":
    p["r"] = rng.uniform(0.04, 0.15) * phi_pk
elif effect == "hysteresis":
    p["w"] = [(rng.uniform(0.02, 0.3) * phi_pk, rng.uniform(0.02, 0.06) * k) for _ in range(4)]
elif effect == "lag":
    p["tc"] = rng.uniform(0.01, 0.04)
elif effect == "slip":
    p["s"] = rng.choice([-1, 1]) * rng.uniform(0.05, 0.15) * phi_pk
elif effect == "tstep":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.04, 0.12) * tau_pk
elif effect == "drift":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.1, 0.3)
elif effect == "kstep":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.08, 0.2)
elif effect == "stop":
    p["at"] = rng.uniform(0.6, 0.8) * phi_pk
    p["ks"] = rng.uniform(2, 6) * k
elif effect == "coulomb":
    p["F"] = rng.uniform(0.03, 0.08) * tau_pk
elif effect == "viscous":
    p["b"] = rng.uniform(0.05, 0.15) * tau_pk  # per (phi_pk rad/s)
elif effect == "ripple":
    p["A"] = rng.uniform(0.03, 0.08) * tau_pk
    p["P"] = rng.uniform(0.1, 0.3) * phi_pk
    p["ph"] = rng.uniform(0, 6.28)
truth["params"] = p


def run(path, r, jump_frac):
    kind = r.choice(["triangle", "chirp", "multisine", "ramps"])
    m = motion(kind, r, T)
    n = int((T + rest) * rate)
    play = [0.0] * len(p.get("w", []))
    y = None
    t_jump = rest + jump_frac * T
    rows = []
    prev_phi = 0.0
    for i in range(n):
        t = i / rate + r.uniform(-JITTER, JITTER) / rate
        tm = t - rest
        x = 0.0 if tm < 0 else m(tm)
        # ease in from rest
        if 0 <= tm < 1.0:
            x *= tm
        phi = phi_pk * x
        dphi = (phi - prev_phi) * rate
        prev_phi = phi
        kk = k
        if effect == "drift":
            kk = k * (1 + p["c"] * max(tm, 0) / T)
        if effect == "kstep" and t > t_jump:
            kk = k * (1 + p["c"])
        tau = kk * phi
        if effect == "backlash":
            rr = p["r"]
            tau = kk * (phi - rr if phi > rr else phi + rr if phi < -rr else 0.0)
        if effect == "hysteresis":
            for j, (rw, w) in enumerate(p["w"]):
                play[j] = min(max(play[j], phi - rw), phi + rw)
                tau += w * (phi - play[j])
        if effect == "stop" and abs(phi) > p["at"]:
            tau += p["ks"] * (abs(phi) - p["at"]) * (1 if phi > 0 else -1)
        if effect == "coulomb" and abs(dphi) > 1e-9:
            tau += p["F"] * math.tanh(dphi / (0.01 * phi_pk))
        if effect == "viscous":
            tau += p["b"] * dphi / phi_pk
        if effect == "ripple":
            tau += p["A"] * math.sin(2 * math.pi * phi / p["P"] + p["ph"])
        if effect == "lag":
            a = 1 - math.exp(-1 / (rate * p["tc"]))
            y = tau if y is None else y + a * (tau - y)
            tau = y
        if effect == "tstep" and t > t_jump:
            tau += p["c"]
        phim = phi
        if effect == "slip" and t > t_jump:
            phim = phi + p["s"]
        if counts:
            q = 2 * math.pi / counts
            phim = round(phim / q) * q
        taum = tau + r.uniform(-1, 1) * noise * math.sqrt(3)
        rows.append((t, phim, taum))
    write_run(path, "t,phi,tau", rows)
    return kind


# The clean twin (TWIN=1): the same plant, motions and noise without the effect.
write_case(out, rng, truth, run, clean=lambda: globals().update(effect="none"))
