#!/usr/bin/env bash
# Abuse cases against `dpmp serve` on loopback, bounded in count and time
# (about two minutes), printing the figures the README quotes.
#
#   scripts/abuse.sh                   # release build, every case
#   CASES="zombie flood" scripts/abuse.sh
#   FLOOD=2000 scripts/abuse.sh        # idle connections in the flood (default 5000)
#
# Cases (scripts/abuse.py): zombie solves (too-short durations and maximal
# requests at once), slow header senders, a flood of idle connections, a
# burst of decompression-bomb PNGs; then here: a half-sent request during a
# shutdown (drain limit), and a second signal during a drain.
# Needs python3 (standard library only). Only loopback is used.
set -euo pipefail
cd "$(dirname "$0")/.."

PORT=${PORT:-18081}
ADDR="127.0.0.1:${PORT}"
OUT=${OUT:-target/abuse}
mkdir -p "$OUT"
cargo build --release --bin dpmp
BIN=target/release/dpmp
"$BIN" serve --print-typical-request 1 > "$OUT/typical.json"

start_server() {
  "$BIN" serve --addr "$ADDR" --header-timeout-ms 2000 --body-timeout-ms 2000 "$@" \
    2> "$OUT/server.log" &
  SERVER=$!
  for _ in $(seq 1 100); do
    curl -sf "http://$ADDR/healthz" >/dev/null 2>&1 && return
    sleep 0.1
  done
  echo "the server did not start; see $OUT/server.log" >&2
  exit 1
}
stop_server() { kill -TERM "$SERVER" 2>/dev/null || true; wait "$SERVER" 2>/dev/null || true; }
trap stop_server EXIT

echo "== $(nproc) cores; dpmp serve defaults but 2 s header and body timeouts"
start_server
ADDR=$ADDR SERVER_PID=$SERVER OUT=$OUT timeout 600 python3 scripts/abuse.py ${CASES:-}
stop_server

# A request whose body never comes, then SIGTERM: the drain ends at its limit.
start_server --drain-timeout-ms 1500
exec 3<>"/dev/tcp/127.0.0.1/$PORT"
printf 'POST /v1/optimize HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\ncontent-length: 1000\r\n\r\n{"pr' >&3
sleep 0.2
t0=$(date +%s.%N)
kill -TERM "$SERVER"
late=$(curl -s -o /dev/null -w '%{http_code}' "http://$ADDR/readyz" || true)
wait "$SERVER" || true
t1=$(date +%s.%N)
exec 3>&-
echo "shutdown with a half-sent request: exit after $(echo "$t1 - $t0" | bc) s (drain limit 1.5 s); /readyz during the drain: $late"

# A second signal during a drain exits at once.
start_server --drain-timeout-ms 30000
exec 3<>"/dev/tcp/127.0.0.1/$PORT"
printf 'POST /v1/optimize HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\ncontent-length: 1000\r\n\r\n{"pr' >&3
sleep 0.2
kill -TERM "$SERVER"
sleep 0.3
t0=$(date +%s.%N)
kill -TERM "$SERVER"
code=0
wait "$SERVER" || code=$?
t1=$(date +%s.%N)
exec 3>&-
echo "second signal during a 30 s drain: exit $code after $(echo "$t1 - $t0" | bc) s"
trap - EXIT
