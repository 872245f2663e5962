#!/usr/bin/env bash
# Train a one-shot sampler on a randomised mix of match-error processes (issue 31 item 3):
# NG-RANSAC's trainer with the supervised loss and the shipped samplers' settings (eps from
# [0.3, 0.9], pools of 11, 8 pools a frame, seed 0, one thread), each training sequence drawing its
# own outlier-kind weights (flat Dirichlet over every simulated kind, the hostile ones included),
# Student-t noise on half the sequences and a score AUC in [0.55, 0.9]
# (agents.ngransac.randomised_frame_stream). Not shipped: its transfer rows are in docs/results.md.
# Usage: scripts/train_randomised.sh [FRAMES] [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES="${1:-16000}"
OUT="${2:-runs/randomised/ngransac-randomised.pt}"
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$(dirname "$OUT")"
exec "${PYTHON:-.venv/bin/python}" - "$FRAMES" "$OUT" <<'PY'
import sys

import torch

from agents.ngransac import NGRansacConfig, NGRansacTrainer

frames, out = int(sys.argv[1]), sys.argv[2]
torch.set_num_threads(1)
trainer = NGRansacTrainer(NGRansacConfig(loss="supervised", frames=frames, seed=0, domain_randomisation=True))
trainer.train(progress=True)
print("wrote", trainer.save(out))
PY
