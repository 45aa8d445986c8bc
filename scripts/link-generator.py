#!/usr/bin/env python3
"""A generator of test data for `rig identify --model link` (docs/IDENTIFY.md, "A third
generator"): paper A's link equation I·q̈ + N·q̇ = τ with one effect, written from issue 11's
words and MODEL.md alone, with conventions the in-tree link plant (agents/model/tests/plants)
does not share: the link's inertia and damping log-uniform over two decades and one, swings of
0.3–1.5 rad, trapezoidal-velocity moves (acceleration steps, as a servo's profile) and chirps
beside multi-sines, the motion computed on a 20 kHz grid and differentiated there, a lag that
is a pure delay or a first-order filter by seed, dry friction built up over a small speed
(tanh), uniform noise and sample times that jitter. Python's standard library only.

Usage: link-generator.py OUTDIR EFFECT SEED  -> OUTDIR/fit.csv, OUTDIR/ho.csv (t, q, tau),
                                                OUTDIR/truth.txt
       link-generator.py --effects              -> the EFFECT names
"""
import math, random, sys, os
from generator_io import case_args, write_case, write_run

EFFECTS = "none tstep offset qlag tlag coulomb gravity ripple".split()
out, effect, seed = case_args("link-generator.py", EFFECTS)
rng = random.Random(7777 * seed + sum(map(ord, effect)) + 1)

I = math.exp(rng.uniform(math.log(0.005), math.log(0.5)))  # kg·m²
N = math.exp(rng.uniform(math.log(0.02), math.log(0.5)))  # N·m·s/rad
amp = rng.uniform(0.3, 1.5)  # rad
f_hi = rng.uniform(0.8, 2.5)  # Hz: the fastest content of the motion
rate = rng.choice([100, 200, 250, 500, 1000])
counts = rng.choice([4096, 16384, 65536])
counts = int(os.environ.get("COUNTS", counts))  # 0: not quantised
T = rng.uniform(20, 40)
rest = rng.uniform(0.5, 2.0)
FINE = 20000.0
# each sample taken up to this fraction of a step off its slot (under 0.5 keeps the order)
JITTER = float(os.environ.get("JITTER", 0.1))
# the torque a swing of the amplitude at the motion's top frequency takes: effects and noise
# are sized from it
w = 2 * math.pi * f_hi
tau_pk = amp * math.hypot(I * w * w, N * w)
noise = float(os.environ.get("NOISE", rng.choice([0.003, 0.01, 0.02]))) * tau_pk
truth = dict(effect=effect, I=I, N=N, amp=amp, tau_pk=tau_pk, rate=rate, noise=noise,
             counts=counts, T=T)

p = {}
if effect == "tstep" or effect == "offset":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.04, 0.12) * tau_pk
elif effect in ("qlag", "tlag"):
    p["d"] = rng.uniform(0.01, 0.04)
    p["filter"] = rng.random() < 0.5
    if os.environ.get("LAG") in ("delay", "filter"):  # every lag one kind (LAG=delay|filter)
        p["filter"] = os.environ["LAG"] == "filter"
elif effect == "coulomb":
    p["F"] = rng.uniform(0.03, 0.08) * tau_pk
    p["vs"] = rng.uniform(0.005, 0.03) * amp * w
elif effect == "gravity":
    p["mgl"] = rng.uniform(0.1, 0.4) * tau_pk
    p["q0"] = rng.uniform(-0.6, 0.6)
elif effect == "ripple":
    p["A"] = rng.uniform(0.03, 0.08) * tau_pk
    p["P"] = amp / rng.uniform(3, 8)
    p["ph"] = rng.uniform(0, 6.28)
truth["params"] = p


