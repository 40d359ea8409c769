"""Fingerprints of every stage of the golden runs, to find what moves a number from one CPU to another.

The loop golden (tests/data/loop_golden/) is bit-exact only on the CPU family that wrote it. When
another CPU computes a different bit, this script says where: it writes one small JSON file of
short hashes, one per stage, and compares such files.

    .venv/bin/python scripts/cpu_fingerprint.py write FILE [--steps N] [--methods vanilla,grouping]
    .venv/bin/python scripts/cpu_fingerprint.py compare A.json B.json [C.json ...]
    .venv/bin/python scripts/cpu_fingerprint.py bisect DIR [--steps N]

The stages, in the order a run meets them:
- `probe/...`: library operations on fixed inputs: libm through Python, numpy and torch (exp, log,
  pow, sin, cos, tanh, sqrt, division), torch's matrix products (MKL: a linear layer, small batched
  3x3 products), reductions, its random draws, OpenCV's filters and resizes, numba's float32 exp;
- `scene/...`: each file of the tiny scene generated again (images, depth, masks);
- `<method>/init`: the field the trainer starts from; then per step `<method>/sNNN/render` (every
  render output), `.../loss` (every loss term's float), `.../grad` (every gradient, before Adam),
  `.../adam` (every parameter after Adam) and `.../field` (after densification).

`write` runs under the environment it is given (tests/support/loop_golden.py's PORTABLE_ENV is what
the golden runs under: set it yourself, or use `bisect`). `compare` prints one row per stage that
differs in any file, with the first differing stage of each run. `bisect` writes one file per
pinning (the portable pin, with each of its parts undone, and with more pinned) into DIR on this
machine and compares them: a stage that moves with a pinning is a CPU-dependent code path. Write a
file on two CPUs under the portable pin and compare them to see what differs across CPUs.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))

import numpy as np  # noqa: E402
import torch  # noqa: E402

HASH_CHARS = 12


def digest(*arrays) -> str:
    """Short sha256 of arrays' bytes (tensors, numpy arrays, floats), shapes and dtypes included."""
    h = hashlib.sha256()
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        if torch.is_tensor(a):
            a = a.detach().cpu().contiguous().numpy()
        a = np.ascontiguousarray(np.asarray(a))
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:HASH_CHARS]


# ---------------------------------------------------------------------------- probes
def _inputs() -> tuple[np.ndarray, np.ndarray]:
    """Fixed inputs: float64 and float32 grids over the ranges the kernels meet."""
    x64 = np.linspace(-20.0, 20.0, 40_001)
    return x64, x64.astype(np.float32)


def probes() -> dict[str, str]:
    """Library operations on fixed inputs (module docstring)."""
    import cv2

    from gsbench.render.cpu_exp import _exp32
    x64, x32 = _inputs()
    pos64, pos32 = np.abs(x64) + 1e-3, np.abs(x32) + np.float32(1e-3)
    libm = [f(v) for v in x64[::97] for f in (math.exp, math.sin, math.cos, math.tanh)]
    libm += [math.log(v) for v in pos64[::97]] + [v ** 0.37 for v in pos64[::97]]
    out = {"probe/python.math": digest(np.array(libm))}
    for name, a, p in (("f64", x64, pos64), ("f32", x32, pos32)):
        out[f"probe/numpy.{name}"] = digest(np.exp(a), np.log(p), np.power(p, a.dtype.type(0.37)), np.sin(a),
                                             np.cos(a), np.tanh(a), np.sqrt(p), a / p)
        out[f"probe/numpy.{name}.reduce"] = digest(a.sum(), (a * a).sum(), np.cumsum(a), a.reshape(-1, 1).mean(0),
                                                    a[:40_000].reshape(200, 200) @ p[:200])
    t, tp = torch.from_numpy(x32), torch.from_numpy(pos32)
    out["probe/torch.unary"] = digest(torch.exp(t), torch.log(tp), torch.pow(tp, 0.37), torch.sin(t), torch.cos(t),
                                      torch.tanh(t), torch.sigmoid(t), torch.sqrt(tp), torch.rsqrt(tp), t / tp)
    m = t[:32_768].reshape(64, 512)
    out["probe/torch.softmax"] = digest(torch.softmax(m, 1), torch.log_softmax(m, 1))
    out["probe/torch.reduce"] = digest(t.sum(), t.mean(), (t * t).sum(), m.sum(1), m.sum(0), torch.cumsum(t, 0))
    g = torch.Generator().manual_seed(0)
    w = torch.randn(512, 168, generator=g)
    out["probe/torch.random"] = digest(w, torch.rand(1000, generator=g), torch.randn(7, generator=g))
    feats = torch.randn(300, 168, generator=g)
    out["probe/torch.linear"] = digest(torch.nn.functional.linear(feats, w, w[:, 0]), feats @ feats.T)
    rot, pts = torch.randn(600, 3, 3, generator=g), torch.randn(600, 3, 1, generator=g)
    out["probe/torch.bmm3x3"] = digest(torch.bmm(rot, pts), torch.cdist(pts[:, :, 0], pts[:100, :, 0]))
    img = np.ascontiguousarray(x32[:32_768].reshape(128, 256) / 20.0)
    out["probe/opencv"] = digest(cv2.GaussianBlur(img, (11, 11), 1.5),
                                 cv2.resize(img, (64, 32), interpolation=cv2.INTER_AREA),
                                 cv2.resize(img, (300, 150), interpolation=cv2.INTER_LINEAR))
    out["probe/numba.exp_f32"] = digest(_numba_exp(np.minimum(x32, np.float32(0.0)), _exp32))
    return out


