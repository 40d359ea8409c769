"""Benchmark: one table of a base commit against another (default: the working tree), in one run.

    .venv/bin/python benchmarks/versus.py --base b7c9fc2 [--head WORKTREE|REV] [--work DIR]
                                          [--size 20000@256x192] [--skip-train] [--json out.json]

Each side (a commit exported with `git archive`, or a copy of a working tree's files that git does not
ignore) is copied into its own folder under --work as its pyproject.toml maps the package
(package-dir), and run with this venv's Python and packages, so both sides use the same torch, numba
and numpy. Every number comes from that side's own code and its own benchmark scripts:
- `cpu` render fwd+bwd ms: `benchmarks/render_cpu.py --scenes WxH/N` (random Gaussians a pixel or
  two wide, 3 feature channels; projection, rasterization and their backward; best of the repeats);
- `cpu` render on the training scene: `benchmarks/raster_scene.py` (this working tree's copy) saves
  train_speed's initial field once (N random-init Gaussians of tabletop-small at WxH) and times each
  side's `render()` on it, the sides alternating for three rounds, each side's best kept;
- bare step, vanilla and gaussiands it/s: `benchmarks/train_speed.py --sizes N@WxH`;
- cpu-medium: `gsbench train --method gaussiands --preset cpu-medium --set priors.masks.provider=gt`
  on a tabletop-medium scene (generated once, seed 0, by the head side), then `gsbench eval`:
  train_s and eval_s as results.json records them, PSNR, 3D-OVS mIoU and LERF mIoU.
The sides run one after the other, base first. Timings need an otherwise idle machine; the table
says what `uptime` reported before each side.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
METRICS = ("psnr", "miou_3dovs", "miou_lerf")


def _run(cmd: list[str], env: dict, cwd: Path, log: Path) -> str:
    """Run a command, keep its output in `log`, fail loudly with the log's tail."""
    print(f"  $ {' '.join(cmd)}", file=sys.stderr, flush=True)
    r = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)   # cwd: never a source folder
    log.write_text(r.stdout + "\n--- stderr ---\n" + r.stderr)
    if r.returncode != 0:
        raise SystemExit(f"versus: {' '.join(cmd)} failed (exit {r.returncode}); see {log}\n{r.stderr[-2000:]}")
    return r.stdout


