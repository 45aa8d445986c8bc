"""The outside review's ten-minute baseline for the measured springs, against `rig identify`.

Each file is tared at the rest it starts with (its first REST_S seconds, default 1), then
    tau = c + k*phi + sum_i w_i * play_{r_i}(phi),   r_i = i/11 * max|phi| of the fit file,
fitted by least squares on the fit file (the first test of each spring and amplitude; with
SWAP=1 the second) and scored on the other. Reimplemented from the review's words (its code
is not ours). Plain Python, no numpy; about two minutes.

    python3 scripts/springs_baseline.py DATA_DIR [REPORTS_DIR]

REPORTS_DIR: the reports of `scripts/identify-springs.sh` (same SWAP), to compare each pair's
held-out RMSE after `rig identify` with the baseline's.
"""
import csv
import glob
import json
import math
import os
import statistics
import sys

REST_S = float(os.environ.get("REST_S", "1.0"))
N_PLAY = 11


def load(path):
    """Deflection [rad] and torque [N·m], less their means over the first REST_S seconds."""
    t, phi, tau = [], [], []
    for row in csv.DictReader(open(path)):
        try:
            t.append(float(row["time"]))
            phi.append(math.radians(float(row["displacement"])))
            tau.append(float(row["torque_out"]))
        except ValueError:
            continue
    rest = [i for i in range(len(t)) if t[i] - t[0] < REST_S]
    p0 = sum(phi[i] for i in rest) / len(rest)
    q0 = sum(tau[i] for i in rest) / len(rest)
    return [x - p0 for x in phi], [x - q0 for x in tau]


def columns(phi, widths):
    """A constant, then a play operator of each width (width 0: phi itself)."""
    cols = [[1.0] * len(phi)]
    for r in widths:
        y, col = phi[0], []
        for x in phi:
            y = max(x - r, min(x + r, y))
            col.append(y)
        cols.append(col)
    return cols


def least_squares(cols, y):
    m = len(cols)
    a = [[sum(u * v for u, v in zip(cols[i], cols[j])) for j in range(m)] for i in range(m)]
    ridge = 1e-12 * sum(a[i][i] for i in range(m)) / m
    b = [sum(u * v for u, v in zip(cols[i], y)) for i in range(m)]
    for i in range(m):
        a[i][i] += ridge
        a[i].append(b[i])
    for i in range(m):  # Gauss-Jordan with partial pivoting
        p = max(range(i, m), key=lambda r: abs(a[r][i]))
        a[i], a[p] = a[p], a[i]
        for r in range(m):
            if r != i and a[i][i] != 0.0:
                f = a[r][i] / a[i][i]
                a[r] = [x - f * z for x, z in zip(a[r], a[i])]
    return [a[i][m] / a[i][i] if a[i][i] != 0.0 else 0.0 for i in range(m)]


def rmse(cols, w, y):
    n = len(y)
    return math.sqrt(sum((sum(w[j] * cols[j][i] for j in range(len(w))) - y[i]) ** 2 for i in range(n)) / n)


def main():
    data = sys.argv[1]
    reports = sys.argv[2] if len(sys.argv) > 2 else None
    pairs = {}
    for f in glob.glob(os.path.join(data, "kt-*.csv")):
        parts = os.path.basename(f).split("-")  # kt-<amp>-<series>-<test>-<spring>-...
        pairs.setdefault((int(parts[4]), parts[1]), []).append((int(parts[3]), f))
    wins, losses, ratios = [], [], []
    print("| spring | T [N·m] | linear (the report's before) / baseline | baseline held-out RMSE [N·m] | rig identify after [N·m] | baseline / rig |")
    print("|---|---|---|---|---|---|")
    for (spring, amp), tests in sorted(pairs.items(), key=lambda kv: (kv[0][0], float(kv[0][1]))):
        if len(tests) < 2:
            continue
        tests.sort()
        fit, held = tests[0][1], tests[1][1]
        if os.environ.get("SWAP"):
            fit, held = held, fit
        phi_f, tau_f = load(fit)
        phi_h, tau_h = load(held)
        top = max(abs(x) for x in phi_f)
        widths = [top * i / N_PLAY for i in range(N_PLAY)]
        w = least_squares(columns(phi_f, widths), tau_f)
        base = rmse(columns(phi_h, widths), w, tau_h)
        name = f"spring{spring}-{amp}nm"
        rig, before = None, None
        if reports and os.path.exists(os.path.join(reports, name + ".json")):
            report = json.load(open(os.path.join(reports, name + ".json")))
            rig, before = report["after"]["rmse"], report["before"]["rmse"]
            (wins if rig <= base else losses).append(name)
            ratios.append(before / base)
        cells = ("–", "–", "–") if rig is None else (f"{before / base:.2f}", f"{rig:.3f}", f"{base / rig:.2f}")
        print(f"| {spring} | {amp} | {cells[0]} | {base:.3f} | {cells[1]} | {cells[2]} |", flush=True)
    if reports:
        print(f"\nThe baseline's median linear/baseline: {statistics.median(ratios):.2f}, "
              f"{sum(r < 1 for r in ratios)} pairs worse than linear. "
              f"`rig identify` as good or better on {len(wins)} of {len(wins) + len(losses)} pairs; "
              f"the baseline better on: {', '.join(losses) or 'none'}.")


if __name__ == "__main__":
    main()