def _numba_exp(x: np.ndarray, exp32) -> np.ndarray:
    """gsbench's float32 exponential (gsbench.render.cpu_exp) over x, in a numba loop as the kernels call it."""
    import numba

    @numba.njit(cache=False)
    def loop(a):
        out = np.empty_like(a)
        for i in range(a.size):
            out[i] = exp32(a[i])
        return out
    return loop(x)


# ---------------------------------------------------------------------------- runs
class Recorder:
    """Hooks on the trainer that hash each stage of each step (module docstring)."""

    def __init__(self, stages: dict[str, str]):
        self.stages = stages
        self.prefix = ""
        self.step = 0

    def key(self, stage: str) -> str:
        return f"{self.prefix}/s{self.step:03d}/{stage}"

    def install(self) -> None:
        from gsbench.train import adam, trainer
        rec, render0, iteration0, adam_step0 = self, trainer.render, trainer.Trainer._iteration, adam.Adam.step
        init0 = trainer.Trainer.__init__

        def render(*a, **k):
            out = render0(*a, **k)
            rec.stages[rec.key("render")] = digest(*(v for v in vars(out).values() if torch.is_tensor(v)))
            return out

        def init(tr, *a, **k):
            init0(tr, *a, **k)
            rec.prefix = f"{rec.prefix.split('/')[0]}/{tr.phase}"
            rec.stages[f"{rec.prefix}/init"] = digest(*tr.ps.params.values())

        def iteration(tr):
            rec.step = tr.step + 1
            res = iteration0(tr)
            terms = {k: float(v) for k, v in res.loss.terms.items()}
            values = [terms[k] for k in sorted(terms)] + [float(res.loss.total.detach())]
            rec.stages[rec.key("loss")] = digest(np.array(values))
            rec.stages[rec.key("field")] = digest(*tr.ps.params.values())
            return res

        def adam_step(opt):
            ps = [p for g in opt.param_groups for p in g["params"]]
            rec.stages.setdefault(rec.key("grad"), digest(*(p.grad for p in ps)))
            adam_step0(opt)
            rec.stages.setdefault(rec.key("adam"), digest(*ps))

        trainer.render, trainer.Trainer._iteration, adam.Adam.step = render, iteration, adam_step
        trainer.Trainer.__init__ = init


def run_stages(steps: int, methods: list[str]) -> dict[str, str]:
    """The tiny scene's files and the first `steps` steps of each method (the golden's settings)."""
    from loop_golden import SET, THREADS
    from tiny import TINY_SCENE_ARGS

    from gsbench.cli import main
    from gsbench.config import load_config
    from gsbench.runs import train_run
    torch.set_num_threads(THREADS)
    stages: dict[str, str] = {}
    rec = Recorder(stages)
    rec.install()
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        assert main(["make-scene", *TINY_SCENE_ARGS, "--out", str(work / "scene"), "--quiet"]) == 0
        for f in sorted(p for p in (work / "scene").rglob("*") if p.is_file()):
            stages[f"scene/{f.relative_to(work / 'scene')}"] = hashlib.sha256(f.read_bytes()).hexdigest()[:HASH_CHARS]
        overrides = [s for s in SET if not s.startswith(("train.iterations=", "twostage.semantic_iterations="))]
        for m in methods:
            rec.prefix, rec.step = m, 0       # step 0: the method's set-up (priors, autoencoder) before training
            cfg = load_config(m, "cpu-small", [*overrides, f"train.iterations={steps}",
                                               f"twostage.semantic_iterations={steps}"])
            train_run(cfg, work / "scene", work / m, progress=False)
    return stages


def write(path: Path, steps: int, methods: list[str]) -> None:
    from gsbench.environment import cpu_facts
    pins = ("MKL_CBWR", "ATEN_CPU_CAPABILITY", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "NPY_DISABLE_CPU_FEATURES",
            "OPENCV_CPU_DISABLE", "MKL_ENABLE_INSTRUCTIONS", "GLIBC_TUNABLES", "ONEDNN_MAX_CPU_ISA")
    data = {"cpu": cpu_facts(), "env": {k: os.environ[k] for k in pins if k in os.environ},
            "stages": {**probes(), **run_stages(steps, methods)}}
    path.write_text(json.dumps(data, indent=0, sort_keys=True) + "\n")
    print(f"wrote {path}: {len(data['stages'])} stages")