def motion(kind, r):
    """q(t)/amp, roughly within [-1, 1]."""
    if kind == "chirp":
        f0 = r.uniform(0.05, 0.2)
        return lambda t: math.sin(2 * math.pi * (f0 * t + (f_hi - f0) * t * t / (2 * T)))
    if kind == "multisine":
        comps = [(r.uniform(0.05, f_hi), r.uniform(0, 6.3), r.uniform(0.3, 1)) for _ in range(4)]
        comps = [(f, ph, a / (1 + 2 * f)) for f, ph, a in comps]
        s = sum(a for _, _, a in comps)
        return lambda t: sum(a * math.sin(2 * math.pi * f * t + ph) for f, ph, a in comps) / s
    # moves between random levels with a trapezoidal speed profile, then holds
    moves, t, lv = [], 0.0, 0.0
    while t < T + 5:
        nl = r.uniform(-1, 1)
        dur = r.uniform(0.6, 2.5)
        acc = r.uniform(0.15, 0.4) * dur  # the time spent accelerating (and braking)
        moves.append((t, dur, acc, lv, nl))
        t += dur + r.uniform(0.3, 2.0)
        lv = nl

    def f(t):
        prev = 0.0
        for a, dur, ta, l0, l1 in moves:
            if t < a:
                return prev
            u = t - a
            if u <= dur:
                vmax = 1 / (dur - ta)  # of the normalised distance per second
                if u < ta:
                    s = 0.5 * vmax / ta * u * u
                elif u < dur - ta:
                    s = 0.5 * vmax * ta + vmax * (u - ta)
                else:
                    v = dur - u
                    s = 1 - 0.5 * vmax / ta * v * v
                return l0 + (l1 - l0) * s
            prev = l1
        return prev
    return f


def run(path, r, jump_frac):
    kind = r.choice(["chirp", "multisine", "moves"])
    m = motion(kind, r)
    n = int((T + rest + 1.0) * FINE)
    lead = 0.2  # the plant runs before the first sample: a lagging sensor has a past
    q = []
    for i in range(n):
        tm = i / FINE - lead - rest
        x = 0.0
        if tm > 0:
            x = m(tm)
            if tm < 2.0:  # eases in from rest
                u = tm / 2.0
                x *= u * u * (3 - 2 * u)
        q.append(amp * x)
    h = 1 / FINE
    tau = [0.0] * n
    for i in range(1, n - 1):
        v = (q[i + 1] - q[i - 1]) / (2 * h)
        a = (q[i + 1] - 2 * q[i] + q[i - 1]) / (h * h)
        t = i / FINE - lead
        tt = I * a + N * v
        if effect == "coulomb":
            tt += p["F"] * math.tanh(v / p["vs"])
        elif effect == "gravity":
            tt += p["mgl"] * math.sin(q[i] + p["q0"])
        elif effect == "ripple":
            tt += p["A"] * math.sin(2 * math.pi * q[i] / p["P"] + p["ph"])
        elif effect == "offset":
            tt += p["c"]
        elif effect == "tstep" and t > rest + jump_frac * T:
            tt += p["c"]
        tau[i] = tt
    tau[0], tau[-1] = tau[1], tau[-2]
    qm = list(q)
    if effect in ("qlag", "tlag"):
        sig = qm if effect == "qlag" else tau
        if p["filter"]:
            a = 1 - math.exp(-1 / (FINE * p["d"]))
            y = sig[0]
            for i in range(n):
                y += a * (sig[i] - y)
                sig[i] = y
        else:
            k = int(round(p["d"] * FINE))
            sig[:] = [sig[0]] * k + sig[: n - k]

    def at(v, t):
        u = (t + lead) * FINE
        i = min(max(int(u), 0), n - 2)
        wgt = u - i
        return v[i] * (1 - wgt) + v[i + 1] * wgt

    res = 2 * math.pi / max(counts, 1)
    rows = []
    for i in range(int((T + rest) * rate)):
        t = i / rate + r.uniform(-JITTER, JITTER) / rate if i else 0.0
        qq = round(at(qm, t) / res) * res if counts else at(qm, t)
        tm = at(tau, t) + r.uniform(-1, 1) * noise * math.sqrt(3)
        rows.append((t, qq, tm))
    write_run(path, "t,q,tau", rows)
    return kind


# The clean twin (TWIN=1): the same plant, motions and noise without the effect.
write_case(out, rng, truth, run, clean=lambda: globals().update(effect="none"))
