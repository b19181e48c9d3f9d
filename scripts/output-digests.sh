#!/usr/bin/env bash
# Digests of fixed-seed outputs, to show that a refactor changed no output byte: run it with the
# binary before and after and diff the two listings.
#
#   bash scripts/output-digests.sh [BIN] > digests.txt      (BIN default: target/release/physnap)
#
# It exports examples/cabinet.json, generates 2 unguided StorageFurniture samples (seed 5) and
# one guided completion of examples/scan_microwave.ply (seed 3, the default sampler), and runs
# one service job over REST (the same scan, seed 3, 60 steps) on loopback ports 18080/15051/19000,
# then prints the sha256 of every file written. ≈ 1 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-target/release/physnap}
W=$(mktemp -d)
SERVE_PID=
trap '[ -n "$SERVE_PID" ] && kill $SERVE_PID 2>/dev/null; rm -rf "$W"' EXIT
"$BIN" export --object examples/cabinet.json --out "$W/export" >/dev/null 2>&1
"$BIN" generate --category StorageFurniture --samples 2 --seed 5 --out "$W/uncond" >/dev/null 2>&1
"$BIN" generate --points examples/scan_microwave.ply --category Microwave --seed 3 \
  --out "$W/guided" >/dev/null 2>&1
"$BIN" serve --http 127.0.0.1:18080 --grpc 127.0.0.1:15051 --admin 127.0.0.1:19000 \
  --data-dir "$W/store" --progress-interval 0 >"$W/serve.log" 2>&1 &
SERVE_PID=$!
for _ in $(seq 1 100); do curl -sf localhost:19000/readyz >/dev/null && break; sleep 0.2; done
ID=$(curl -sf 'localhost:18080/v1/jobs?category=Microwave&seed=3&steps=60' \
  -H 'content-type: application/x-ply' --data-binary @examples/scan_microwave.ply \
  | grep -o '"id":"[^"]*"' | head -1 | cut -d'"' -f4)
curl -sfN "localhost:18080/v1/jobs/$ID/events" >/dev/null
mkdir -p "$W/service"
for a in model.glb robot.zip object.json ranking.json; do
  curl -sf -o "$W/service/$a" "localhost:18080/v1/jobs/$ID/artifacts/$a"
done
rm -rf "$W/store" "$W/serve.log"
# ranking.json of `generate` names the points file it read; the path is the same in both runs.
(cd "$W" && find . -type f | sort | xargs sha256sum)
