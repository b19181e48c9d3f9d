#!/usr/bin/env bash
# Session 31: the fresh scans' category-aware block, scans 15-29 x 2, shipped and v5.
# /work/data/testset_s1_15_29 (eval guided has --max-clouds but no offset) was made with:
#   mkdir -p /work/data/testset_s1_15_29 && python3 -c "import json,shutil
#   d=json.load(open('/work/data/testset_s1/testset.json')); d['clouds']=d['clouds'][15:30]
#   [shutil.copy('/work/data/testset_s1/'+c['cloud'],'/work/data/testset_s1_15_29/') for c in d['clouds']]
#   json.dump(d,open('/work/data/testset_s1_15_29/testset.json','w'))"
cd /work/exp/s30
B=/work/bin/physnap-s27
for w in shipped v5; do
  case $w in shipped) W=/work/exp/s30/shipped_w;; v5) W=v5/weights;; esac
  RAYON_NUM_THREADS=1 $B eval guided --weights $W --clouds /work/data/testset_s1_15_29 --max-clouds 15 --samples-per-cloud 2 \
    --variants pc+pen+mob --category-aware yes --out s1b_g_${w}_yes > s1b_g_${w}_yes.log 2>&1 &
done
wait
echo done > s1b_yes.done
