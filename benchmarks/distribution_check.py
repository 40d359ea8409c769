"""Benchmark check: a change to the code leaves the claims' results unchanged in distribution.

    .venv/bin/python benchmarks/distribution_check.py --tree BASE HEAD
        [--grids control_sem-cpu depth_formulation-cpu] [--seeds 0 1 2 3 4] [--jobs 2]
        [--metrics psnr miou_3dovs mbiou_3dovs] [--store results/cpu] [--work DIR] [--json out.json]

Each checkout (`--tree`, each with its own `.venv`) runs its own copy of each grid file, trimmed to
`--seeds`, with `gsbench ablate --executor local --jobs N` (as `gsbench claims` runs the plan). For
every arm (a grid's cell over its seeds) and metric it prints the baseline's mean with its 95 %
t-interval over the seeds, the head's mean, the difference of means, and whether the head's mean
lies inside the baseline's interval; then how many cells gave the same value on both checkouts
(`==`). A change that keeps the bits passes with every difference 0; a change of numerics must keep
every head mean inside the baseline's interval (issue 52's rule). With `--store` (a published store,
e.g. results/cpu) the head's arms are also set against the store's published seeds of the same
setting (their mean and 95 % t-interval), and the head cells the store holds from this machine's CPU
family are compared value for value. A finished cell is not run again: a second call with the same
`--work` only prints.

Not a timing: run it beside other work if need be. Exit status 1 when a head mean falls outside its
interval.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

from gsbench.reports.stats import mean_band

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cell_overhead import ablate_argv, trimmed_grid  # noqa: E402  (a script beside this one)

METRICS = ("psnr", "miou_3dovs", "mbiou_3dovs")


def run_tree(tree: Path, grid: str, seeds: list[int], work: Path, jobs: int) -> dict[str, dict]:
    """Run `tree`'s grid file trimmed to `seeds`; {run_id: {"arm", "seed", "metrics"}} of its done cells."""
    grid_file = trimmed_grid(tree, grid, seeds, work)
    runs = work / "runs"
    subprocess.run(ablate_argv(tree, grid_file, runs, jobs), check=True)
    plan = json.loads((runs / f"grid-{grid}.json").read_text())
    out = {}
    for cell in plan["cells"]:
        results = runs / cell["run_id"] / "results.json"
        if not results.is_file():
            continue
        axes = " ".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in sorted(cell["axes"].items()))
        arm = f"{grid} {cell['method']} {axes}".strip()
        out[cell["run_id"]] = {"arm": arm, "seed": cell["seed"],
                               "metrics": json.loads(results.read_text()).get("metrics") or {}}
    return out


def interval(values: list[float]) -> tuple[float, float, float]:
    """Mean and its 95 % t-interval (nan bounds for fewer than two values)."""
    mean, half = mean_band(values)
    return (mean, math.nan, math.nan) if half is None else (mean, mean - half, mean + half)


def compare(base: dict, head: dict, metrics: list[str]) -> tuple[list[dict], int, int]:
    """Per arm and metric: the baseline's interval, the head's mean and their difference; and the
    count of (cell, metric) values equal on both, of those both have."""
    rows, same, total = [], 0, 0
    arms = sorted({c["arm"] for c in base.values()})
    for arm in arms:
        ids = sorted(r for r, c in base.items() if c["arm"] == arm and r in head)
        for m in metrics:
            pairs = [(base[r]["metrics"].get(m), head[r]["metrics"].get(m)) for r in ids]
            pairs = [(b, h) for b, h in pairs if _number(b) and _number(h)]
            if not pairs:
                continue
            total += len(pairs)
            same += sum(b == h for b, h in pairs)
            mean, lo, hi = interval([b for b, _ in pairs])
            head_mean = statistics.fmean(h for _, h in pairs)
            inside = (lo <= head_mean <= hi) if not math.isnan(lo) else head_mean == mean
            rows.append({"arm": arm, "metric": m, "n": len(pairs), "base_mean": mean, "lo": lo, "hi": hi,
                         "head_mean": head_mean, "diff": head_mean - mean, "inside": inside})
    return rows, same, total


