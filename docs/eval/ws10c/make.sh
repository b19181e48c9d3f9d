#!/usr/bin/env bash
# Session 42: candidate ws10c = the shipped weights (s14r) with session 41's third decoder cycle
# (docs/eval/wrong_side/run.sh, W = 10: 3,000 steps, seed 2, eikonal 0.03, --wrong-side 10,
# encoder frozen) installed, then the guided slices (30 fresh scans x 2, seed set 0, both
# blocks, pc+pen+mob, session 39's binary as s14r's and ov3's runs), then after.sh (eval shape
# and eval generative at seeds 12345 / 1 / 2). Merged and compared with
#   scripts/merge-guided-slices.py --out ws10c_{no,yes}_s0.json r/ws10c_{no,yes}_s0_c*
#   scripts/compare-guided.py --a ws10c_A_s0.json --b ../single_schedule/s14r_A_s0.json \
#     --variant pc+pen+mob --aware A --label-a ws10c --label-b s14r --common   (A = no, yes)
set -euo pipefail
cd /work/exp/s42/ws10c
cp -r /work/main/weights weights
/work/bin/physnap-s42b train install-shape --shape /work/exp/s41/ws/cycle3_ws10 --weights weights
W=/work/exp/s42/ws10c/weights TAG=ws10c VARIANTS=pc+pen+mob BIN=/work/bin/physnap-s39 \
  WORK=/work/exp/s42/ws10c bash /work/main/scripts/guided-slices.sh
bash after.sh
