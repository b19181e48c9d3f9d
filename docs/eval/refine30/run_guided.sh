#!/usr/bin/env bash
# Session 37: guided pc+pen+mob of weights $W on the 30 fresh scans with --guidance-refine-steps $REF,
# seed set $SEED (default 0), blocks $BLOCKS (default both), scans $FROM-$TO, one scan per process.
cd "${WORK:-/work/exp/s37}" || exit 1
mkdir -p r logs
W=${W:-/work/exp/s36/d21k/weights}; TAG=${TAG:-d21k}; REF=${REF:-30}
one() {
  set -- $1
  o=r/${TAG}_r${REF}_$1_s$2_c$3
  [ -f $o/guided_table.json ] && return
  RAYON_NUM_THREADS=1 /work/bin/physnap-s36 eval guided --weights $W --clouds /work/data/testset_s1 --data /work/data/train \
    --skip-clouds $3 --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob --category-aware $1 --seed $2 \
    --guidance-refine-steps $REF ${LS:+--loss-scales $LS} --out $o > logs/${TAG}_r${REF}_$1_s$2_c$3.log 2>&1
}
export -f one; export W LS TAG REF
for c in $(seq ${FROM:-0} ${TO:-29}); do for a in ${BLOCKS:-no yes}; do echo "$a ${SEED:-0} $c"; done; done | xargs -P ${P:-2} -I{} bash -c 'one "{}"'
echo finished > ${TAG}_r${REF}_guided.done
