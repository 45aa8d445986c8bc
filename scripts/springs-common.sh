# Sourced by scripts/identify-springs.sh and scripts/springs-two-fit.sh:
#   data  the measured springs (first argument, else ../shared/data/sea-torsion-springs)
#   out   where the reports go (second argument, else $TMPDIR/$out_default)
#   here, rig  the clone's root and the rig binary (scripts/rig-binary.sh)
#   each_pair FN  calls FN SPRING AMPLITUDE FIRST SECOND NAME for each spring and amplitude
#                 with two tests (in the order of their test ids)
#   identify NAME ARGS…  `rig identify --model linear` on the data README's columns, the
#                 report at $out/NAME.json; says so and returns 1 when it fails
#                 (MODEL=restoring: paper B's restoring model, `rig identify`'s default for a joint;
#                 REST_TARE=1: each rest taken for the zeros, `--rest-tare`)
source "$(dirname "${BASH_SOURCE[0]}")/rig-binary.sh"
data="${1:-$here/../shared/data/sea-torsion-springs}"
out="${2:-${TMPDIR:-/tmp}/$out_default}"
if [ ! -d "$data" ]; then
  echo "no data at $data: put the shared data beside the clone (../shared/data/sea-torsion-springs)" >&2
  exit 2
fi
mkdir -p "$out"

each_pair() {
  local each="$1"
  # kt-<amplitude>-<series>-<test>-<spring>-<date>-<time>.csv → pairs by (spring, amplitude).
  ls "$data"/kt-*.csv | xargs -n1 basename | awk -F- '{print $5" "$2}' | sort -n -k1,1 -k2,2 -u |
    while read -r spring amp; do
      # shellcheck disable=SC2046
      set -- $(ls "$data"/kt-"$amp"-*-*-"$spring"-*.csv | sort -t- -k4,4n)
      [ $# -ge 2 ] || continue
      "$each" "$spring" "$amp" "$1" "$2" "spring$spring-${amp}nm"
    done
}

identify() {
  local name="$1"
  shift
  local rest=()
  if [ -n "${REST_TARE:-}" ]; then rest=(--rest-tare); fi
  "$rig" identify --model "${MODEL:-linear}" --columns t=time,phi=displacement:deg,tau=torque_out \
    "$@" "${rest[@]}" --report "$out/$name.json" >/dev/null 2>"$out/$name.log" \
    || { echo "$name: failed, see $out/$name.log" >&2; return 1; }
}
