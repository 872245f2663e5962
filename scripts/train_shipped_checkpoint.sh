#!/usr/bin/env bash
# Reproduce a learned sampler that ships with the package (agents/checkpoints/).
# NG-RANSAC-style training with the trainer's defaults (loss: supervised | self-supervised |
# self-supervised-smooth): contamination drawn from [0.3, 0.9], budget 11, 8 pools a frame,
# 16000 frames, seed 0; about 6-10 minutes on one CPU core. One thread, so that the run is
# bit-for-bit repeatable (a different thread count changes torch's reduction order).
set -euo pipefail
cd "$(dirname "$0")/.."
loss=${1:-supervised}
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
.venv/bin/vo-gym train --algo ngransac --loss "$loss" --seed 0 --out "runs/ship-$loss" --no-progress
.venv/bin/python -c "from agents.checkpoint import export_checkpoint; export_checkpoint('runs/ship-$loss/ngransac-$loss.pt', 'agents/checkpoints/ngransac-$loss.pt')"
echo "wrote agents/checkpoints/ngransac-$loss.pt"
