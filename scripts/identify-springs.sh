#!/usr/bin/env bash
# Runs `rig identify --model linear` on every spring and torque amplitude of the measured
# torsion springs (../shared/data/sea-torsion-springs, see its README): fit on the first of
# the two tests, hold out the other. Prints the Markdown table of docs/IDENTIFY.md.
#   scripts/identify-springs.sh [DATA_DIR] [OUT_DIR]
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
data="${1:-$here/../shared/data/sea-torsion-springs}"
out="${2:-${TMPDIR:-/tmp}/rig-springs}"
rig="${RIG:-${CARGO_TARGET_DIR:-$here/target}/release/rig}"
if [ ! -d "$data" ]; then
  echo "no data at $data: put the shared data beside the clone (../shared/data/sea-torsion-springs)" >&2
  exit 2
fi
[ -x "$rig" ] || (cd "$here" && cargo build --release -p rig >&2)
mkdir -p "$out"
# kt-<amplitude>-<series>-<test>-<spring>-<date>-<time>.csv → pairs by (spring, amplitude).
keys=$(ls "$data"/kt-*.csv | xargs -n1 basename | awk -F- '{print $5" "$2}' | sort -n -k1,1 -k2,2 -u)
echo "$keys" | while read -r spring amp; do
  files=$(ls "$data"/kt-"$amp"-*-*-"$spring"-*.csv | sort -t- -k4,4n)
  set -- $files
  [ $# -ge 2 ] || continue
  name="spring$spring-${amp}nm"
  "$rig" identify --model linear --columns t=time,phi=displacement:deg,tau=torque_out \
    --data "$1" --holdout "$2" --report "$out/$name.json" >/dev/null 2>"$out/$name.log" \
    || { echo "$name: failed, see $out/$name.log" >&2; continue; }
  echo "$out/$name.json"
done | python3 "$here/scripts/springs_table.py"
