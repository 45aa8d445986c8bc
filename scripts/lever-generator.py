#!/usr/bin/env python3
"""A fifth generator of test data for `rig identify --model restoring`: paper B's lever VSA
joint with friction in its spring, written from ../shared/MODEL.md §1, §2 and §6.1 alone, with
conventions the in-tree lever (agents/model/tests/plants) does not share: the pivot anywhere in
2-16 mm (the in-tree lever sits at 9 mm), the swing set by how far the torsion spring turns
(8-25 % of its 43 degrees), MODEL.md's classic Bouc-Wen form (tau = a*tau_lever + (1-a)*k0*z,
z integrated in time by RK4 with random n, beta and gamma), paper B's 14-bit AS5048A or a
16-bit encoder, triangle, chirp, multi-sine and ramp-and-hold motions. Each effect acts at its
physical place: the gap and the stop in the spring's own angle alpha (the stop is the spring
meeting its limit, passed to the joint through the lever), the lag a torque sensor's filter or
its transport delay, the slip on the deflection encoder. Python's standard library only.

Usage: lever-generator.py OUTDIR EFFECT SEED  -> OUTDIR/fit.csv, OUTDIR/ho.csv, OUTDIR/truth.txt
       lever-generator.py --effects              -> the EFFECT names
"""
import math
import os
import random
from generator_io import case_args, motion, write_case, write_run

EFFECTS = "none offset tstep slip backlash drift kstep lag stop viscous ripple".split()
out, effect, seed = case_args("lever-generator.py", EFFECTS)
rng = random.Random(7000 * seed + sum(map(ord, effect)) + 13)

# Paper B's lever (MODEL.md §1): p from the paper's stiffness range, d0 and k_alpha its own.
P, D0, K_ALPHA = 0.0315, 0.0096, 0.9788 / math.radians(43)
ALPHA_LIMIT = math.radians(43)


def lever(phi, d_a):
    """(alpha, G, tau) of the lever at deflection phi: the spring's angle, dalpha/dphi and the
    static torque at the main joint, exact."""
    beta = math.atan2(P * math.sin(phi), P * math.cos(phi) - d_a)
    alpha = beta - phi
    ell = math.hypot(P * math.cos(phi) - d_a, P * math.sin(phi))
    g = d_a * math.cos(alpha + phi) / ell
    return alpha, g, g * K_ALPHA * alpha


d = rng.uniform(0.002, 0.016)
d_a = D0 + d
k0 = (d_a / (P - d_a)) ** 2 * K_ALPHA  # MODEL.md §1, eq. 3
alpha_pk = rng.uniform(0.08, 0.25) * ALPHA_LIMIT
lo, hi = 0.0, 1.0  # the deflection at which the spring has turned alpha_pk
for _ in range(60):
    mid = 0.5 * (lo + hi)
    lo, hi = (mid, hi) if abs(lever(mid, d_a)[0]) < alpha_pk else (lo, mid)
phi_pk = lo
tau_pk = lever(phi_pk, d_a)[2]
rate = rng.choice([100, 200, 250, 500, 1000])
JITTER = float(os.environ.get("JITTER", 0.1))
PIVOT = os.environ.get("PIVOT") == "1"  # a pivot column d [mm], as a rig's recording has
noise = rng.choice([0.003, 0.01, 0.02]) * tau_pk
counts = rng.choice([16384, 65536])
while phi_pk / (2 * math.pi / counts) < 200 and counts < 65536:
    counts *= 4
T = rng.uniform(20, 40)
rest = rng.uniform(1.0, 2.5)
# Bouc-Wen (MODEL.md §2, A = 1): a share 1 - a through the friction element, its yield
# z_max = (beta + gamma)^(-1/n) a fraction of the swing.
a_bw = rng.uniform(0.7, 0.9)
n_bw = rng.choice([1, 2, 3])
z_max = rng.uniform(0.08, 0.3) * phi_pk
share = rng.uniform(0.5, 0.9)  # beta / (beta + gamma)
s_bw = z_max ** (-n_bw)
beta_bw, gamma_bw = share * s_bw, (1 - share) * s_bw
truth = dict(effect=effect, d_mm=d * 1e3, k0=k0, phi_pk=phi_pk, tau_pk=tau_pk, rate=rate,
             noise=noise, counts=counts, T=T, a_bw=a_bw, n_bw=n_bw, z_max=z_max, share=share)

p = {}
if effect == "offset":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.03, 0.1) * tau_pk
elif effect == "tstep":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.04, 0.12) * tau_pk
elif effect == "slip":
    p["s"] = rng.choice([-1, 1]) * rng.uniform(0.04, 0.1) * phi_pk
elif effect == "backlash":
    p["r"] = rng.uniform(0.03, 0.1) * alpha_pk  # a gap in the spring's own angle
