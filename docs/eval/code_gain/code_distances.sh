#!/usr/bin/env bash
# Session 51: do fcg2's generated shape codes sit closer to the training codes than lg2's?
# The same generate calls as docs/eval/ceilings (session 45), for both weights, then
# docs/eval/ceilings/code_distances.py against each weights' own codes (lg2: NAP's encoding of
# the shipped prior, /work/exp/s44/codes; fcg2: the fitted codes, /work/exp/s46/codes_fit).
cd /work/exp/s51/cd || exit 1
B=/work/bin/physnap-s50a
for w in lg2:/work/exp/s47/lg2/weights fcg2:/work/main/weights; do
  t=${w%%:*}; W=${w#*:}
  RAYON_NUM_THREADS=1 $B generate --weights $W --samples 24 --seed 200 --out unc_$t > gen_unc_$t.log 2>&1 &
  RAYON_NUM_THREADS=1 $B generate --weights $W --samples 12 --seed 300 --sampler ddpm --steps 0 --out ddpm_$t > gen_ddpm_$t.log 2>&1
  wait
done
S=/work/main/docs/eval/ceilings/code_distances.py
{ echo "== lg2 (codes /work/exp/s44/codes)"; python3 $S /work/exp/s44/codes unc_lg2 ddpm_lg2
  echo "== fcg2 (codes /work/exp/s46/codes_fit)"; python3 $S /work/exp/s46/codes_fit unc_fcg2 ddpm_fcg2; } > code_distances.txt 2>&1
echo done > cd.done
# Then fclg2 (the same fitted codes at --code-gain 1), run by hand the same way:
#   generate --weights /work/exp/s48/fclg2/weights --samples 24 --seed 200 --out unc_fclg2
#   generate --weights /work/exp/s48/fclg2/weights --samples 12 --seed 300 --sampler ddpm --steps 0 --out ddpm_fclg2
#   python3 code_distances.py /work/exp/s46/codes_fit unc_fclg2 ddpm_fclg2