def install(rev: str, work: Path) -> tuple[Path, Path, str]:
    """(source folder, site folder, label) of one side: a commit exported with git archive, or a folder."""
    if Path(rev).is_dir():      # a copy of its tracked and untracked, not ignored files
        tree = Path(rev).resolve()
        src, label = work / f"src-{tree.name}", f"{tree.name} (working tree)"
        if src.exists():
            shutil.rmtree(src)
        src.mkdir(parents=True)
        files = subprocess.run(["git", "ls-files", "-z", "-co", "--exclude-standard"], cwd=tree, capture_output=True,
                               check=True).stdout
        packed = subprocess.run(["tar", "--null", "-T", "-", "-cf", "-"], cwd=tree, input=files, capture_output=True,
                                check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(src)], input=packed, check=True)
    else:
        sha = subprocess.run(["git", "rev-parse", "--short", rev], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout.strip()
        src, label = work / f"src-{sha}", sha
        if not src.exists():
            src.mkdir(parents=True)
            archive = subprocess.run(["git", "archive", sha], cwd=REPO, capture_output=True, check=True).stdout
            subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    site = work / f"site-{label.split()[0]}"
    if site.exists():
        shutil.rmtree(site)
    # the package as its own pyproject.toml maps it (package-dir), copied folder by folder: a
    # commit's `packages` list may miss a folder, which pip would then leave out
    mapping = tomllib.loads((src / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    for name, folder in sorted(mapping.items(), key=lambda kv: kv[0].count(".")):
        shutil.copytree(src / folder, site / name.replace(".", "/"), dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__"))
    return src, site, label


def _rows(md: str) -> list[list[str]]:
    return [[c.strip() for c in line.strip().strip("|").split("|")] for line in md.splitlines()
            if line.startswith("|") and not line.startswith("|---")]


def measure(src: Path, site: Path, label: str, size: str, scene: Path | None, work: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(site), PYTHONDONTWRITEBYTECODE="1")
    tag = label.split()[0]
    out: dict = {"side": label, "load": os.getloadavg()[0]}
    n, wh = size.split("@")
    res = _run([sys.executable, str(src / "benchmarks" / "render_cpu.py"), "--scenes", f"{wh}/{n}",
                "--repeats", "5"], env, work, work / f"render-{tag}.log")
    for r in _rows(res)[1:]:
        out["render_fwd_ms"] = float(r[3].split("/")[1])
        out["render_fwdbwd_ms"] = float(r[4].split("/")[1])
    ts = _run([sys.executable, str(src / "benchmarks" / "train_speed.py"), "--sizes", size, "--devices", "cpu"],
              env, work, work / f"train_speed-{tag}.log")
    for r in _rows(ts):
        if len(r) >= 5 and r[0] == "cpu" and re.fullmatch(r"[0-9.]+", r[4] or ""):
            key = "bare" if r[3].startswith("bare") else r[3]
            out.setdefault(f"{key}_its", float(r[4]))
    if scene is not None:
        run = work / f"run-{tag}"
        if run.exists():
            shutil.rmtree(run)
        gsbench = [sys.executable, "-c", "import sys; from gsbench.cli import main; sys.exit(main())"]
        _run([*gsbench, "-q", "train", "--method", "gaussiands", "--preset", "cpu-medium", "--scene", str(scene),
              "--set", "priors.masks.provider=gt", "--out", str(run), "--no-progress"], env, work,
             work / f"train-{tag}.log")
        t0 = time.perf_counter()
        _run([*gsbench, "-q", "eval", str(run), "--no-progress"], env, work, work / f"eval-{tag}.log")
        out["eval_wall_s"] = time.perf_counter() - t0
        r = json.loads((run / "results.json").read_text())
        out.update({k: r["timings"].get(k) for k in ("train_s", "eval_s")})
        out.update({k: r["metrics"].get(k) for k in METRICS})
    return out


def raster_rounds(sides: list, size: str, work: Path, rounds: int = 3) -> list[dict]:
    """Per side {"scene_fwd_ms", "scene_fwdbwd_ms"}: raster_scene.py's timing of that side's render()
    on one saved training field, the sides alternating, the best of the rounds."""
    script = REPO / "benchmarks" / "raster_scene.py"
    field = work / f"raster-field-{size.replace('@', '_')}.pt"
    head_site = sides[-1][1]
    if not field.exists():
        _run([sys.executable, str(script), "--make", str(field), "--size", size],
             dict(os.environ, PYTHONPATH=str(head_site)), work, work / "raster-make.log")
    best: list[dict] = [{} for _ in sides]
    for k in range(rounds):
        for j, (_src, site, label) in enumerate(sides):
            out = _run([sys.executable, str(script), "--time", str(field)],
                       dict(os.environ, PYTHONPATH=str(site)), work, work / f"raster-{label.split()[0]}-{k}.log")
            r = json.loads(out.strip().splitlines()[-1])
            for key in ("fwd_ms", "fwdbwd_ms"):
                best[j][f"scene_{key}"] = min(best[j].get(f"scene_{key}", float("inf")), r[key])
    return best


def table(base: dict, head: dict) -> str:
    rows = [("cpu render fwd ms", "render_fwd_ms", True), ("cpu render fwd+bwd ms", "render_fwdbwd_ms", True),
            ("cpu render fwd ms, training scene", "scene_fwd_ms", True),
            ("cpu render fwd+bwd ms, training scene", "scene_fwdbwd_ms", True),
            ("bare step it/s", "bare_its", False), ("vanilla it/s", "vanilla_its", False),
            ("gaussiands it/s", "gaussiands_its", False), ("cpu-medium train_s", "train_s", True),
            ("cpu-medium eval_s", "eval_s", True), ("cpu-medium eval wall s", "eval_wall_s", True)]
    lines = [f"| measure | {base['side']} | {head['side']} | speed-up |", "|---|---:|---:|---:|"]
    for name, key, lower in rows:
        a, b = base.get(key), head.get(key)
        if a is None or b is None:
            continue
        ratio = (a / b if lower else b / a) if a and b else float("nan")
        lines.append(f"| {name} | {a:.2f} | {b:.2f} | {ratio:.2f}x |")
    if base.get("train_s") is not None:
        lines.append(f"| cpu-medium train+eval s | {base['train_s'] + base['eval_s']:.1f} "
                     f"| {head['train_s'] + head['eval_s']:.1f} "
                     f"| {(base['train_s'] + base['eval_s']) / (head['train_s'] + head['eval_s']):.2f}x |")
    for k in METRICS:
        if base.get(k) is not None:
            lines.append(f"| {k} | {base[k]:.4f} | {head[k]:.4f} | |")
    lines.append(f"| load average before | {base['load']:.2f} | {head['load']:.2f} | |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", required=True, help="base commit (e.g. b7c9fc2)")
    ap.add_argument("--head", default=str(REPO), help="a commit or a source folder (default: this working tree)")
    ap.add_argument("--work", default=None, help="folder for the exports, installs, scene, runs and logs")
    ap.add_argument("--size", default="20000@256x192", help="N@WxH of the render and step benchmarks")
    ap.add_argument("--skip-train", action="store_true", help="leave out the cpu-medium train and eval")
    ap.add_argument("--json", default=None, help="also write both sides' numbers to this JSON file")
    a = ap.parse_args(argv)
    work = Path(a.work or tempfile.mkdtemp(prefix="gsbench-versus-")).resolve()
    work.mkdir(parents=True, exist_ok=True)
    print(f"versus: work folder {work}", file=sys.stderr)
    sides = [install(rev, work) for rev in (a.base, a.head)]
    scene = None
    if not a.skip_train:
        scene = work / "tabletop-medium"
        if not scene.exists():
            src, site, label = sides[1]
            _run([sys.executable, "-c", "import sys; from gsbench.cli import main; sys.exit(main())", "-q",
                  "make-scene", "--preset", "tabletop-medium", "--out", str(scene), "--no-progress"],
                 dict(os.environ, PYTHONPATH=str(site)), work, work / "make-scene.log")
    results = []
    for src, site, label in sides:
        print(f"versus: measuring {label}", file=sys.stderr, flush=True)
        results.append(measure(src, site, label, a.size, scene, work))
    print("versus: the rasterizer on the training scene, sides alternating", file=sys.stderr, flush=True)
    for r, extra in zip(results, raster_rounds(sides, a.size, work)):
        r.update(extra)
    print(table(*results))
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
