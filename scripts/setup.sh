#!/usr/bin/env bash
# Create .venv and install vo-gym with every extra: dev (tests), peers (OpenCV, PoseLib for the
# benchmark), superansac (SupeRANSAC for the benchmark; installs only on CPython 3.11 / Linux
# x86-64, where its wheel exists), train (torch, stable-baselines3, tensorboard, rich), distributed
# (Ray, PyYAML), images (OpenCV, scikit-image, Pillow: the image front end) and render (moderngl, glcontext:
# rendered sequences). Rendering headless on the CPU needs the system's EGL and Mesa (llvmpipe): on
# Debian/Ubuntu this installs them with apt-get when run as root and they are missing (CI runs it as root).
# torch is pinned first to the local CPU build: resolving a bare "torch" on a fresh
# machine would pull a multi-GB CUDA build. pyproject keeps a compatible range.
set -euo pipefail
cd "$(dirname "$0")/.."
EGL_PACKAGES="libegl1 libegl-mesa0 libgl1-mesa-dri"
if command -v dpkg-query >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
    missing=""
    for package in $EGL_PACKAGES; do
        status=$(dpkg-query -W -f='${Status}' "$package" 2>/dev/null || true)
        case "$status" in
            *"install ok installed"*) ;;
            *) missing="$missing $package" ;;
        esac
    done
    if [ -n "$missing" ]; then
        if [ "$(id -u)" = "0" ]; then
            echo "installing EGL/Mesa for headless rendering:$missing"
            DEBIAN_FRONTEND=noninteractive apt-get update -qq
            DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing
        else
            echo "warning: rendered sequences need$missing (run: sudo apt-get install$missing)" >&2
        fi
    fi
fi
PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet "torch==2.13.0"
# OpenCV comes as the contrib build (AKAZE is there only in OpenCV 5); a .venv made before holds the
# plain wheel, and two wheels writing one cv2 package break each other when either is removed.
if .venv/bin/python -m pip show --quiet opencv-python-headless >/dev/null 2>&1; then
    # both, when both are there: removing one deletes files of the cv2 package the other needs too
    .venv/bin/python -m pip uninstall --quiet --yes opencv-python-headless opencv-contrib-python-headless 2>/dev/null || true
fi
.venv/bin/python -m pip install --quiet -e ".[dev,peers,superansac,train,distributed,images,render]"
echo "vo-gym set up in .venv ($(.venv/bin/python -c 'import torch, numpy; print("torch", torch.__version__, "numpy", numpy.__version__)'))"
