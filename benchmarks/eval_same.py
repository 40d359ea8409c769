"""Benchmark and check: `gsbench eval` of one trained run by two checkouts, results compared exactly.

    .venv/bin/python benchmarks/eval_same.py --run RUN_DIR --base CHECKOUT [--head CHECKOUT]
                                             [--rounds 2] [--work DIR] [--json out.json]

Each side (a commit or a folder, as `versus.py` takes them) is exported and its packages laid out
as its pyproject.toml maps them (`versus.install`); it then runs on this venv's Python and packages.
Each round copies the run folder twice (the run itself is never written) and evaluates one copy
with each side, the two alternating, base first in even rounds. A first, untimed round lets numba
compile into the fresh copies; its results are compared like the others. It then compares, value for value with `==`:
every metric, per-view value, skip reason, metric id, frame list, resolution and note of the two
results.json files (timings, memory, machine and the timed `fps` aside), and every array and
field of the previews. It prints the eval_s of each side per round, their ratio, and the first
differences; the exit status is 1 when anything differs. The two sides must read the same run
format.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from versus import REPO, install  # noqa: E402  (a script beside this one)

# results.json keys that depend on the machine or the clock, not on the computation
TIMED = {"timings", "memory", "machine", "created", "env"}
TIMED_METRICS = {"fps"}
EVAL = "import sys; from gsbench.evaluation import evaluate_run; evaluate_run(sys.argv[1], progress=False)"


def evaluate(site: Path, run: Path) -> float:
    """Evaluate `run` in a fresh process with the gsbench laid out in `site`; the command's wall time."""
    env = dict(os.environ, PYTHONPATH=str(site))
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", EVAL, str(run)], check=True, env=env, cwd=str(site))
    return time.perf_counter() - t0


def _diff(a, b, where: str, out: list[str]) -> None:
    """Append a line per difference between two JSON values (exact: floats with ==)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if k not in a or k not in b:
                out.append(f"{where}.{k}: only in {'head' if k in b else 'base'}")
            else:
                _diff(a[k], b[k], f"{where}.{k}", out)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for k, (x, y) in enumerate(zip(a, b)):
            _diff(x, y, f"{where}[{k}]", out)
    elif type(a) is not type(b) or a != b:
        if not (isinstance(a, float) and isinstance(b, float) and np.isnan(a) and np.isnan(b)):
            out.append(f"{where}: {a!r} != {b!r}")


def _comparable(results: dict) -> dict:
    out = {k: v for k, v in results.items() if k not in TIMED}
    for key in ("metrics", "metric_impl", "per_view", "skipped"):
        if isinstance(out.get(key), dict):
            out[key] = {k: v for k, v in out[key].items() if k not in TIMED_METRICS}
    return out


def compare_runs(base: Path, head: Path) -> list[str]:
    """Differences between two evaluated copies of a run: results.json and the previews."""
    diffs: list[str] = []
    ra = json.loads((base / "results.json").read_text())
    rb = json.loads((head / "results.json").read_text())
    _diff(_comparable(ra), _comparable(rb), "results", diffs)
    pa, pb = base / "previews", head / "previews"
    if pa.is_dir() != pb.is_dir():
        return diffs + ["previews: a folder on one side only"]
    if not pa.is_dir():
        return diffs
    names = sorted({p.name for p in pa.iterdir()} | {p.name for p in pb.iterdir()})
    for name in names:
        fa, fb = pa / name, pb / name
        if not (fa.exists() and fb.exists()):
            diffs.append(f"previews/{name}: on one side only")
        elif name.endswith(".npz"):
            with np.load(fa) as za, np.load(fb) as zb:
                for k in sorted(set(za.files) | set(zb.files)):
                    if k not in za.files or k not in zb.files:
                        diffs.append(f"previews/{name}:{k}: on one side only")
                    elif za[k].dtype != zb[k].dtype or za[k].shape != zb[k].shape or \
                            not np.array_equal(za[k], zb[k], equal_nan=True):
                        diffs.append(f"previews/{name}:{k}: arrays differ")
        elif name.endswith(".json"):
            _diff(json.loads(fa.read_text()), json.loads(fb.read_text()), f"previews/{name}", diffs)
    return diffs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", type=Path, required=True, help="a trained run folder (read only)")
    ap.add_argument("--base", required=True, help="the baseline: a commit or a folder")
    ap.add_argument("--head", default=str(REPO), help="a commit or a folder (default: this working tree)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--work", type=Path, default=Path("/tmp/gsbench-eval-same"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if not (args.run / "model.pt").exists():
        sys.exit(f"{args.run}: not a trained run folder (no model.pt)")
    sides, sites = {}, {}
    for side, rev in (("base", args.base), ("head", args.head)):
        _, sites[side], sides[side] = install(rev, args.work / side)
    times: dict[str, list[float]] = {"base": [], "head": []}
    eval_s: dict[str, list[float]] = {"base": [], "head": []}
    diffs: list[str] = []
    for r in range(max(1, args.rounds) + 1):            # round 0: numba compiles, not timed
        copies = {}
        for side in (("base", "head") if r % 2 == 0 else ("head", "base")):
            dst = args.work / f"round{r}-{side}"
            shutil.rmtree(dst, ignore_errors=True)
            shutil.copytree(args.run, dst, ignore=shutil.ignore_patterns("results.json", "previews", "*.lock"))
            wall = evaluate(sites[side], dst)
            if r > 0:
                times[side].append(wall)
                eval_s[side].append(json.loads((dst / "results.json").read_text())["timings"]["eval_s"])
            copies[side] = dst
        diffs += [f"round {r}: {d}" for d in compare_runs(copies["base"], copies["head"])]
    print("| side | checkout | eval_s per round (s) | command per round (s) |")
    print("|---|---|---|---|")
    for side in ("base", "head"):
        print(f"| {side} | {sides[side]} | {', '.join(f'{v:.2f}' for v in eval_s[side])} | "
              f"{', '.join(f'{v:.2f}' for v in times[side])} |")
    ratio = statistics.median(h / b for h, b in zip(eval_s["head"], eval_s["base"]) if b > 0)
    cmd = statistics.median(h / b for h, b in zip(times["head"], times["base"]) if b > 0)
    print(f"\nhead / base, median over rounds: eval_s {ratio:.3f}, eval command {cmd:.3f}")
    print("results.json and previews: " + ("identical" if not diffs else f"{len(diffs)} differences"))
    for d in diffs[:40]:
        print("  " + d)
    if args.json:
        args.json.write_text(json.dumps({"sides": {k: str(v) for k, v in sides.items()}, "eval_s": eval_s,
                                         "command_s": times, "differences": diffs}, indent=1))
    sys.exit(1 if diffs else 0)


if __name__ == "__main__":
    main()
