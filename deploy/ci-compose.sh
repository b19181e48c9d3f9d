#!/usr/bin/env bash
# The compose deployment, run for real: deploy/docker-compose.yml (physnap + the Caddy gateway)
# started with podman-compose and deploy/compose.local.yml, with no image registry. `.ci/run`
# runs it; it exits non-zero on the first failed check, printing the service logs, and always tears
# the stack down (containers, volumes and network, by name).
#
#   bash deploy/ci-compose.sh                          # uses target/release/physnap
#   PHYSNAP_BIN=target/debug/physnap bash deploy/ci-compose.sh
#
# What it does:
#   1. builds localhost/debian:bookworm-slim from Debian's archive (mmdebstrap, the mirror apt
#      already uses), unless it exists; then the runtime image from the binary
#      (deploy/Containerfile.prebuilt) and the gateway image with Debian's caddy
#      (deploy/Containerfile.gateway);
#   2. `podman-compose up`, then waits for physnap's health check (`podman healthcheck run`:
#      there is no systemd to run it) and for the gateway;
#   3. through the gateway: 401 without a token, no admin endpoints, a REST job followed on its
#      SSE stream to `done`, its GLB checked by the Khronos validator and its URDF by
#      check_urdf, a gRPC WatchJob (h2c) of the same job with the `physnap watch` client;
#   4. a job accepted before `podman-compose restart physnap` finishes after it, and the first
#      job's artefacts are still served (the data volume is kept);
#   5. the scale-out profile: PostgreSQL (deploy/Containerfile.postgres) + 2 API replicas + 3
#      workers behind deploy/Caddyfile.scale; jobs submitted through that gateway are spread
#      over the workers and streamed to `done` by whichever API replica answers;
#   6. prints the image sizes, the time from `up` to healthy and one job's time through the
#      gateway; with PHYSNAP_CI_COMPARE=1 also directly (the container's address on the
#      compose network).
# Needs podman, podman-compose, mmdebstrap, runc, curl, python3, node with the validator
# (`bash .ci/setup` installs them) and root (rootful podman).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "$(id -u)" != 0 ]; then exec sudo --preserve-env=PHYSNAP_BIN,PHYSNAP_GATEWAY_PORT,PHYSNAP_CI_COMPARE,PATH bash "$0" "$@"; fi
BIN=${PHYSNAP_BIN:-target/release/physnap}
PROJECT=physnap-ci
PORT=${PHYSNAP_GATEWAY_PORT:-18080}
GW=http://127.0.0.1:$PORT
TOKEN=ci-token-$RANDOM$RANDOM
WORK=$(mktemp -d /tmp/physnap-ci-compose.XXXXXX)
PHYSNAP_CTR=${PROJECT}_physnap_1
GATEWAY_CTR=${PROJECT}_gateway_1
SCALE_SERVICES=(postgres api1 api2 worker1 worker2 worker3 gateway-scale)
SCALE_PORT=${PHYSNAP_SCALE_GATEWAY_PORT:-18081}
T0=$(date +%s)

say() { echo "ci-compose: $*"; }
fail() {
  echo "ci-compose: FAILED: $*" >&2
  exit 1
}
for tool in podman podman-compose mmdebstrap runc curl python3 node check_urdf; do
  command -v "$tool" >/dev/null || fail "$tool is missing (run bash .ci/setup)"
done
[ -x "$BIN" ] || fail "no physnap binary at $BIN (cargo build --release, or set PHYSNAP_BIN)"

# Podman settings for this host, kept out of /etc: crun cannot run on hybrid cgroups here, and
# raising RLIMIT_NOFILE to podman's default is not permitted.
cat >"$WORK/containers.conf" <<'EOF'
[containers]
default_ulimits = ["nofile=16384:16384", "nproc=16384:16384"]
[engine]
runtime = "runc"
cgroup_manager = "cgroupfs"
events_logger = "file"
EOF
export CONTAINERS_CONF=$WORK/containers.conf
# Docker-format images keep the HEALTHCHECK instruction (OCI images drop it).
export BUILDAH_FORMAT=docker
export PHYSNAP_TOKENS_FILE_ON_HOST=$WORK/tokens.txt PHYSNAP_GATEWAY_PORT=$PORT \
  PHYSNAP_SCALE_GATEWAY_PORT=$SCALE_PORT PHYSNAP_DB_PASSWORD=ci-db-$RANDOM$RANDOM
COMPOSE=(podman-compose -p "$PROJECT" -f deploy/docker-compose.yml -f deploy/compose.local.yml)

