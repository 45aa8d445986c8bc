#!/usr/bin/env bash
# Runs `rig identify --model linear` on both tests of every spring and torque amplitude of the
# measured torsion springs (../shared/data/sea-torsion-springs), the two files fitted together
# in the order of their test ids, every fourth time block of each held out (no --holdout).
# It checks how the fit files' frames chain (docs/IDENTIFY.md, item 3: a file zeroed at its
# start is read from where the one before it ended unloaded). Prints a Markdown table.
#   scripts/springs-two-fit.sh [DATA_DIR] [OUT_DIR]
set -euo pipefail
out_default=rig-springs-two-fit
source "$(dirname "$0")/springs-common.sh"
echo "| spring | T [N·m] | tests | RMSE before [N·m] | after [N·m] | before/after | effects | deflection zeros [mrad] |"
echo "|---|---|---|---|---|---|---|---|"
two() {
  identify "$5" --data "$3" --data "$4" || return 0
  local ids
  ids="$(basename "$3" | cut -d- -f4) + $(basename "$4" | cut -d- -f4)"
  python3 - "$out/$5.json" "$1" "$2" "$ids" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
b, a = r["before"]["rmse"], r["after"]["rmse"]
names = ", ".join(e["name"] for e in r["effects"]) or "none"
zeros = ", ".join(f"{t['deflection_zero'] * 1e3:+.3f}" for t in r["tare"])
print(f"| {sys.argv[2]} | {sys.argv[3]} | {sys.argv[4]} | {b:.4f} | {a:.4f} | {b / a:.2f} | {names} | {zeros} |")
PY
}
each_pair two
