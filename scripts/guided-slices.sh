#!/usr/bin/env bash
# Guided checks of one weights directory on the fresh test scans, one scan per process, several
# processes at a time: the runner behind docs/eval/recipe128/d21k and docs/eval/refine30.
#
#   W=WEIGHTS TAG=NAME [SEED=0] [BLOCKS="no yes"] [FROM=0] [TO=29] [P=2] [LS=PC,PEN,MOB] \
#   [REF=N] [PHYS=N] [VARIANTS=pc+pen+mob,uncond] [BIN=physnap] [WORK=.] [CLOUDS=...] [DATA=...] \
#     bash scripts/guided-slices.sh
#
# Each (block, scan) writes WORK/r/TAG_BLOCK_sSEED_cSCAN/guided_table.json (`eval guided
# --skip-clouds SCAN --max-clouds 1 --samples-per-cloud 2`, one thread) and its log under
# WORK/logs; slices already written are skipped, so a stopped run resumes. LS sets
# --loss-scales, REF --guidance-refine-steps, PHYS --guidance-refine-physics-steps (unset: the
# binary's defaults). Merge the slices
# with scripts/merge-guided-slices.py and compare with scripts/compare-guided.py.
set -euo pipefail
cd "${WORK:-.}"
mkdir -p r logs
: "${W:?W=weights directory}" "${TAG:?TAG=name of the run}"
export W TAG LS="${LS:-}" REF="${REF:-}" PHYS="${PHYS:-}" BIN="${BIN:-physnap}"
export VARIANTS="${VARIANTS:-pc+pen+mob,uncond}"
export CLOUDS="${CLOUDS:-/work/data/testset_s1}" DATA="${DATA:-/work/data/train}"
one() {
  set -- $1
  o=r/${TAG}_$1_s$2_c$3
  [ -f "$o/guided_table.json" ] && return
  RAYON_NUM_THREADS=1 $BIN eval guided --weights "$W" --clouds "$CLOUDS" --data "$DATA" \
    --skip-clouds $3 --max-clouds 1 --samples-per-cloud 2 --variants "$VARIANTS" \
    --category-aware $1 --seed $2 ${LS:+--loss-scales $LS} ${REF:+--guidance-refine-steps $REF} \
    ${PHYS:+--guidance-refine-physics-steps $PHYS} \
    --out "$o" > logs/${TAG}_$1_s$2_c$3.log 2>&1
}
export -f one
for c in $(seq "${FROM:-0}" "${TO:-29}"); do
  for a in ${BLOCKS:-no yes}; do echo "$a ${SEED:-0} $c"; done
done | xargs -P "${P:-2}" -I{} bash -c 'one "{}"'
echo finished > "${TAG}_guided.done"
