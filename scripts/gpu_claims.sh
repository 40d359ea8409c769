#!/bin/sh
# Claims cells on a lent GPU machine, published into results/gpu: see scripts/gpu_claims.py and
# docs/training.md ("First run on a GPU"). Runs with the machine's python3 (the one that holds torch).
exec "${PYTHON:-python3}" "$(dirname "$0")/gpu_claims.py" "$@"
