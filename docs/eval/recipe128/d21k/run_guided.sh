#!/usr/bin/env bash
# Session 36: guided checks of a candidate on the 30 fresh scans, seed set $SEED (default 0),
# blocks $BLOCKS (default both), default guidance (or --loss-scales $LS), one scan per process.
cd /work/exp/s36 || exit 1
mkdir -p r logs
W=${W:-d21k/weights}; TAG=${TAG:-d21k}
one() {
  set -- $1
  o=r/${TAG}_$1_s$2_c$3
  [ -f $o/guided_table.json ] && return
  RAYON_NUM_THREADS=1 /work/bin/physnap-s36 eval guided --weights $W --clouds /work/data/testset_s1 --data /work/data/train \
    --skip-clouds $3 --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $1 --seed $2 \
    ${LS:+--loss-scales $LS} --out $o > logs/${TAG}_$1_s$2_c$3.log 2>&1
}
export -f one; export W LS TAG
for c in $(seq ${FROM:-0} ${TO:-29}); do for a in ${BLOCKS:-no yes}; do echo "$a ${SEED:-0} $c"; done; done | xargs -P ${P:-2} -I{} bash -c 'one "{}"'
echo finished > ${TAG}_guided.done
