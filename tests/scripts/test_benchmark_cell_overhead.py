"""benchmarks/cell_overhead.py: each checkout runs its own grid file with only the asked seeds, and a
cell's time splits into training, evaluation and the rest. A fake checkout (a `gsbench` script that
writes the run files a cell leaves) stands in for a real one, so no cell is trained here."""
from __future__ import annotations

import stat
import textwrap
from pathlib import Path

import yaml
from bench_scripts import load_benchmark

FAKE_GSBENCH = """#!/bin/sh
# argv: -q ablate --grid FILE --out DIR ...: one finished cell per seed of the grid file
grid="$4"; out="$6"
mkdir -p "$out"; echo "$@" > "$out/argv.txt"
for seed in $(grep -A1 '^seeds:' "$grid" | tail -n 1 | tr -dc '0-9 '); do
  d="$out/cell$seed"; mkdir -p "$d"
  echo '{"state": "done", "wall_s": 10.0}' > "$d/cell_status.json"
  echo '{"train_s": 6.5}' > "$d/train_summary.json"
  echo '{"timings": {"eval_s": 2.0}}' > "$d/results.json"
done
"""


def _fake_tree(root: Path) -> Path:
    (root / "gsbench" / "grids").mkdir(parents=True)
    grid = {"study": "control_sem", "base": {"method": "gaussiands"}, "scenes": ["tabletop-medium"],
            "seeds": [0, 1, 2], "axes": {"gaussiands.lambdas.sem": [0.0, 5.0]}}
    (root / "gsbench" / "grids" / "g-cpu.yaml").write_text(yaml.safe_dump(grid, sort_keys=False))
    exe = root / ".venv" / "bin" / "gsbench"
    exe.parent.mkdir(parents=True)
    exe.write_text(textwrap.dedent(FAKE_GSBENCH))
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return root


def test_cells_are_timed_by_phase_on_the_checkouts_own_grid(tmp_path):
    bench = load_benchmark("cell_overhead")
    tree = _fake_tree(tmp_path / "tree")
    res = bench.run_tree(tree, "g-cpu", [0], tmp_path / "work")
    trimmed = yaml.safe_load((tmp_path / "work" / "g-cpu.yaml").read_text())
    assert trimmed["seeds"] == [0] and trimmed["axes"] == {"gaussiands.lambdas.sem": [0.0, 5.0]}
    assert [c["run"] for c in res["cells"]] == ["cell0"]
    cell = res["cells"][0]
    assert (cell["cell_s"], cell["train_s"], cell["eval_s"]) == (10.0, 6.5, 2.0)
    assert abs(cell["other_s"] - 1.5) < 1e-12
    assert bench.summary(res)["other_s"] == cell["other_s"] and res["command_s"] > 0


def test_the_jobs_reach_the_ablate_command(tmp_path):
    bench = load_benchmark("cell_overhead")
    tree = _fake_tree(tmp_path / "tree")
    res = bench.run_tree(tree, "g-cpu", [0, 1], tmp_path / "work", jobs=2)
    argv = (tmp_path / "work" / "runs" / "argv.txt").read_text().split()
    assert argv[argv.index("--jobs") + 1] == "2" and res["cells"]
