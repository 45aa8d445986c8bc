#!/usr/bin/env python3
"""drop-rows.py CASE OUT MODE: a third- or fourth-generator case (CASE/fit.csv, CASE/ho.csv)
as a lab's logger would have recorded it, written to OUT/fit.csv and OUT/ho.csv.

MODE: `tenth` drops a tenth of the rows at random (seeded: the same rows every time), as a
bus that misses frames or a network recording that loses packets; `pause` removes the 0.3 s
in the middle of each file, as a logger that stalls. Python's standard library only.
"""
import os
import random
import sys

if len(sys.argv) != 4 or sys.argv[3] not in ("tenth", "pause"):
    sys.exit("usage: drop-rows.py CASE OUT tenth|pause")
case, out, mode = sys.argv[1:]
os.makedirs(out, exist_ok=True)
for name in ("fit.csv", "ho.csv"):
    lines = open(os.path.join(case, name)).read().splitlines()
    header, rows = lines[0], lines[1:]
    if mode == "tenth":
        rng = random.Random(7)
        rows = [r for r in rows if rng.random() > 0.10]
    else:
        t = [float(r.split(",")[0]) for r in rows]
        mid = 0.5 * (t[0] + t[-1])
        rows = [r for r, tt in zip(rows, t) if not mid <= tt < mid + 0.3]
    with open(os.path.join(out, name), "w") as f:
        f.write("\n".join([header] + rows) + "\n")
