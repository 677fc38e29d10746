#!/usr/bin/env bash
# Load benchmark of `dpmp serve` on loopback, bounded in time.
#
#   scripts/load.sh                # release build, 10 s per point, 60 s memory run
#   PROFILE=dev DURATION=5s MEMORY_S=30 scripts/load.sh
#   SEEDS="0" scripts/load.sh      # one typical problem (default: seeds 0-19 in turn)
#   ROUTES=plan MEMORY_S=0 scripts/load.sh   # /v1/plan only
#
# Measures /v1/optimize on typical problems (real-like prior, 10-obstacle
# cluster, 150 samples, 2 cm clearance; `dpmp serve --print-typical-request`),
# each client posting the seeds in turn so the figure is that of a mix of
# problems rather than of one, at 1, 8 and 64 concurrent clients with wrk (installed with apt-get when
# missing), then resident memory (VmRSS) every 5 s over a run at 8 clients.
# /v1/plan is measured too when a model exists at models/default (needs
# python3 to build the 640x480 JPEG body). Only loopback is used.
set -euo pipefail
cd "$(dirname "$0")/.."

PROFILE=${PROFILE:-release}
DURATION=${DURATION:-10s}
MEMORY_S=${MEMORY_S:-60}
PORT=${PORT:-18080}
ADDR="127.0.0.1:${PORT}"
OUT=${OUT:-target/load}
mkdir -p "$OUT"

if ! command -v wrk >/dev/null; then
  echo "installing wrk (apt-get)" >&2
  apt-get install -y wrk >/dev/null || sudo apt-get install -y wrk >/dev/null
fi

if [ "$PROFILE" = "release" ]; then
  cargo build --release --bin dpmp
  BIN=target/release/dpmp
else
  cargo build --bin dpmp
  BIN=target/debug/dpmp
fi

SEEDS=${SEEDS:-$(seq -s ' ' 0 19)}
OPTIMIZE_BODIES=()
for seed in $SEEDS; do
  "$BIN" serve --print-typical-request "$seed" > "$OUT/optimize-$seed.json"
  OPTIMIZE_BODIES+=("$OUT/optimize-$seed.json")
done
# Each wrk thread posts the bodies listed in bodies.txt in turn.
cat > "$OUT/post.lua" <<LUA
local bodies = {}
for path in io.lines("$OUT/bodies.txt") do
  local f = io.open(path, "rb")
  bodies[#bodies + 1] = f:read("*a")
  f:close()
end
local next_body = 0
wrk.method = "POST"
wrk.headers["Content-Type"] = "application/json"
request = function()
  next_body = next_body % #bodies + 1
  return wrk.format(nil, nil, nil, bodies[next_body])
end
LUA

"$BIN" serve --addr "$ADDR" --queue 1024 --deadline-ms 5000 2> "$OUT/server.log" &
SERVER=$!
trap 'kill -TERM $SERVER 2>/dev/null || true; wait $SERVER 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do
  curl -sf "http://$ADDR/healthz" >/dev/null 2>&1 && break
  sleep 0.1
done

run_wrk() { # route clients duration
  local threads=$(( $2 < 2 ? $2 : 2 ))
  wrk -t "$threads" -c "$2" -d "$3" --timeout 30s --latency -s "$OUT/post.lua" "http://$ADDR$1"
}

summarise() { # route clients < wrk output
  awk -v route="$1" -v c="$2" '
    /Requests\/sec/ {rps=$2}
    /^ +50%/ {p50=$2} /^ +99%/ {p99=$2}
    /Non-2xx/ {errors=$NF}
    /Socket errors/ {sock=$0}
    END {printf "%s clients=%s req/s=%s p50=%s p99=%s non2xx=%s %s\n", route, c, rps, p50, p99, (errors==""?0:errors), sock}'
}

use_bodies() { # body...
  printf '%s\n' "$@" > "$OUT/bodies.txt"
}

bench_route() { # route body...
  local route=$1
  shift
  use_bodies "$@"
  run_wrk "$route" 1 2s > /dev/null # warm-up
  for c in 1 8 64; do
    run_wrk "$route" "$c" "$DURATION" | tee "$OUT/wrk-$(basename "$route")-$c.txt" | summarise "$route" "$c"
  done
}

echo "== $(nproc) cores, profile $PROFILE, $DURATION per point"
echo "== /v1/optimize on typical seeds: $SEEDS"
[ "${ROUTES:-all}" = plan ] || bench_route /v1/optimize "${OPTIMIZE_BODIES[@]}"

if [ -f models/default/config.json ] && command -v python3 >/dev/null; then
  # A real generated plant (its image as a 640x480 JPEG, its depth PNG, box and scene).
  python3 -c "import PIL" 2>/dev/null || python3 -m pip install --quiet pillow
  rm -rf "$OUT/plant"
  "$BIN" data generate --out "$OUT/plant" --configs 1 --berries-per-config 1 --demos 2 --seed 5 >/dev/null
  python3 - "$OUT/plant" "$OUT/plan.json" <<'PY'
import base64, io, json, sys
from PIL import Image
data_dir, out = sys.argv[1], sys.argv[2]
manifest = json.load(open(f"{data_dir}/manifest.json"))
entry = (manifest.get("targets") or manifest.get("entries"))[0]
record = json.load(open(f"{data_dir}/{entry['record']}"))
buf = io.BytesIO()
Image.open(f"{data_dir}/{record['image']}").convert("RGB").save(buf, format="JPEG", quality=90)
body = {"image_base64": base64.b64encode(buf.getvalue()).decode(), "target_box": record["box"],
        "mask_applied": True, "obstacles": record["scene"]["obstacles"], "clearance_m": 0.02}
if record.get("depth"):  # the aligned depth image: the depth-aware plan
    body["depth_base64"] = base64.b64encode(open(f"{data_dir}/{record['depth']}", "rb").read()).decode()
json.dump(body, open(out, "w"))
PY
  bench_route /v1/plan "$OUT/plan.json"
else
  echo "/v1/plan skipped: no model at models/default (train one first, see README)"
fi

if [ "$MEMORY_S" -le 0 ]; then
  exit 0
fi
echo "== resident memory over ${MEMORY_S} s at 8 clients (/v1/optimize)"
use_bodies "${OPTIMIZE_BODIES[@]}"
run_wrk /v1/optimize 8 "${MEMORY_S}s" > "$OUT/wrk-memory.txt" &
WRK=$!
for t in $(seq 0 5 "$MEMORY_S"); do
  echo "t=${t}s $(grep VmRSS /proc/$SERVER/status)"
  sleep 5
done
wait $WRK
summarise /v1/optimize 8 < "$OUT/wrk-memory.txt"
echo "peak: $(grep VmHWM /proc/$SERVER/status)"
