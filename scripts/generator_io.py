"""What the test-data generators (scripts/third-generator.py, scripts/link-generator.py) share:
how a case's two runs are drawn and written. No plant, no effect: those are each generator's."""
import os
import random


def write_run(path, header, rows):
    """A run as CSV: `header` (e.g. "t,phi,tau"), then (t, angle, torque) rows."""
    with open(path, "w") as f:
        f.write(header + "\n")
        for t, a, b in rows:
            f.write(f"{t:.6f},{a:.9e},{b:.9e}\n")


def write_case(out, rng, truth, run):
    """The fit and held-out runs of a case into OUT/fit.csv and OUT/ho.csv, each from its own
    draw of `rng`, with a jump part-way at its own instant (the same one with SAMEJUMP=1):
    `run(path, rng, jump_fraction)` writes one and returns its motion's name; the case's truth
    goes to OUT/truth.txt."""
    jf = rng.uniform(0.3, 0.7)
    jh = jf if os.environ.get("SAMEJUMP") else rng.uniform(0.3, 0.7)
    truth["fit_motion"] = run(os.path.join(out, "fit.csv"), random.Random(rng.random()), jf)
    truth["ho_motion"] = run(os.path.join(out, "ho.csv"), random.Random(rng.random()), jh)
    with open(os.path.join(out, "truth.txt"), "w") as f:
        f.write(repr(truth) + "\n")


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
