#!/usr/bin/env bash
# The main job end to end on the small built-in scene: make the scene, train GaussianDS (and the
# two baselines), evaluate, collect and write the HTML report. Used by `make demo`.
set -euo pipefail
VENV=${1:-.venv}
OUT=${2:-demo_out}
GS="$VENV/bin/gsbench"
mkdir -p "$OUT"
step() {
  echo "==> gsbench $*"
  set +e
  "$GS" "$@"
  rc=$?
  set -e
  if [ $rc -ne 0 ]; then echo "demo failed at: gsbench $*" >&2; exit $rc; fi
}
# Re-running the demo reuses the scene and the finished runs (train skips a run whose status is done).
if [ -f "$OUT/scene/gsbench_scene.json" ]; then
  echo "==> reusing the scene in $OUT/scene"
else
  step make-scene --preset tabletop-small --out "$OUT/scene"
fi
for m in gaussiands vanilla twostage; do
  step train --method "$m" --scene "$OUT/scene" --preset cpu-small --out "$OUT/runs/$m"
  step eval "$OUT/runs/$m"
done
step collect "$OUT/runs"
step report "$OUT/runs" --out "$OUT/report"

