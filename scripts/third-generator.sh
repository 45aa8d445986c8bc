#!/bin/bash
# third-generator.sh OUT SEEDS [EFFECT...]: `rig identify --model $model` on the third generator's
# cases (scripts/third-generator.py), fitted on one run and scored on the other: one line per
# case with the held-out RMSE after/before and the effects named (a case `rig identify` fails
# on is said, its log kept). The rig binary: scripts/rig-binary.sh. SAMEJUMP=1: a jump at the
# same instant in both runs. PLANT=link: paper A's link equation (scripts/link-generator.py,
# `rig identify --model link`). PLANT=lever: paper B's lever with Bouc-Wen friction
# (scripts/lever-generator.py, `rig identify --model restoring`). DROP=tenth|pause: each
# case's files as a logger that drops samples or stalls would have written them
# (scripts/drop-rows.py). JITTER=J: each sample's instant up to J of a step off its slot
# (default 0.1; under 0.5 keeps the order). CONFIG=FILE (PLANT=lever): the runs carry the pivot
# column and `rig identify` is given the rig config FILE, whose lever's envelope it then follows
# (rig-config/examples/bench.toml is the generator's lever). TWIN=1: each case's clean twin
# too (the same plant, motions and noise without the effect, scripts/generator_io.py), and
# the line gives the case's held-out error after over the twin's ("after/twin": 1.00 is as
# low as the data allow). FROM=K: seeds K to K+SEEDS−1 (default 0), e.g. seeds never tuned on.
set -euo pipefail
source "$(dirname "$0")/rig-binary.sh"
OUT=$1; S=$2; shift 2
gen=$here/scripts/third-generator.py; model=linear
[ "${PLANT:-linear}" = link ] && { gen=$here/scripts/link-generator.py; model=link; }
[ "${PLANT:-linear}" = lever ] && { gen=$here/scripts/lever-generator.py; model=restoring; }
cfg=()
[ -n "${CONFIG:-}" ] && { export PIVOT=1; cfg=(--config "$CONFIG"); }
EFF=${*:-$(python3 "$gen" --effects)}
for e in $EFF; do for s in $(seq ${FROM:-0} $((${FROM:-0}+S-1))); do
  d=$OUT/$e-$s; python3 "$gen" "$d" "$e" "$s"
  if [ -n "${DROP:-}" ]; then
    python3 "$here/scripts/drop-rows.py" "$d" "$d" "$DROP"
    [ "${TWIN:-}" = 1 ] && python3 "$here/scripts/drop-rows.py" "$d/twin" "$d/twin" "$DROP"
  fi
  "$rig" identify --model $model --data "$d/fit.csv" --holdout "$d/ho.csv" --report "$d/r.json" \
    "${cfg[@]}" > "$d/log" 2>&1 || { echo "$e-$s: rig identify failed, see $d/log" >&2; continue; }
  if [ "${TWIN:-}" = 1 ]; then
    "$rig" identify --model $model --data "$d/twin/fit.csv" --holdout "$d/twin/ho.csv" \
      --report "$d/twin/r.json" "${cfg[@]}" > "$d/twin/log" 2>&1 ||
      echo "$e-$s: rig identify failed on the twin, see $d/twin/log" >&2
  fi
  python3 - "$d" <<'PY'
import json,sys,ast,os
d=sys.argv[1]; r=json.load(open(d+'/r.json')); t=ast.literal_eval(open(d+'/truth.txt').read())
tw=d+'/twin/r.json'
twin=f"  after/twin {r['after']['rmse']/json.load(open(tw))['after']['rmse']:.3f}" if os.path.exists(tw) else ''
names=[x['name']+('('+x['params'].get('on','')+')' if 'on' in x.get('params',{}) else '') for x in r['effects']]
b, a = r['before']['rmse'], r['after']['rmse']
print(f"{d.split('/')[-1]:14s} {t['rate']:5d}Hz {t['fit_motion']:9s}/{t['ho_motion']:9s} n={t['noise']/t['tau_pk']:.3f} c={t['counts']:5d}  after/before {a/b:.3f}{twin}  {names}")
PY
done; done
