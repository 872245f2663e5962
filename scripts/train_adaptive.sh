#!/usr/bin/env bash
# Train a learned in-frame sampler (agents/adaptive/) in the adaptive environment, one CPU thread.
#   scripts/train_adaptive.sh                 -> agents/checkpoints/adaptive-pg-prior.pt (the default one):
#       over the frozen shipped ngransac-supervised sampler, 18 minutes of this process' CPU time, seed 4
#   scripts/train_adaptive.sh pg [MINUTES]    -> agents/checkpoints/adaptive-pg.pt: no prior, MINUTES of
#       wall clock (default 25), seed 0
# Usage: scripts/train_adaptive.sh [pg-prior|pg] [MINUTES] [OUT] [LOG]
# Without OUT it replaces the shipped checkpoint (python -m agents.adaptive --overwrite); a given OUT
# that exists is refused, as python -m agents.adaptive refuses it.
set -euo pipefail
cd "$(dirname "$0")/.."
VARIANT="${1:-pg-prior}"
case "$VARIANT" in
  pg-prior) MINUTES="${2:-18}"; ARGS=(--prior ngransac-supervised --clock cpu --seed 4) ;;
  pg) MINUTES="${2:-25}"; ARGS=(--seed 0) ;;
  *) echo "train_adaptive.sh: the variant must be pg-prior or pg, got '$VARIANT'" >&2; exit 2 ;;
esac
if [ -n "${3:-}" ]; then OUT="$3"; else OUT="agents/checkpoints/adaptive-$VARIANT.pt"; ARGS+=(--overwrite); fi
LOG="${4:-runs/adaptive-$VARIANT.log}"
mkdir -p "$(dirname "$LOG")"
exec .venv/bin/python -m agents.adaptive --minutes "$MINUTES" --out "$OUT" --log "$LOG" "${ARGS[@]}"