teardown() {
  local rc=$?
  if [ "$rc" != 0 ]; then
    for c in "$PHYSNAP_CTR" "$GATEWAY_CTR" "${SCALE_SERVICES[@]/#/${PROJECT}_}"; do
      c=${c%_1}_1
      echo "----- logs of $c -----" >&2
      podman logs --tail 200 "$c" >&2 2>&1 || true
    done
  fi
  "${COMPOSE[@]}" down -v -t 5 >/dev/null 2>&1 || true
  podman rm -f -i "$PHYSNAP_CTR" "$GATEWAY_CTR" >/dev/null 2>&1 || true
  for svc in "${SCALE_SERVICES[@]}"; do podman rm -f -i "${PROJECT}_${svc}_1" >/dev/null 2>&1 || true; done
  podman volume rm -f "${PROJECT}_physnap-data" "${PROJECT}_caddy-data" "${PROJECT}_postgres-data" \
    >/dev/null 2>&1 || true
  podman network rm -f "${PROJECT}_default" >/dev/null 2>&1 || true
  local left
  left=$(podman ps -a -q --filter "label=io.podman.compose.project=$PROJECT"
    podman volume ls -q --filter "label=io.podman.compose.project=$PROJECT")
  if [ -n "$left" ]; then
    echo "ci-compose: teardown left: $left" >&2
    rc=1
  fi
  rm -rf "$WORK"
  say "$([ "$rc" = 0 ] && echo passed || echo failed) in $(($(date +%s) - T0)) s"
  exit "$rc"
}
trap teardown EXIT

