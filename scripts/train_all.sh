#!/usr/bin/env bash
# Train every dPMP variant (Direct, AE, VAE, cVAE, each AE/VAE/cVAE also with
# latent tuning) on one generated dataset, evaluate each on the test split,
# and copy the chosen default (l-dPMP-cVAE unless DEFAULT says otherwise) to
# models/default. Usage:
#   scripts/train_all.sh [DATA_DIR] [SEED]
# Environment: EPOCHS_TP1, EPOCHS_TP2, EPOCHS_TP3, BATCH, LR, ALPHA, PATIENCE,
# DEFAULT (a model name below, e.g. cvae-lt), OUT_ROOT (default models/variants).
set -euo pipefail
cd "$(dirname "$0")/.."

DATA="${1:-data/synth}"
SEED="${2:-7}"
OUT_ROOT="${OUT_ROOT:-models/variants}"
EPOCHS_TP1="${EPOCHS_TP1:-30}"
EPOCHS_TP2="${EPOCHS_TP2:-60}"
EPOCHS_TP3="${EPOCHS_TP3:-20}"
BATCH="${BATCH:-5}"
LR="${LR:-1e-4}"
ALPHA="${ALPHA:-1.0}"
PATIENCE="${PATIENCE:-10}"
DEFAULT="${DEFAULT:-cvae-lt}"

if [ ! -f "$DATA/manifest.json" ]; then
  echo "no dataset at $DATA (generate one with: dpmp data generate --out $DATA)" >&2
  exit 2
fi

cargo build --release
BIN=target/release/dpmp
COMMON=(--data "$DATA" --seed "$SEED" --epochs-tp1 "$EPOCHS_TP1" --epochs-tp2 "$EPOCHS_TP2"
        --epochs-tp3 "$EPOCHS_TP3" --batch "$BATCH" --lr "$LR" --alpha "$ALPHA" --patience "$PATIENCE")

train() {  # name arch [--latent-tuning]
  local name="$1" arch="$2"; shift 2
  echo "== training $name" >&2
  "$BIN" train --arch "$arch" --out "$OUT_ROOT/$name" "${COMMON[@]}" "$@" >"$OUT_ROOT/$name.train.json"
  "$BIN" eval --model "$OUT_ROOT/$name" --data "$DATA" --split test --format json \
    --out "$OUT_ROOT/$name/eval-test" >"$OUT_ROOT/$name.eval.json"
}

mkdir -p "$OUT_ROOT"
train direct direct
for arch in ae vae cvae; do
  train "$arch" "$arch"
  train "$arch-lt" "$arch" --latent-tuning
done

echo "| model | Eq. 7 total | final TCP position error (m) | orientation | +3σ position (m) | Davies–Bouldin |"
echo "|---|---|---|---|---|---|"
for name in direct ae ae-lt vae vae-lt cvae cvae-lt; do
  python3 - "$OUT_ROOT/$name.eval.json" "$name" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
db = r["table2"]["davies_bouldin"]
print(f"| {sys.argv[2]} | {r['eq7_total']:.3e} | {r['mean_final_position_error_m']:.4f} | "
      f"{r['table3']['mean']['orientation']:.4f} | {r['table3']['plus_3sigma']['position_m']:.4f} | "
      f"{'n/a' if db is None else f'{db:.3f}'} |")
PY
done

rm -rf models/default.tmp
mkdir -p models/default.tmp
cp "$OUT_ROOT/$DEFAULT/model.safetensors" "$OUT_ROOT/$DEFAULT/config.json" \
   "$OUT_ROOT/$DEFAULT/loss_curves.png" models/default.tmp/
cp -r "$OUT_ROOT/$DEFAULT/eval-test" models/default.tmp/eval-test
rm -rf models/default
mv models/default.tmp models/default
echo "models/default <- $OUT_ROOT/$DEFAULT" >&2
