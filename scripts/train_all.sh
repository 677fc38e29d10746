#!/usr/bin/env bash
# Train every dPMP variant (Direct, AE, VAE, cVAE, each AE/VAE/cVAE also with
# latent tuning) on one generated dataset with the same settings, in joint
# space or task space (SPACE), evaluate each on the test split, print the
# comparison table and the paper's Table III with both halves (every model
# of either space found under OUT_ROOT), and (when DEFAULT names one of them)
# copy it to models/default. The shipped default is the
# depth-conditioned cVAE trained by the README's command, not one of these.
#
# A latent-tuning variant NAME-lt is the finished NAME run (tp1 + tp2)
# extended by tp3 (`--latent-tuning --resume`): bit-identical to training it
# from scratch (tp1/tp2 are the same seeded phases), at the cost of tp3 only.
# Its recorded training time includes tp1 + tp2.
#
# Usage:
#   scripts/train_all.sh [DATA_DIR] [SEED]
# Environment: SPACE (joint, default, or task: models named task-NAME),
# EPOCHS_TP1, EPOCHS_TP2, EPOCHS_TP3, BATCH, LR, ALPHA, PATIENCE,
# DEFAULT (a model name below to install as models/default; default none),
# OUT_ROOT (default models/variants),
# MODELS (space-separated subset and order, default "cvae cvae-lt ae ae-lt
# vae vae-lt direct"; also cvae-depth, the cVAE conditioned on the target's
# depth), FORCE=1 (retrain models whose evaluation exists),
# BIN (the dpmp binary; default: build and use target/release/dpmp).
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
DEFAULT="${DEFAULT:-}"
SPACE="${SPACE:-joint}"
case "$SPACE" in
  joint) PREFIX="" ;;
  task) PREFIX="task-" ;;
  *) echo "SPACE must be joint or task, got $SPACE" >&2; exit 2 ;;
esac
MODELS="${MODELS:-cvae cvae-lt ae ae-lt vae vae-lt direct}"
ALL="direct ae ae-lt vae vae-lt cvae cvae-lt cvae-depth"

if [ ! -f "$DATA/manifest.json" ]; then
  echo "no dataset at $DATA (generate one with: dpmp data generate --out $DATA)" >&2
  exit 2
fi

if [ -z "${BIN:-}" ]; then
  cargo build --release
  BIN=target/release/dpmp
fi
COMMON=(--data "$DATA" --seed "$SEED" --epochs-tp1 "$EPOCHS_TP1" --epochs-tp2 "$EPOCHS_TP2"
        --epochs-tp3 "$EPOCHS_TP3" --batch "$BATCH" --lr "$LR" --alpha "$ALPHA" --patience "$PATIENCE"
        --space "$SPACE")

evaluate() {  # name
  "$BIN" eval --model "$OUT_ROOT/$1" --data "$DATA" --split test --format json \
    --out "$OUT_ROOT/$1/eval-test" >"$OUT_ROOT/$1.eval.json.tmp"
  mv "$OUT_ROOT/$1.eval.json.tmp" "$OUT_ROOT/$1.eval.json"
}

train_one() {  # variant (the model is saved as $PREFIX$variant)
  local variant="$1" arch="${1%-lt}" name="$PREFIX$1" base="$PREFIX${1%-lt}" extra=()
  if [ "$arch" = cvae-depth ]; then
    arch=cvae
    extra=(--depth-condition)
  fi
  if [ -f "$OUT_ROOT/$name.eval.json" ] && [ "${FORCE:-0}" != 1 ]; then
    echo "== $name: already trained and evaluated (FORCE=1 retrains)" >&2
    return
  fi
  echo "== training $name ($(date -u +%H:%M:%S))" >&2
  if [ "$variant" = "${variant%-lt}" ]; then
    rm -rf "$OUT_ROOT/$name"
    "$BIN" train --arch "$arch" --out "$OUT_ROOT/$name" "${COMMON[@]}" "${extra[@]}" >"$OUT_ROOT/$name.train.json"
  else
    # Extend the finished run without latent tuning by tp3.
    if [ ! -f "$OUT_ROOT/$base/train_state/state.json" ]; then
      train_one "$arch"
    fi
    rm -rf "$OUT_ROOT/$name"
    cp -r "$OUT_ROOT/$base" "$OUT_ROOT/$name"
    rm -rf "$OUT_ROOT/$name/eval-test"
    "$BIN" train --arch "$arch" --latent-tuning --resume --out "$OUT_ROOT/$name" "${COMMON[@]}" \
      >"$OUT_ROOT/$name.train.json"
  fi
  evaluate "$name"
}

