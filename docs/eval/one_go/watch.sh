#!/usr/bin/env bash
# Copies the run's stages.tsv into this folder and commits it after every finished stage, so that
# the record survives the session even if the run does not finish in it.
cd /work/main || exit 1
seen=0
while true; do
  f=/work/exp/s52/repro/stages.tsv
  if [ -f "$f" ]; then
    n=$(wc -l < "$f")
    if [ "$n" != "$seen" ]; then
      cp "$f" docs/eval/one_go/stages.tsv
      git add docs/eval/one_go/stages.tsv
      git commit -q -m "The recipe in one go (session 52): $(tail -1 "$f" | cut -f1,2 | tr '\t' ' ') s, $n stages done" -- docs/eval/one_go/stages.tsv
      seen=$n
    fi
  fi
  grep -q '^exit ' /work/exp/s52/repro.log 2>/dev/null && break
  sleep 30
done
