#!/usr/bin/env bash
# Device run: eval guided for candidate v5r2, seed set 1000, scans 11-29, both blocks,
# one (block, scan) unit per process, 16 at a time, single-threaded each.
cd "$(dirname "$0")" || exit 1
T0=$(date +%s)
xz -dc pn.xz > pn && chmod +x pn && tar xJf devdata.tar.xz || exit 1
R=$(cd .. && pwd)
W=$PWD/v5r2w
bash $R/docs/eval/recipe128/v5r2/assemble.sh ./pn $W > logs_asm.txt 2>&1 || { tail logs_asm.txt; exit 1; }
echo "assembled at $(( $(date +%s) - T0 )) s"
sha256sum $W/*.safetensors
nproc
mkdir -p r logs
units() { for c in $(seq 11 29); do echo "no 1000 $c"; echo "yes 1000 $c"; done; }
one() {
  set -- $1
  o=r/v5r2_$1_s$2_c$3
  RAYON_NUM_THREADS=1 ./pn eval guided --weights "$W" --clouds testset_s1 --data train --skip-clouds $3 \
    --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $1 --seed $2 \
    --out $o > logs/v5r2_$1_s$2_c$3.log 2>&1
}
export -f one; export W
units | timeout ${BUDGET:-420} xargs -P ${P:-16} -I{} bash -c 'one "{}"'
echo "elapsed $(( $(date +%s) - T0 )) s; done units: $(ls r/*/guided_table.json 2>/dev/null | wc -l)"
tar czf $OUT/res.tgz r logs