mkdir -p "$OUT_ROOT"
for name in $MODELS; do
  train_one "$name"
done

echo "| model | Eq. 7 total | final TCP position error (m) | orientation (Eq. 9) | -3σ / +3σ position (m) | Davies–Bouldin | training time (s) |"
echo "|---|---|---|---|---|---|---|"
for name in $ALL; do
  [ -f "$OUT_ROOT/$PREFIX$name.eval.json" ] || continue
  python3 - "$OUT_ROOT/$PREFIX$name.eval.json" "$OUT_ROOT/$PREFIX$name/config.json" "$PREFIX$name" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
c = json.load(open(sys.argv[2]))
db = r["table2"]["davies_bouldin"]
t3 = r["table3"]
print(f"| {sys.argv[3]} | {r['eq7_total']:.3e} | {t3['mean']['position_m']:.4f} | "
      f"{t3['mean']['orientation']:.4f} | {t3['minus_3sigma']['position_m']:.4f} / {t3['plus_3sigma']['position_m']:.4f} | "
      f"{'n/a' if db is None else f'{db:.3f}'} | {c['training']['seconds']:.0f} |")
PY
done

# Table III, both halves: final-point position (m) / orientation (Eq. 9) of
# the mean trajectory and of the 3σ trajectories (the mean of the -3σ and
# +3σ errors, the paper's single "3std." column), joint space beside task
# space, each variant above the paper's figures (its Table III, real data).
echo
echo "| model | joint: mean | joint: 3σ | task: mean | task: 3σ |"
echo "|---|---|---|---|---|"
python3 - "$OUT_ROOT" $ALL <<'PY'
import json, os, sys
root, names = sys.argv[1], sys.argv[2:]
label = {"direct": "dPMP-Direct", "ae": "dPMP-AE", "ae-lt": "l-dPMP-AE", "vae": "dPMP-VAE",
         "vae-lt": "l-dPMP-VAE", "cvae": "dPMP-cVAE", "cvae-lt": "l-dPMP-cVAE",
         "cvae-depth": "dPMP-cVAE + depth condition"}
paper = {"direct": ("0.15 / 0.10", "0.31 / 0.41", "0.08 / 0.06", "0.10 / 0.10"),
         "ae": ("0.10 / 0.06", "0.32 / 0.41", "0.04 / 0.04", "0.09 / 0.07"),
         "vae": ("0.06 / 0.03", "0.19 / 0.31", "0.03 / 0.03", "0.07 / 0.06"),
         "cvae": ("0.04 / 0.02", "0.18 / 0.28", "0.02 / 0.02", "0.06 / 0.06")}
def cells(path):
    if not os.path.exists(path):
        return ["—", "—"]
    t3 = json.load(open(path))["table3"]
    m, lo, hi = t3["mean"], t3["minus_3sigma"], t3["plus_3sigma"]
    sigma = [(lo[k] + hi[k]) / 2 for k in ("position_m", "orientation")]
    return [f"{m['position_m']:.3f} / {m['orientation']:.3f}", f"{sigma[0]:.3f} / {sigma[1]:.3f}"]
for n in names:
    j, t = cells(f"{root}/{n}.eval.json"), cells(f"{root}/task-{n}.eval.json")
    if j == ["—", "—"] and t == ["—", "—"]:
        continue
    print(f"| {label.get(n, n)} | " + " | ".join(j + t) + " |")
    if n in paper:
        print(f"| *paper: {label[n]}* | " + " | ".join(f"*{c}*" for c in paper[n]) + " |")
PY

if [ -n "$DEFAULT" ] && [ -f "$OUT_ROOT/$DEFAULT.eval.json" ]; then
  rm -rf models/default.tmp
  mkdir -p models/default.tmp
  cp "$OUT_ROOT/$DEFAULT/model.safetensors" "$OUT_ROOT/$DEFAULT/config.json" \
     "$OUT_ROOT/$DEFAULT/loss_curves.png" "$OUT_ROOT/$DEFAULT/metrics.csv" models/default.tmp/
  cp -r "$OUT_ROOT/$DEFAULT/eval-test" models/default.tmp/eval-test
  rm -rf models/default
  mv models/default.tmp models/default
  echo "models/default <- $OUT_ROOT/$DEFAULT" >&2
fi