# ---- 1. images ---------------------------------------------------------------------------
if ! podman image exists localhost/debian:bookworm-slim; then
  mirror=$(sed -n 's/^URIs:[[:space:]]*//p' /etc/apt/sources.list.d/*.sources 2>/dev/null |
    tr ' ' '\n' | grep -v security | head -1 || true)
  if [ -z "$mirror" ] && [ -f /etc/apt/sources.list ]; then
    mirror=$(awk '$1 == "deb" { for (i = 2; i <= NF; i++) if ($i ~ /^[a-z]+:\/\//) { print $i; exit } }' \
      /etc/apt/sources.list | grep -v security | head -1 || true)
  fi
  [ -n "$mirror" ] || fail "no Debian mirror found in /etc/apt/sources.list{,.d}"
  say "building localhost/debian:bookworm-slim from $mirror (mmdebstrap)"
  mmdebstrap --variant=minbase --quiet bookworm "$WORK/rootfs.tar" "$mirror"
  podman import -q "$WORK/rootfs.tar" localhost/debian:bookworm-slim >/dev/null
  rm -f "$WORK/rootfs.tar"
fi
mkdir -p "$WORK/ctx"
cp "$BIN" "$WORK/ctx/physnap"
strip "$WORK/ctx/physnap" 2>/dev/null || true
say "building localhost/physnap:local from $BIN"
podman build -q -f deploy/Containerfile.prebuilt -t localhost/physnap:local "$WORK/ctx" >/dev/null
say "building localhost/physnap-gateway:local (Debian's caddy)"
podman build -q -f deploy/Containerfile.gateway -t localhost/physnap-gateway:local deploy >/dev/null
say "building localhost/physnap-postgres:local (Debian's postgresql)"
podman build -q -f deploy/Containerfile.postgres -t localhost/physnap-postgres:local deploy >/dev/null

# ---- 2. up -------------------------------------------------------------------------------
echo "ci $TOKEN" >"$PHYSNAP_TOKENS_FILE_ON_HOST"
chmod 644 "$PHYSNAP_TOKENS_FILE_ON_HOST"
# A stack left by an interrupted run would hold the port and the names.
"${COMPOSE[@]}" down -v -t 1 >/dev/null 2>&1 || true
say "podman-compose up"
t_up=$(date +%s.%N)
"${COMPOSE[@]}" up -d --no-build physnap gateway >"$WORK/up.log" 2>&1 || {
  cat "$WORK/up.log" >&2
  fail "podman-compose up"
}

wait_healthy() { # [container] (default: physnap's)
  local ctr=${1:-$PHYSNAP_CTR}
  local deadline=$(($(date +%s) + 90))
  until podman healthcheck run "$ctr" >/dev/null 2>&1; do
    [ "$(date +%s)" -lt "$deadline" ] || fail "$ctr not healthy after 90 s"
    sleep 0.5
  done
}
wait_healthy
t_healthy=$(date +%s.%N)
deadline=$(($(date +%s) + 30))
until [ "$(curl -s -o /dev/null -w '%{http_code}' "$GW/v1/categories")" = 200 ]; do
  [ "$(date +%s)" -lt "$deadline" ] || fail "the gateway does not answer on $GW"
  sleep 0.5
done
say "healthy $(python3 -c "print(f'{$t_healthy - $t_up:.1f}')") s after up"

# ---- 3. through the gateway --------------------------------------------------------------
AUTH=(-H "Authorization: Bearer $TOKEN")
code() { curl -s -o /dev/null -w '%{http_code}' "$@"; }
json() { python3 -c "import json, sys; d = json.load(sys.stdin); print($1)"; }

[ "$(code "$GW/v1/jobs")" = 401 ] || fail "GET /v1/jobs without a token is not 401"
[ "$(code -H 'Authorization: Bearer wrong-token' "$GW/v1/jobs")" = 401 ] ||
  fail "GET /v1/jobs with a wrong token is not 401"
for p in /metrics /livez /readyz; do
  c=$(code "$GW$p")
  [ "$c" = 404 ] || fail "the admin endpoint $p is reachable through the gateway ($c)"
done
[ -z "$(podman port "$PHYSNAP_CTR")" ] || fail "physnap publishes ports on the host: $(podman port "$PHYSNAP_CTR")"
say "401 without a token; admin endpoints not reachable through the gateway"

# A short guided job on the shipped weights: the microwave scan, 12 DDIM steps, no refinement
# (a CI run uses the debug binary).
submit() { # base-url seed -> job id
  curl -sS --fail-with-body "${AUTH[@]}" -H 'Content-Type: application/x-ply' \
    --data-binary @examples/scan_microwave.ply \
    "$1/v1/jobs?category=Microwave&steps=12&refine_steps=0&resolution=12&seed=$2" >"$WORK/submit.json" ||
    fail "submit: $(cat "$WORK/submit.json")"
  json "d['id']" <"$WORK/submit.json"
}
follow() { # base-url id -> the state in the `done` event of the job's SSE stream
  curl -sfN --max-time 300 "${AUTH[@]}" "$1/v1/jobs/$2/events" >"$WORK/sse-$2.txt" ||
    fail "the SSE stream of $2 failed"
  awk '/^event: done/ { d = 1; next } d && /^data:/ { sub(/^data: ?/, ""); print; exit }' \
    "$WORK/sse-$2.txt" >"$WORK/done-$2.json"
  [ -s "$WORK/done-$2.json" ] || fail "no done event on the SSE stream of $2"
  json "d['state']" <"$WORK/done-$2.json"
}
t_job=$(date +%s.%N)
ID=$(submit "$GW" 1)
follow "$GW" "$ID" >"$WORK/state"
t_gw=$(python3 -c "print(f'{$(date +%s.%N) - $t_job:.1f}')")
state=$(cat "$WORK/state")
[ "$state" = SUCCEEDED ] || fail "job $ID ended $state"
grep -q '^event: progress' "$WORK/sse-$ID.txt" || fail "no progress events on the SSE stream of $ID"
say "REST job $ID: SSE followed to done ($state) in $t_gw s"
curl -sf "${AUTH[@]}" -o "$WORK/model.glb" "$GW/v1/jobs/$ID/artifacts/model.glb" ||
  fail "downloading model.glb"
node tests/tools/validate_gltf.js "$WORK/model.glb" >"$WORK/gltf.json" || true
errors=$(json "d['numErrors'], d['numWarnings']" <"$WORK/gltf.json") ||
  fail "the glTF validator did not run"
[ "$errors" = "0 0" ] || fail "model.glb: validator errors, warnings: $errors"
curl -sf "${AUTH[@]}" -o "$WORK/robot.zip" "$GW/v1/jobs/$ID/artifacts/robot.zip" ||
  fail "downloading robot.zip"
python3 -c "import zipfile, sys; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])" \
  "$WORK/robot.zip" "$WORK/robot"
urdf=$(find "$WORK/robot" -name '*.urdf' | head -1)
[ -n "$urdf" ] && check_urdf "$urdf" >/dev/null || fail "robot.zip: check_urdf"
say "model.glb: 0 validator errors or warnings; the URDF passes check_urdf"
"$BIN" watch "$ID" --server "$GW" --token "$TOKEN" 2>"$WORK/watch.txt" ||
  fail "gRPC WatchJob through the gateway: $(cat "$WORK/watch.txt")"
grep -q "job $ID: SUCCEEDED" "$WORK/watch.txt" || fail "gRPC WatchJob: $(cat "$WORK/watch.txt")"
say "gRPC WatchJob of $ID through the gateway (h2c): SUCCEEDED"

# With PHYSNAP_CI_COMPARE=1, the same job directly on the container's address, for the
# gateway's overhead (BENCHMARKS.md; CI skips it).
if [ "${PHYSNAP_CI_COMPARE:-0}" = 1 ]; then
  ip=$(podman inspect -f '{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}' "$PHYSNAP_CTR")
  t_job=$(date +%s.%N)
  DIRECT=$(submit "http://$ip:8080" 1)
  follow "http://$ip:8080" "$DIRECT" >"$WORK/state"
  state=$(cat "$WORK/state")
  t_direct=$(python3 -c "print(f'{$(date +%s.%N) - $t_job:.1f}')")
  [ "$state" = SUCCEEDED ] || fail "direct job $DIRECT ended $state"
  say "the same job directly on $ip:8080: $t_direct s (through the gateway: $t_gw s)"
fi

# ---- 4. restart --------------------------------------------------------------------------
glb_sha=$(sha256sum "$WORK/model.glb" | cut -d' ' -f1)
A=$(submit "$GW" 2)
B=$(submit "$GW" 3)
before=$(curl -sf "${AUTH[@]}" "$GW/v1/jobs/$B" | json "d['state']")
case "$before" in QUEUED | RUNNING) ;; *) fail "job $B was $before before the restart" ;; esac
say "restarting physnap with jobs $A and $B accepted ($B $before)"
"${COMPOSE[@]}" restart physnap >"$WORK/restart.log" 2>&1 || {
  cat "$WORK/restart.log" >&2
  fail "podman-compose restart physnap"
}
wait_healthy
for j in "$A" "$B"; do
  follow "$GW" "$j" >"$WORK/state"
  state=$(cat "$WORK/state")
  [ "$state" = SUCCEEDED ] || fail "job $j ended $state after the restart"
done
curl -sf "${AUTH[@]}" -o "$WORK/model-again.glb" "$GW/v1/jobs/$ID/artifacts/model.glb" ||
  fail "job $ID's model.glb is gone after the restart"
[ "$(sha256sum "$WORK/model-again.glb" | cut -d' ' -f1)" = "$glb_sha" ] ||
  fail "job $ID's model.glb changed across the restart"
say "after the restart: $A and $B SUCCEEDED; $ID's model.glb is unchanged (volume kept)"

# ---- 5. scale-out -------------------------------------------------------------------------
say "podman-compose up of the scale profile: ${SCALE_SERVICES[*]}"
t_up=$(date +%s.%N)
"${COMPOSE[@]}" up -d --no-build "${SCALE_SERVICES[@]}" >"$WORK/up-scale.log" 2>&1 || {
  cat "$WORK/up-scale.log" >&2
  fail "podman-compose up (scale)"
}
for svc in api1 api2 worker1 worker2 worker3; do wait_healthy "${PROJECT}_${svc}_1"; done
SGW=http://127.0.0.1:$SCALE_PORT
deadline=$(($(date +%s) + 30))
until [ "$(curl -s -o /dev/null -w '%{http_code}' "$SGW/v1/categories")" = 200 ]; do
  [ "$(date +%s)" -lt "$deadline" ] || fail "the scale gateway does not answer on $SGW"
  sleep 0.5
done
say "scale profile healthy $(python3 -c "print(f'{$(date +%s.%N) - $t_up:.1f}')") s after up"
ids=()
for seed in 11 12 13 14 15 16; do ids+=("$(submit "$SGW" "$seed")"); done
for j in "${ids[@]}"; do
  state=$(follow "$SGW" "$j")
  [ "$state" = SUCCEEDED ] || fail "scale job $j ended $state"
done
grep -q '^event: progress' "$WORK/sse-${ids[0]}.txt" ||
  fail "no progress from a worker reached an API replica's SSE stream"
ran=0
for svc in worker1 worker2 worker3; do
  n=$(podman logs "${PROJECT}_${svc}_1" 2>&1 | grep -c 'job leased' || true)
  say "$svc ran $n job(s)"
  [ "$n" -gt 0 ] && ran=$((ran + 1))
done
[ "$ran" -ge 2 ] || fail "the jobs were not spread over the workers"
for svc in api1 api2; do
  n=$(podman logs "${PROJECT}_${svc}_1" 2>&1 | grep -c 'job leased' || true)
  [ "$n" = 0 ] || fail "the API replica $svc ran jobs"
done
curl -sf "${AUTH[@]}" -o "$WORK/scale.glb" "$SGW/v1/jobs/${ids[0]}/artifacts/model.glb" ||
  fail "downloading a scale job's model.glb"
"$BIN" watch "${ids[1]}" --server "$SGW" --token "$TOKEN" 2>"$WORK/watch-scale.txt" ||
  fail "gRPC WatchJob through the scale gateway: $(cat "$WORK/watch-scale.txt")"
say "scale: ${#ids[@]} jobs through 2 API replicas on $ran of 3 workers, all SUCCEEDED; SSE, gRPC and artefacts through the gateway"

# ---- 6. facts ----------------------------------------------------------------------------
podman images --format '{{.Repository}}:{{.Tag}} {{.Size}}' |
  grep -E '^localhost/(debian:bookworm-slim|physnap:local|physnap-gateway:local) ' |
  sed 's/^/ci-compose: image /'
