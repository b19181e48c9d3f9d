#!/usr/bin/env bash
# Session 36: rebuild the data, encode the shipped shape prior's codes, set up d21k's resume.
set -ex
B=/work/bin/physnap-s36
cd /work/exp/s36
[ -d /work/data/train ] || { $B data synth --out /work/data/synth --objects 3000 --seed 0 > synth.log
  $B data import --partnet-mobility /work/data/synth --out /work/data/train > import.log; }
[ -d /work/data/testset_s1 ] || $B data testset --data /work/data/train --out /work/data/testset_s1 --count 30 --seed 1 > testset.log
[ -f codes/codebook.npy ] || RAYON_NUM_THREADS=2 $B train encode --weights /work/main/weights --data /work/data/train --out codes > encode.log 2>&1
mkdir -p d21k/weights d14k_ship
cp /work/main/weights/*.safetensors d14k_ship/
cp /work/main/docs/eval/recipe128/d14k/{denoiser.safetensors,manifest.json} d14k_ship/
cp /work/main/weights/*.safetensors d21k/weights/
cp /work/main/docs/eval/recipe128/d14k/{denoiser.safetensors,manifest.json} d21k/weights/
sha=$(sha256sum d21k/weights/denoiser.safetensors | cut -d' ' -f1)
echo "{\"step\": 14000, \"sha256\": \"$sha\", \"loss_ema\": 0.0252, \"wall_seconds_total\": 6476}" > d21k/weights/checkpoint.json
echo prepped > prep.done
