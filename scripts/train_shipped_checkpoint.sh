#!/usr/bin/env bash
# Reproduce the learned sampler that ships with the package (agents/checkpoints/).
# NG-RANSAC-style training (loss: supervised | self-supervised | self-supervised-smooth),
# contamination drawn from [0.3, 0.9], budget 16, seed 0; about 5-10 minutes on 2 CPU cores.
set -euo pipefail
cd "$(dirname "$0")/.."
loss=${1:-supervised}
.venv/bin/vo-gym train --algo ngransac --loss "$loss" --frames 1500 --seed 0 --out "runs/ship-$loss"
.venv/bin/python -c "from agents.checkpoint import export_checkpoint; export_checkpoint('runs/ship-$loss/ngransac-$loss.pt', 'agents/checkpoints/ngransac-$loss.pt')"
echo "wrote agents/checkpoints/ngransac-$loss.pt"