elif effect == "drift":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.1, 0.3)
elif effect == "kstep":
    p["c"] = rng.choice([-1, 1]) * rng.uniform(0.08, 0.2)
elif effect == "lag":
    p["kind"] = rng.choice(["filter", "delay"])
    p["tc"] = rng.uniform(0.01, 0.03)
elif effect == "stop":
    p["at"] = rng.uniform(0.6, 0.8) * alpha_pk  # the spring meets its stop
    p["ks"] = rng.uniform(3, 8) * K_ALPHA
elif effect == "viscous":
    p["b"] = rng.uniform(0.03, 0.08) * tau_pk  # per (phi_pk rad/s)
elif effect == "ripple":
    p["A"] = rng.uniform(0.03, 0.08) * tau_pk
    p["P"] = rng.uniform(0.1, 0.3) * phi_pk
    p["ph"] = rng.uniform(0, 6.28)
truth["params"] = p


def spring_torque(phi, t, t_jump):
    """The elastic torque at the joint: the spring at its angle alpha, seen through the lever,
    with the gap, the stop and the stiffness change where they act."""
    alpha, g, _ = lever(phi, d_a)
    if effect == "backlash":  # the spring unloaded inside the gap
        r_gap = p["r"]
        alpha = math.copysign(max(abs(alpha) - r_gap, 0.0), alpha)
    tau_s = K_ALPHA * alpha
    if effect == "drift":
        tau_s *= 1 + p["c"] * t / T
    if effect == "kstep" and t > t_jump:
        tau_s *= 1 + p["c"]
    if effect == "stop" and abs(alpha) > p["at"]:
        tau_s += p["ks"] * math.copysign(abs(alpha) - p["at"], alpha)
    return g * tau_s


def run(path, r, jump_frac):
    kind = r.choice(["triangle", "chirp", "multisine", "ramps"])
    m = motion(kind, r, T, (0.1, 0.5), (0.6, 1.5), (0.05, 1.2))
    fine = 10_000
    t_jump = rest + jump_frac * T
    truth[f"jump_{os.path.basename(path)[:-4]}_s"] = t_jump  # jump_fit_s, jump_ho_s
    lead = 0.5  # a lagging torque reads, at the start, the motion before it
    n_fine = int((T + rest + lead) * fine) + 2

    def phi_at(t):
        tm = t - rest  # at rest, then eased in over the first second
        return 0.0 if tm < 0 else phi_pk * m(tm) * min(tm, 1.0)

    def zdot(z, dphi):
        return dphi - beta_bw * abs(dphi) * abs(z) ** (n_bw - 1) * z - gamma_bw * dphi * abs(z) ** n_bw

    z, y = 0.0, None
    taus = []
    h = 1.0 / fine
    prev = phi_at(-lead)
    for i in range(n_fine):
        t = i * h - lead
        phi = phi_at(t)
        dphi = (phi - prev) / h
        # RK4 in time at constant rate over the step
        k1 = zdot(z, dphi)
        k2 = zdot(z + 0.5 * h * k1, dphi)
        k3 = zdot(z + 0.5 * h * k2, dphi)
        k4 = zdot(z + h * k3, dphi)
        z += h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        prev = phi
        tau = a_bw * spring_torque(phi, t, t_jump) + (1 - a_bw) * k0 * z
        if effect == "viscous":
            tau += p["b"] * dphi / phi_pk
        if effect == "ripple":
            tau += p["A"] * math.sin(2 * math.pi * phi / p["P"] + p["ph"])
        if effect == "lag" and p["kind"] == "filter":
            a = 1 - math.exp(-h / p["tc"])
            y = tau if y is None else y + a * (tau - y)
            tau = y
        taus.append(tau)

    def tau_at(t):
        u = min(max((t + lead) * fine, 0.0), n_fine - 2.0)
        i = int(u)
        w = u - i
        return taus[i] * (1 - w) + taus[i + 1] * w

    rows = []
    q = 2 * math.pi / counts
    for i in range(int((T + rest) * rate)):
        t = (i + r.uniform(-JITTER, JITTER)) / rate
        tau = tau_at(t - p["tc"] if effect == "lag" and p["kind"] == "delay" else t)
        phim = phi_at(t)
        if effect == "offset":
            tau += p["c"]
        if effect == "tstep" and t > t_jump:
            tau += p["c"]
        if effect == "slip" and t > t_jump:
            phim += p["s"]
        phim = round(phim / q) * q
        rows.append((t, phim, tau + r.gauss(0, noise)) + ((d * 1e3,) if PIVOT else ()))
    write_run(path, "t,phi,tau" + (",d" if PIVOT else ""), rows)
    return kind


# The clean twin (TWIN=1): the same plant, motions and noise without the effect.
write_case(out, rng, truth, run, clean=lambda: globals().update(effect="none"))
