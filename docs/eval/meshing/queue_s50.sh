#!/bin/bash
# Session 50 queue: fclg2 --retrieval all at 32³, seeds 6-8 (category samples only) and the
# 48 + 48 run at seed 12345 (1-NNA); then the 30-scan guided check on s47a (lg2's slices' binary).
cd /work/exp/s50
W=/work/exp/s48/fclg2/weights
while pgrep -f "gen32ra_fclg2_[45].json" >/dev/null; do sleep 10; done
full() {
  RAYON_NUM_THREADS=1 /work/bin/physnap-s47a eval generative --weights $W --data /work/data/train \
    --samples 48 --refs 48 --per-category 4 --states 4 --points 256 --seed 12345 --retrieval all \
    --progress-interval 60 --out gen32rafull_fclg2_12345.json > gen32rafull_fclg2_12345.log 2>&1
}
export -f full; export W
printf '%s\n' full 6 7 8 | xargs -P 2 -I{} bash -c 'if [ {} = full ]; then full; else bash genra32.sh fclg2 $W {}; fi'
echo gen > gen.done
W=$W TAG=fclg2 WORK=/work/exp/s47/gchk VARIANTS=pc+pen+mob BIN=/work/bin/physnap-s47a bash /work/main/scripts/guided-slices.sh > guided.out 2>&1
echo guided > guided.done