def against_store(head: dict, store: Path, metrics: list[str]) -> tuple[list[dict], int, int]:
    """The head's arms against the published store's cells of the same setting (gsbench's own store
    reader, today's numerics version only): per arm and metric the store's mean and 95 % t-interval
    over its published seeds, the head's mean over its seeds and their difference; and (equal,
    compared) values of the head cells the store holds from this machine's CPU family. Cells
    published on another CPU family are not compared value for value: their bits differ
    (docs/training.md, "The same numbers on any CPU")."""
    from gsbench.environment import cpu_facts
    from gsbench.grids.seed_spread import setting_key
    from gsbench.grids.store import read_store
    from gsbench.grids.verify import same_cpu
    from gsbench.numerics import NUMERICS_VERSION
    cells = [c for c in read_store(store) if c.numerics_version == NUMERICS_VERSION]
    by_id = {c.run_id: c for c in cells}
    here = cpu_facts()
    rows, same, total, arms = [], 0, 0, {}
    for run_id, cell in head.items():
        published = by_id.get(run_id)
        if published is None:
            continue
        arms.setdefault(setting_key(published.record), []).append(run_id)
        if same_cpu(published.record["provenance"], here):
            for m in metrics:
                b, h = published.metrics.get(m), cell["metrics"].get(m)
                if _number(b) and _number(h):
                    total += 1
                    same += b == h
    for key, ids in arms.items():
        setting = [c for c in cells if setting_key(c.record) == key]
        models = sorted({str(c.record["provenance"].get("cpu_model")) for c in setting})
        head_ids = [r for r, c in head.items() if c["arm"] == head[ids[0]]["arm"]]
        for m in metrics:
            pub = [c.metrics.get(m) for c in setting if _number(c.metrics.get(m))]
            now = [head[r]["metrics"].get(m) for r in head_ids if _number(head[r]["metrics"].get(m))]
            if len(pub) < 2 or not now:
                continue
            mean, lo, hi = interval(pub)
            head_mean = statistics.fmean(now)
            rows.append({"arm": head[ids[0]]["arm"], "metric": m, "n_store": len(pub), "n_head": len(now),
                         "store_mean": mean, "lo": lo, "hi": hi, "head_mean": head_mean, "diff": head_mean - mean,
                         "inside": lo <= head_mean <= hi, "store_cpus": models})
    return sorted(rows, key=lambda r: r["arm"]), same, total


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _cpu_model() -> str:
    from gsbench.environment import cpu_facts
    return str(cpu_facts().get("cpu_model"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tree", type=Path, nargs=2, required=True, help="baseline and head checkouts, each with .venv")
    ap.add_argument("--grids", nargs="+", default=["control_sem-cpu", "depth_formulation-cpu"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--metrics", nargs="+", default=list(METRICS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--store", type=Path, default=None, help="a published store (e.g. results/cpu) to compare with")
    ap.add_argument("--work", type=Path, default=Path("distribution_check_work"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    cells = [{}, {}]
    for i, tree in enumerate(args.tree):
        for grid in args.grids:
            cells[i].update(run_tree(tree.resolve(), grid, args.seeds, args.work / f"tree{i}" / grid, args.jobs))
    rows, same, total = compare(cells[0], cells[1], args.metrics)
    print(f"baseline {args.tree[0]}  head {args.tree[1]}  seeds {args.seeds}")
    w = max([len(r["arm"]) for r in rows] + [3])
    print(f"{'arm':{w}s} {'metric':12s} {'n':>2s} {'base mean':>10s} {'95% interval':>21s} {'head mean':>10s} "
          f"{'diff':>10s} inside")
    for r in rows:
        inside = "yes" if r["inside"] else "NO"
        print(f"{r['arm']:{w}s} {r['metric']:12s} {r['n']:2d} {r['base_mean']:10.4f} "
              f"[{r['lo']:9.4f}, {r['hi']:9.4f}] {r['head_mean']:10.4f} {r['diff']:+10.2e} {inside}")
    print(f"values equal on both checkouts: {same} of {total}")
    report = {"trees": [str(t) for t in args.tree], "seeds": args.seeds, "rows": rows, "same": same, "total": total}
    if args.store:
        s_rows, s_same, s_total = against_store(cells[1], args.store, args.metrics)
        print(f"\nhead against the published store ({args.store}), its seeds of each setting "
              f"(published on {', '.join(sorted({c for r in s_rows for c in r['store_cpus']})) or '-'}; "
              f"this machine {_cpu_model()})")
        print(f"{'arm':{w}s} {'metric':12s} {'n':>2s} {'store mean':>10s} {'95% interval':>21s} {'n':>2s} "
              f"{'head mean':>10s} {'diff':>10s} inside")
        for r in s_rows:
            inside = "yes" if r["inside"] else "NO"
            print(f"{r['arm']:{w}s} {r['metric']:12s} {r['n_store']:2d} {r['store_mean']:10.4f} "
                  f"[{r['lo']:9.4f}, {r['hi']:9.4f}] {r['n_head']:2d} {r['head_mean']:10.4f} "
                  f"{r['diff']:+10.2e} {inside}")
        print(f"head values equal to the store's cells of this CPU family: {s_same} of {s_total}")
        report["store"] = {"rows": s_rows, "same": s_same, "total": s_total}
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))
    return 0 if all(r["inside"] for r in rows) else 1   # the store's rows inform; two CPU families may differ


if __name__ == "__main__":
    sys.exit(main())
