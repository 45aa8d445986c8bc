#!/usr/bin/env bash
# Runs `rig identify --model linear` on every spring and torque amplitude of the measured
# torsion springs (../shared/data/sea-torsion-springs, see its README): fit on the first of
# the two tests, hold out the other. Prints the Markdown table of docs/IDENTIFY.md.
#   scripts/identify-springs.sh [DATA_DIR] [OUT_DIR]
# SWAP=1: the other order (fit on the second test, hold out the first).
set -euo pipefail
out_default=rig-springs
source "$(dirname "$0")/springs-common.sh"
one() {
  if [ -n "${SWAP:-}" ]; then set -- "$1" "$2" "$4" "$3" "$5"; fi
  identify "$5" --data "$3" --holdout "$4" && echo "$out/$5.json" || true
}
each_pair one | python3 "$here/scripts/springs_table.py"
