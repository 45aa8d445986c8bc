"""What the test-data generators (scripts/third-generator.py, scripts/link-generator.py,
scripts/lever-generator.py) share: how a case's two runs are drawn and written, and the joint
generators' four motions. No plant, no effect: those are each generator's."""
import math
import os
import random


def motion(kind, r, T, triangle_hz=(0.1, 0.6), chirp_end_hz=(0.8, 2.0), sine_hz=(0.05, 1.5)):
    """A motion over a run of T seconds, drawn from `r`, as a function of time into [-1, 1]:
    a triangle wave, a chirp (from 0.05-0.2 Hz to `chirp_end_hz` over T), a sum of four sines
    (frequencies in `sine_hz`), or ramps (smoothstep, 0.5-2.5 s) and holds (0.3-2 s) between
    random levels, starting from 0."""
    if kind == "triangle":
        f = r.uniform(*triangle_hz)
        return lambda t: (2 / math.pi) * math.asin(math.sin(2 * math.pi * f * t))
    if kind == "chirp":
        f0, f1 = r.uniform(0.05, 0.2), r.uniform(*chirp_end_hz)
        return lambda t: math.sin(2 * math.pi * (f0 * t + (f1 - f0) * t * t / (2 * T)))
    if kind == "multisine":
        comps = [(r.uniform(*sine_hz), r.uniform(0, 6.3), r.uniform(0.3, 1)) for _ in range(4)]
        s = sum(a for _, _, a in comps)
        return lambda t: sum(a * math.sin(2 * math.pi * f * t + p) for f, p, a in comps) / s
    pts, t, lv = [], 0.0, 0.0
    while t < T + 5:
        nl = r.uniform(-1, 1)
        dur = r.uniform(0.5, 2.5)
        hold = r.uniform(0.3, 2.0)
        pts.append((t, t + dur, lv, nl))
        t += dur + hold
        lv = nl

    def f(t):
        prev = 0.0
        for a, b, l0, l1 in pts:
            if t < a:
                return prev
            if t <= b:
                x = (t - a) / (b - a)
                return l0 + (l1 - l0) * (3 * x * x - 2 * x ** 3)
            prev = l1
        return prev
    return f


def write_run(path, header, rows):
    """A run as CSV: `header` (e.g. "t,phi,tau"), then (t, angle, torque, ...) rows: the time
    to the microsecond, every other value to ten significant digits."""
    with open(path, "w") as f:
        f.write(header + "\n")
        for t, *values in rows:
            f.write(",".join([f"{t:.6f}"] + [f"{v:.9e}" for v in values]) + "\n")


def write_case(out, rng, truth, run, clean):
    """The fit and held-out runs of a case into OUT/fit.csv and OUT/ho.csv, each from its own
    draw of `rng`, with a jump part-way at its own instant (the same one with SAMEJUMP=1):
    `run(path, rng, jump_fraction)` writes one and returns its motion's name; the case's truth
    goes to OUT/truth.txt.

    With TWIN=1 the case's clean twin too, into OUT/twin/: `clean()` takes the effect out of
    the plant, and the same two runs are written again from the same draws (the same plant,
    motion, sample instants and noise), so that the twin's held-out error after identification
    is the floor the case's own can reach."""
    jf = rng.uniform(0.3, 0.7)
    jh = jf if os.environ.get("SAMEJUMP") else rng.uniform(0.3, 0.7)
    seed_fit, seed_ho = rng.random(), rng.random()
    truth["fit_motion"] = run(os.path.join(out, "fit.csv"), random.Random(seed_fit), jf)
    truth["ho_motion"] = run(os.path.join(out, "ho.csv"), random.Random(seed_ho), jh)
    with open(os.path.join(out, "truth.txt"), "w") as f:
        f.write(repr(truth) + "\n")
    if os.environ.get("TWIN") == "1":
        twin = os.path.join(out, "twin")
        os.makedirs(twin, exist_ok=True)
        clean()
        run(os.path.join(twin, "fit.csv"), random.Random(seed_fit), jf)
        run(os.path.join(twin, "ho.csv"), random.Random(seed_ho), jh)


def case_args(script, effects):
    """The command line OUTDIR EFFECT SEED (or --effects: print `effects` and exit), checked;
    OUTDIR made. Returns (out, effect, seed)."""
    import sys
    if sys.argv[1:] == ["--effects"]:
        sys.exit(print(" ".join(effects)))
    if len(sys.argv) != 4 or sys.argv[2] not in effects or not sys.argv[3].isdigit():
        sys.exit(f"usage: {script} OUTDIR EFFECT SEED (EFFECT one of {', '.join(effects)}; "
                 f"SEED a whole number), not {' '.join(sys.argv[1:])!r}")
    out, effect, seed = sys.argv[1], sys.argv[2], int(sys.argv[3])
    os.makedirs(out, exist_ok=True)
    return out, effect, seed
