#!/usr/bin/env bash
# Train the learned in-frame sampler (agents/adaptive.py) in the adaptive environment and ship it as
# agents/checkpoints/adaptive-pg.pt. CPU only, one thread, MINUTES of wall clock (default 25).
# Usage: scripts/train_adaptive.sh [MINUTES] [OUT] [LOG]
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES="${1:-25}"
OUT="${2:-agents/checkpoints/adaptive-pg.pt}"
LOG="${3:-runs/adaptive-pg.log}"
mkdir -p "$(dirname "$LOG")"
exec .venv/bin/python -m agents.adaptive --minutes "$MINUTES" --out "$OUT" --log "$LOG" --seed 0
