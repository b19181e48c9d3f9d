#!/usr/bin/env bash
# The REST contract checked by an outside fuzzer: schemathesis (PyPI, pinned) against a live
# `physnap serve` on the tiny test weights, every check, for a bounded time. Exits non-zero on
# any failure. `.ci/run` runs it after the tests (their build provides the binaries).
#
#   bash scripts/ci-schemathesis.sh            # target/debug/physnap, 150 s of fuzzing
#   PHYSNAP_BIN=target/release/physnap SCHEMATHESIS_MAX_TIME=300 SCHEMATHESIS_SEED=2 \
#     bash scripts/ci-schemathesis.sh
# Settings (one documented relaxation on POST /v1/jobs) are in scripts/schemathesis.toml.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${PHYSNAP_BIN:-target/debug/physnap}
TINY=${PHYSNAP_TINY_WEIGHTS_BIN:-$(dirname "$BIN")/examples/tiny_weights}
MAX_TIME=${SCHEMATHESIS_MAX_TIME:-150}
VENV=${SCHEMATHESIS_VENV:-tests/tools/stvenv}
[ -x "$BIN" ] || { echo "ci-schemathesis: no physnap binary at $BIN" >&2; exit 1; }
[ -x "$TINY" ] || { echo "ci-schemathesis: no $TINY (cargo build --example tiny_weights)" >&2; exit 1; }
if ! "$VENV/bin/schemathesis" --version 2>/dev/null | grep -q '4.32.5'; then
  python3 -m venv "$VENV"
  "$VENV/bin/python" -m pip install --disable-pip-version-check -q schemathesis==4.32.5
fi
WORK=$(mktemp -d /tmp/physnap-schemathesis.XXXXXX)
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
TOKEN=fuzz-token-$RANDOM$RANDOM
"$TINY" "$WORK/weights"
"$BIN" serve --weights "$WORK/weights" --data-dir "$WORK/data" --tokens "fuzz:$TOKEN" \
  --http "127.0.0.1:$PORT" --grpc 127.0.0.1:0 --admin 127.0.0.1:0 --drain-timeout 1 >"$WORK/server.log" 2>&1 &
SERVER=$!
cleanup() {
  local rc=$?
  kill "$SERVER" 2>/dev/null && wait "$SERVER" 2>/dev/null
  if [ "$rc" != 0 ]; then
    echo "----- server log (last 50 lines) -----" >&2
    tail -50 "$WORK/server.log" >&2
  fi
  rm -rf "$WORK"
  exit "$rc"
}
trap cleanup EXIT
for _ in $(seq 100); do
  curl -sf -o /dev/null "http://127.0.0.1:$PORT/v1/categories" -H "Authorization: Bearer $TOKEN" && break
  sleep 0.2
done
"$VENV/bin/schemathesis" --config-file scripts/schemathesis.toml run openapi.yaml --url "http://127.0.0.1:$PORT" \
  -H "Authorization: Bearer $TOKEN" --checks all --max-time "$MAX_TIME" \
  --request-timeout 30 --seed "${SCHEMATHESIS_SEED:-1}" --no-color
