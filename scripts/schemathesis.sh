#!/usr/bin/env bash
# Property-based API probe: schemathesis against `dpmp serve`, driven by
# api/openapi.yaml, with every check on, loopback only, bounded in examples
# and wall-clock time. The server runs with a bearer token and every request
# carries it (schemathesis' own ignored_auth check runs only where the spec
# makes auth mandatory; api/openapi.yaml declares it optional, `- {}`).
#
#   scripts/schemathesis.sh                  # the release binary, 50 examples per operation
#   MAX_EXAMPLES=20 scripts/schemathesis.sh
#   DPMP_BIN=target/debug/dpmp scripts/schemathesis.sh
#
# Knobs: DPMP_BIN (default target/release/dpmp; build it first), MAX_EXAMPLES
# (per operation in the examples and fuzzing phases, default 50), SEED
# (default 1, for reproducible runs), PHASES (default all four; the coverage
# phase adds ~2,500 deterministic boundary cases, ~20 s, and finds most of the
# real bugs), EXCLUDE_CHECKS (comma-separated, default none: e.g.
# positive_data_acceptance, which schema-valid but semantically invalid
# inputs such as a prior for another number of joints always trip), OUT
# (reports and the server log, default target/schemathesis).
# Installs schemathesis (pinned below) with pip when it is missing. Exits
# non-zero when schemathesis reports a failure or an error, when it runs past
# 600 s, or when the server does not start.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD

SCHEMATHESIS_VERSION=4.32.5    # 4.x CLI: `--checks all`, `--max-examples`, `--phases`
DPMP_BIN=${DPMP_BIN:-target/release/dpmp}
MAX_EXAMPLES=${MAX_EXAMPLES:-50}
SEED=${SEED:-1}
PHASES=${PHASES:-examples,coverage,fuzzing,stateful}
EXCLUDE_CHECKS=${EXCLUDE_CHECKS:-}
OUT=${OUT:-target/schemathesis}

if [[ ! -x "$DPMP_BIN" ]]; then
  echo "no executable $DPMP_BIN (cargo build --release --bin dpmp, or set DPMP_BIN)" >&2
  exit 2
fi

# schemathesis, installed when missing (CI starts on a fresh machine).
installed=$(python3 -c 'import schemathesis; print(schemathesis.__version__)' 2>/dev/null || true)
if [[ -z "$installed" ]]; then
  python3 -m pip install --quiet "schemathesis==${SCHEMATHESIS_VERSION}"
elif [[ "$installed" != "$SCHEMATHESIS_VERSION" ]]; then
  echo "note: schemathesis $installed is installed; this script was written for $SCHEMATHESIS_VERSION" >&2
fi

mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
WORK=$(mktemp -d)
SERVER=
PROBE=
cleanup() {
  # Stop schemathesis (if a signal cut it short) and the server, whatever
  # happened; the server drains for at most 5 s, then it is killed.
  if [[ -n "$PROBE" ]]; then kill -TERM "$PROBE" 2>/dev/null || true; wait "$PROBE" 2>/dev/null || true; fi
  if [[ -n "$SERVER" ]]; then
    kill -TERM "$SERVER" 2>/dev/null || true
    for _ in $(seq 1 50); do kill -0 "$SERVER" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$SERVER" 2>/dev/null || true
    wait "$SERVER" 2>/dev/null || true
  fi
  rm -rf "$WORK"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# A random token in a file only we can read.
(umask 077; python3 -c 'import secrets; print(secrets.token_urlsafe(32))' > "$WORK/token")
TOKEN=$(cat "$WORK/token")

# A free loopback port (the kernel's pick; a tiny race with other processes).
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
URL="http://127.0.0.1:${PORT}"

"$DPMP_BIN" serve --addr "127.0.0.1:${PORT}" --token-file "$WORK/token" 2> "$OUT/server.log" &
SERVER=$!
ready=
for _ in $(seq 1 300); do    # up to 30 s (the model loads first)
  if curl -sf "$URL/readyz" > /dev/null 2>&1; then ready=1; break; fi
  kill -0 "$SERVER" 2>/dev/null || break
  sleep 0.1
done
if [[ -z "$ready" ]]; then
  echo "dpmp serve did not become ready on $URL; its log:" >&2
  tail -n 30 "$OUT/server.log" >&2
  exit 1
fi
echo "== dpmp serve ready on $URL; schemathesis $(python3 -c 'import schemathesis; print(schemathesis.__version__)'), ${MAX_EXAMPLES} examples per operation, seed ${SEED}"

# Every check (less EXCLUDE_CHECKS), going on past a failure so that one run
# lists them all; failures and errors make schemathesis exit 1, the time
# bound makes `timeout` exit 124. It runs in OUT, which gets the reports
# (JUnit, NDJSON events) and its `.schemathesis/` crash cache (`st replay ID`
# from there), not the repository root.
exclude=()
if [[ -n "$EXCLUDE_CHECKS" ]]; then exclude=(--exclude-checks "$EXCLUDE_CHECKS"); fi
# In the background with `wait`, so that a signal to this script runs the
# traps at once instead of after schemathesis ends.
(cd "$OUT" && exec timeout 600 python3 -m schemathesis.cli run "$ROOT/api/openapi.yaml" \
  --url "$URL" \
  --header "Authorization: Bearer ${TOKEN}" \
  --checks all ${exclude[@]+"${exclude[@]}"} \
  --continue-on-failure \
  --phases "$PHASES" \
  --max-examples "$MAX_EXAMPLES" \
  --seed "$SEED" \
  --workers 1 \
  --request-timeout 30 \
  --generation-database none \
  --report junit,ndjson --report-dir . \
  --no-color) &
PROBE=$!
status=0
wait "$PROBE" || status=$?
PROBE=

if [[ $status -eq 124 ]]; then
  echo "schemathesis ran past 600 s" >&2
elif [[ $status -ne 0 ]]; then
  echo "schemathesis found failures (exit $status); reports in $OUT, server log $OUT/server.log" >&2
fi
exit "$status"
