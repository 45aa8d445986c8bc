#!/usr/bin/env bash
# Runs `rig identify --model linear` on both tests of every spring and torque amplitude of the
# measured torsion springs (../shared/data/sea-torsion-springs), the two files fitted together
# in the order of their test ids, every fourth time block of each held out (no --holdout).
# It checks how the fit files' frames chain (docs/IDENTIFY.md, item 3: a file zeroed at its
# start is read from where the one before it ended unloaded). Prints a Markdown table.
#   scripts/springs-two-fit.sh [DATA_DIR] [OUT_DIR]
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
data="${1:-$here/../shared/data/sea-torsion-springs}"
out="${2:-${TMPDIR:-/tmp}/rig-springs-two-fit}"
rig="${RIG:-${CARGO_TARGET_DIR:-$here/target}/release/rig}"
if [ ! -d "$data" ]; then
  echo "no data at $data: put the shared data beside the clone (../shared/data/sea-torsion-springs)" >&2
  exit 2
fi
[ -x "$rig" ] || (cd "$here" && cargo build --release -p rig >&2)
mkdir -p "$out"
echo "| spring | T [N·m] | tests | RMSE before [N·m] | after [N·m] | before/after | effects | deflection zeros [mrad] |"
echo "|---|---|---|---|---|---|---|---|"
keys=$(ls "$data"/kt-*.csv | xargs -n1 basename | awk -F- '{print $5" "$2}' | sort -n -k1,1 -k2,2 -u)
echo "$keys" | while read -r spring amp; do
  files=$(ls "$data"/kt-"$amp"-*-*-"$spring"-*.csv | sort -t- -k4,4n)
  set -- $files
  [ $# -ge 2 ] || continue
  name="spring$spring-${amp}nm"
  "$rig" identify --model linear --columns t=time,phi=displacement:deg,tau=torque_out \
    --data "$1" --data "$2" --report "$out/$name.json" >/dev/null 2>"$out/$name.log" \
    || { echo "$name: failed, see $out/$name.log" >&2; continue; }
  ids="$(basename "$1" | cut -d- -f4) + $(basename "$2" | cut -d- -f4)"
  python3 - "$out/$name.json" "$spring" "$amp" "$ids" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
b, a = r["before"]["rmse"], r["after"]["rmse"]
names = ", ".join(e["name"] for e in r["effects"]) or "none"
zeros = ", ".join(f"{t['deflection_zero'] * 1e3:+.3f}" for t in r["tare"])
print(f"| {sys.argv[2]} | {sys.argv[3]} | {sys.argv[4]} | {b:.4f} | {a:.4f} | {b / a:.2f} | {names} | {zeros} |")
PY
done
