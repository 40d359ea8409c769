#!/usr/bin/env bash
# Tests of the real prior providers (Depth Anything via transformers, SAM2, OpenCLIP) with tiny,
# randomly initialised models built offline. They need the `models` extra, which pulls torchvision
# (a ~5.5 GB CUDA torch build), so they run in their own venv, never in the main .venv.
#
#   bash scripts/test_models.sh [extra pytest args]
#   bash scripts/test_models.sh --setup-only      (create / update the venv, run nothing)
#
# GSBENCH_MODELS_VENV  venv folder (default /tmp/gsbench-venv-models: outside the work tree, so
#                      that it can never be committed). Created on the first run, reused after.
# PY                   Python used to create the venv (default python3; 3.11 takes torch 2.14.1 and
#                      torchvision 0.29.1 from this machine's disk).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${GSBENCH_MODELS_VENV:-/tmp/gsbench-venv-models}
PY=${PY:-python3}
VPY="$VENV/bin/python"
if [ ! -x "$VPY" ]; then
  echo "test_models: creating $VENV"
  "$PY" -m venv "$VENV"
fi
if ! "$VPY" -c "import torch, torchvision" 2>/dev/null; then
  echo "test_models: installing torch==2.14.1 torchvision==0.29.1 (large)"
  "$VPY" -m pip install --quiet torch==2.14.1 torchvision==0.29.1
fi
# SAM2's optional CUDA extension is not built (CPU-only tests; sam2 runs without it).
export SAM2_BUILD_CUDA=0
echo "test_models: installing gsbench[models,lpips,test]"
"$VPY" -m pip install --quiet -e ".[models,lpips,test]"
if [ "${1:-}" = "--setup-only" ]; then
  echo "test_models: venv ready at $VENV"
  exit 0
fi
export HF_HUB_OFFLINE=1 TRANSFORMERS_OFFLINE=1
set +e
"$(dirname "$VPY")/pytest" -q tests/models_extra tests/metrics/test_metrics_lpips_reference.py "$@"
rc=$?
set -e
# exit 5 = no tests collected: that is a failure here (the models tests must run in this venv).
exit $rc
