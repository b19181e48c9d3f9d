#!/usr/bin/env bash
# Reproduces EVALUATION.md "Generative metrics": category accuracy of a weights directory at
# several seeds, pooled, and per category (with the test split's own ceiling), plus MMD / COV /
# 1-NNA / validity at the seeds that draw unconditional samples (12345 and 1).
#
#   bash scripts/eval/category-seeds.sh [WEIGHTS] [DATA] [OUT] [SEED ...]
#
# Defaults: WEIGHTS=weights, DATA=data/train (the README's `data synth --objects 3000 --seed 0`
# + `data import`), OUT=out/category-seeds, seeds 12345 1 2 3 4 5 6 7 8. Each seed runs
#
#   physnap eval generative --weights WEIGHTS --data DATA --per-category 4 --states 4 \
#       --points 256 --samples N --refs N --seed SEED --out OUT/gen_SEED.json
#
# with N = 48 at seeds 12345 and 1 (unconditional samples and references too) and N = 2
# otherwise (the 52 category samples are what counts there). Two evaluations run at a time, one
# thread each (≈ 10 min per pair on 2 cores). PHYSNAP_BIN names the binary (default: physnap on
# PATH). Finished seeds (their JSON exists) are skipped on a rerun. Python 3, standard library.
set -euo pipefail
WD=${1:-weights}
DATA=${2:-data/train}
OUT=${3:-out/category-seeds}
shift $(($# < 3 ? $# : 3))
BIN=${PHYSNAP_BIN:-physnap}
seeds=("$@")
[ ${#seeds[@]} = 0 ] && seeds=(12345 1 2 3 4 5 6 7 8)
mkdir -p "$OUT"
g() {
  local s=$1 n=2
  { [ "$s" = 1 ] || [ "$s" = 12345 ]; } && n=48
  [ -f "$OUT/gen_$s.json" ] && return
  RAYON_NUM_THREADS=1 "$BIN" eval generative --weights "$WD" --data "$DATA" --per-category 4 \
    --states 4 --points 256 --samples $n --refs $n --seed "$s" --out "$OUT/gen_$s.json" \
    > "$OUT/gen_$s.log" 2>&1
}
for ((i = 0; i < ${#seeds[@]}; i += 2)); do
  g "${seeds[$i]}" &
  [ -n "${seeds[$((i + 1))]:-}" ] && g "${seeds[$((i + 1))]}"
  wait
done
python3 - "$OUT" "${seeds[@]}" <<'EOF'
import collections, json, sys
out, seeds = sys.argv[1], sys.argv[2:]
hits, n = collections.Counter(), collections.Counter()
ceiling = {}
print('| seed | category hits / samples | accuracy | valid | MMD | COV | 1-NNA |')
print('|---|---|---|---|---|---|---|')
for s in seeds:
    d = json.load(open(f'{out}/gen_{s}.json'))
    c = d['conditional']
    h = sum(x['hits'] for x in c['categories'])
    k = sum(x['samples'] for x in c['categories'])
    for x in c['categories']:
        hits[x['category']] += x['hits']
        n[x['category']] += x['samples']
        r = x['reference_loo']
        ceiling.setdefault(x['category'], f"{r['hits']} / {r['objects']}")
    u = d['unconditional'] if d['unconditional']['samples'] >= 48 else None
    row = [s, f'{h} / {k}', f'{100 * h / k:.1f} %']
    row += ([f"{100 * u['valid_rate']:.0f} %", f"{u['mmd']:.4f}", f"{u['cov']:.3f}",
             f"{u['one_nna']:.3f}"] if u else ['—'] * 4)
    print('| ' + ' | '.join(map(str, row)) + ' |')
H, N = sum(hits.values()), sum(n.values())
print(f'\npooled: {H} / {N} = {100 * H / N:.1f} %\n')
print('| category | hits / samples | test split ceiling, leave one out, first seed |')
print('|---|---|---|')
for cat in sorted(n):
    print(f'| {cat} | {hits[cat]} / {n[cat]} | {ceiling[cat]} |')
EOF