# ---------------------------------------------------------------------------- compare
def _order(stage: str) -> tuple:
    """Probes, then the scene, then each run's stages in step order."""
    head = 0 if stage.startswith("probe/") else 1 if stage.startswith("scene/") else 2
    return (head, stage)


def _group(stage: str) -> tuple[str, str]:
    """(group, rest): each probe its own group, the scene one, each run's phase one (rest: step/stage)."""
    step = re.search(r"/s\d{3}/", stage)
    if step:
        return stage[:step.start()], stage[step.start() + 1:]
    if stage.startswith("scene/"):
        return "scene", stage[len("scene/"):]
    if stage.startswith("probe/"):
        return stage, ""
    return stage.rsplit("/", 1)[0], stage.rsplit("/", 1)[-1]     # <method>/<phase>/init


def compare(files: list[Path], every_stage: bool = False) -> int:
    """Print, per stage group, whether each file differs from the first and where it first does (with
    `every_stage`, one row per stage); exit status 1 when any stage differs."""
    data = []
    for f in files:
        try:
            data.append(json.loads(Path(f).read_text())["stages"])
        except (OSError, ValueError, KeyError, TypeError) as e:
            sys.exit(f"{f}: not a fingerprint file written by `cpu_fingerprint.py write` ({type(e).__name__}: {e})")
    names = [Path(f).stem for f in files]
    stages = sorted(set().union(*data), key=_order)
    base = data[0]
    differing = [s for s in stages if len({d.get(s) for d in data}) > 1]
    print("| stage | " + " | ".join(names[1:]) + " |")
    print("|---|" + "---|" * (len(names) - 1))
    if every_stage:
        for s in differing:
            print(f"| {s} | " + " | ".join("same" if d.get(s) == base.get(s) else "differs" for d in data[1:]) + " |")
    else:
        groups: dict[str, list[str]] = {}
        for s in stages:
            groups.setdefault(_group(s)[0], []).append(s)
        for g, members in groups.items():
            cells = []
            for d in data[1:]:
                first = next((s for s in members if d.get(s) != base.get(s)), None)
                where = _group(first)[1] if first is not None else ""
                cells.append("same" if first is None else "differs" + (f" from {where}" if where else ""))
            print(f"| {g} | " + " | ".join(cells) + " |")
    print(f"\n{len(differing)} of {len(stages)} stages differ from {names[0]} in at least one file")
    return 1 if differing else 0


def _portable() -> dict[str, str]:
    from loop_golden import PORTABLE_ENV
    return dict(PORTABLE_ENV)


def bisect(folder: Path, steps: int, methods: list[str]) -> int:
    """One file per pinning on this machine (module docstring), then compare them."""
    base = _portable()
    variants = {"portable": base}
    for k in base:
        variants[f"without-{k}"] = {kk: v for kk, v in base.items() if kk != k}
    variants["plus-numba-sse2"] = {**base, "NUMBA_CPU_FEATURES": "+64bit,+cmov,+cx8,+fxsr,+mmx,+sse,+sse2"}
    variants["plus-glibc-no-fma"] = {**base, "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2_Usable,-FMA_Usable,-AVX_Usable,"
                                     "-AVX2,-FMA,-AVX,-AVX512F"}
    variants["plus-onednn-off"] = {**base, "ONEDNN_MAX_CPU_ISA": "SSE41"}
    variants["no-pin"] = {}
    folder.mkdir(parents=True, exist_ok=True)
    clean = {k: v for k, v in os.environ.items() if k not in base and k not in ("NUMBA_CPU_FEATURES", "GLIBC_TUNABLES")}
    files = []
    with tempfile.TemporaryDirectory() as caches:
        for name, env in variants.items():
            out = folder / f"{name}.json"
            files.append(out)
            if out.exists():          # an interrupted bisect resumes: files already written are kept
                continue
            cmd = [sys.executable, __file__, "write", str(out), "--steps", str(steps), "--methods", ",".join(methods)]
            # one numba cache per numba target: variants that compile alike share their kernels
            target = hashlib.sha256(repr((env.get("NUMBA_CPU_NAME"), env.get("NUMBA_CPU_FEATURES"))).encode())
            cache = Path(caches) / target.hexdigest()[:8]
            subprocess.run(cmd, env={**clean, **env, "NUMBA_CACHE_DIR": str(cache)}, check=True)
    return compare(files)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name in ("write", "bisect"):
        p = sub.add_parser(name)
        p.add_argument("path", type=Path)
        p.add_argument("--steps", type=int, default=10)
        p.add_argument("--methods", default="vanilla,grouping,gaussiands")
    p = sub.add_parser("compare")
    p.add_argument("files", type=Path, nargs="+")
    p.add_argument("--every-stage", action="store_true", help="one row per differing stage")
    a = ap.parse_args(argv)
    if a.cmd == "compare":
        return compare(a.files, a.every_stage)
    methods = [m for m in a.methods.split(",") if m]
    if a.cmd == "write":
        write(a.path, a.steps, methods)
        return 0
    return bisect(a.path, a.steps, methods)


if __name__ == "__main__":
    sys.exit(main())
