#!/usr/bin/env bash
# Device run: eval guided for candidate v5r (and the shipped weights at a second seed set) on
# the 30 fresh scans, one (job, scan) unit per process, 16 at a time, single-threaded each.
cd "$(dirname "$0")" || exit 1
T0=$(date +%s)
xz -dc pn.xz > pn && chmod +x pn && tar xJf devdata.tar.xz || exit 1
nproc; lscpu | grep -i "model name"
R=$(cd .. && pwd)
mkdir -p r logs
units() {
  for job in "v5r no 0" "v5r yes 0" "v5r no 1000" "v5r yes 1000" "shipped no 1000"; do
    for c in $(seq 0 29); do echo "$job $c"; done
  done
}
one() {
  set -- $1
  w=$R/docs/eval/recipe128/v5r/weights; [ "$1" = shipped ] && w=$R/weights
  o=r/$1_$2_s$3_c$4
  RAYON_NUM_THREADS=1 ./pn eval guided --weights "$w" --clouds testset_s1 --data train --skip-clouds $4 \
    --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $2 --seed $3 \
    --out $o > logs/$1_$2_s$3_c$4.log 2>&1
}
export -f one; export R
units | tail -n +$(( ${SKIP:-0} + 1 )) | timeout ${BUDGET:-500} xargs -P ${P:-16} -I{} bash -c 'one "{}"'
echo "elapsed $(( $(date +%s) - T0 )) s; done units: $(ls r/*/guided_table.json 2>/dev/null | wc -l)"
tar czf $OUT/res.tgz r logs
