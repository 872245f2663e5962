#!/usr/bin/env bash
# Create .venv and install vo-gym with every extra: dev (tests), peers (OpenCV, PoseLib for the
# benchmark), superansac (SupeRANSAC for the benchmark; installs only on CPython 3.11 / Linux
# x86-64, where its wheel exists), train (torch, stable-baselines3, tensorboard, rich) and
# distributed (Ray, PyYAML).
# torch is pinned first to the local CPU build: resolving a bare "torch" on a fresh
# machine would pull a multi-GB CUDA build. pyproject keeps a compatible range.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet "torch==2.13.0"
.venv/bin/python -m pip install --quiet -e ".[dev,peers,superansac,train,distributed]"
echo "vo-gym set up in .venv ($(.venv/bin/python -c 'import torch, numpy; print("torch", torch.__version__, "numpy", numpy.__version__)'))"
