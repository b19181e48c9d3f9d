#!/usr/bin/env bash
# Waits for the one-go run (run.sh) to exit, then commits its weights folder, report and the
# time(1) summary into docs/eval/one_go/, so that the next session (a fresh machine) can score
# them: this session's device time is spent and the 2-core evaluations (≈ 13 min) would not fit.
cd /work/main || exit 1
until grep -q '^exit ' /work/exp/s52/repro.log 2>/dev/null; do sleep 20; done
sleep 40   # let watch.sh commit the last stage first
mkdir -p docs/eval/one_go/weights
cp /work/exp/s52/repro/weights/*.safetensors /work/exp/s52/repro/weights/*.json docs/eval/one_go/weights/ 2>/dev/null
cp /work/exp/s52/repro/stages.tsv /work/exp/s52/repro/recipe.knobs docs/eval/one_go/ 2>/dev/null
grep -v 'INFO physnap: \(shape\|diffusion\|encode\): ' /work/exp/s52/repro.log | tail -200 > docs/eval/one_go/repro_log_tail.txt
git add docs/eval/one_go
git commit -q -m "The recipe in one go (session 52): $(tail -1 /work/exp/s52/repro.log); its weights, stages.tsv and log tail committed for the next session's evaluation" -- docs/eval/one_go
