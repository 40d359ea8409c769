"""A faked CUDA machine: torch.cuda.is_available / device_count (and the device name) patched, the
rest of torch left real, so any code that really touches CUDA on this CPU-only torch still fails.
Every decision that does not compute on a GPU is exercised here: device and backend resolution for
every shipped preset and grid, `make demo`'s configuration end to end, the executor's GPU slots,
resume across device kinds, and gsplat present without its compiled extension."""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
import torch

import gsbench.render.backend_choice as D
import gsbench.render.gsplat_ext as G
from gsbench.config import load_config, shipped_presets
from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.train.render_backend import prebuild_for
from gsbench.render.gsplat_ext import GsplatStatus
from paths import REPO_ROOT

ROOT = REPO_ROOT
SHIPPED = [None, *shipped_presets()]           # None: default.yaml alone
REAL_GSPLAT_AVAILABLE = D.gsplat_available


@pytest.fixture
def fake_cuda(monkeypatch):
    """Two CUDA devices as far as the decision points can tell; gsplat ready to render."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setattr(torch.cuda, "current_device", lambda: 0)
    monkeypatch.setattr(torch.cuda, "get_device_name", lambda *a: "Fake GPU")
    monkeypatch.setattr(torch.cuda, "get_device_properties",
                        lambda i: SimpleNamespace(name="Fake GPU", total_memory=80 * 2**30, major=9, minor=0))
    monkeypatch.setattr(D, "gsplat_status", lambda: GsplatStatus(G.READY, "1.5.3", "faked: extension loaded"),
                        raising=False)
    monkeypatch.setattr(D, "gsplat_available", lambda: True)
    return monkeypatch


def _real_gsplat_check(mp) -> None:
    """Undo the fixture's gsplat shortcut: the real check runs (on the fake package)."""
    mp.setattr(D, "gsplat_status", G.gsplat_status, raising=False)
    mp.setattr(D, "gsplat_available", REAL_GSPLAT_AVAILABLE)


def _resolve(cfg: dict) -> tuple[str, str]:
    dev = resolve_device(cfg)
    return str(dev), D.resolve_backend(cfg.get("backend", "auto"), dev)


# ---------------------------------------------------------------------------- point 1: presets and grids
@pytest.mark.parametrize("preset", SHIPPED)
@pytest.mark.parametrize("method", ["vanilla", "twostage", "gaussiands"])
def test_every_shipped_preset_resolves_on_a_cuda_machine(fake_cuda, preset, method):
    cfg = load_config(method, preset, [])
    pinned = preset is not None and yaml.safe_load((ROOT / "gsbench" / "configs" / f"{preset}.yaml").read_text()
                                                   ).get("backend") == "cpu"   # the file says cpu
    assert _resolve(cfg) == (("cpu", "cpu") if pinned else ("cuda:0", "gsplat"))


def test_the_shipped_presets_are_the_files():
    assert shipped_presets() == sorted(p.stem for p in (ROOT / "gsbench" / "configs").glob("*.yaml")
                                       if p.stem != "default")
    assert {"cpu-small", "cpu-medium", "cpu-real", "paper"} <= set(shipped_presets())


def test_every_shipped_grid_resolves_on_a_cuda_machine(fake_cuda, tmp_path):
    from gsbench.grids.planning import cell_config
    from gsbench.grids.grid_file import load_grid, shipped_grids
    names = shipped_grids()
    assert "tiny-test" in names and any(n.endswith("-cpu") for n in names)
    for name in names:
        grid = load_grid(name)
        seen = set()
        for cell in grid.cells():     # scenes and seeds do not change the resolution: one cell per config
            key = json.dumps([cell.method, cell.preset, {k: v for k, v in cell.overrides.items() if k != "seed"}],
                             sort_keys=True, default=str)
            if key in seen:
                continue
            seen.add(key)
            cfg = cell_config(cell, tmp_path, grid.axis_keys)
            got = _resolve(cfg)        # an InputError here fails the test with the grid's name in the trace
            if name.endswith("-cpu") or name == "tiny-test":
                assert got == ("cpu", "cpu"), name
            else:
                assert got[0] == "cuda:0", name


def test_explicit_cuda_with_the_cpu_backend_is_still_one_clear_error(fake_cuda):
    cfg = load_config("vanilla", "cpu-small", ["train.device=cuda"])
    with pytest.raises(InputError, match="backend=cpu renders on the CPU only"):
        _resolve(cfg)
    assert _resolve(load_config("vanilla", "cpu-small", ["train.device=cuda:1", "backend=auto"])) == ("cuda:1",
                                                                                                        "gsplat")


def test_the_cuda_end_to_end_test_configs_resolve(fake_cuda):
    from tiny import device_run_overrides
    for dev, want in (("cpu", ("cpu", "cpu")), ("cuda", ("cuda:0", "gsplat"))):
        assert _resolve(load_config("vanilla", "cpu-small", device_run_overrides(dev))) == want


def _demo_train_args() -> tuple[list[str], str]:
    """The methods and preset `make demo` trains with, read from scripts/demo.sh."""
    text = (ROOT / "scripts" / "demo.sh").read_text()
    methods = re.search(r"for m in ([a-z ]+); do", text).group(1).split()
    preset = re.search(r'step train --method "\$m" .*--preset (\S+)', text).group(1)
    return methods, preset


def test_demo_configuration_and_tiny_run_train_and_evaluate_on_a_cuda_machine(fake_cuda, tiny_scene, tmp_path):
    """`make demo`'s preset (and the tiny_run fixture's arguments) on a CUDA machine: the run trains
    and evaluates on the CPU with the cpu backend, and nothing touches CUDA (this torch has none)."""
    from gsbench.cli import main
    from gsbench.store import read_json
    from tiny import TINY_TRAIN_ARGS
    methods, preset = _demo_train_args()
    assert methods == ["gaussiands", "vanilla", "twostage"] and preset == "cpu-small"
    for m in methods:
        assert _resolve(load_config(m, preset, [])) == ("cpu", "cpu")
    assert TINY_TRAIN_ARGS[TINY_TRAIN_ARGS.index("--preset") + 1] == preset
    run = tmp_path / "run"
    assert main(["train", *TINY_TRAIN_ARGS, "--scene", str(tiny_scene), "--out", str(run)]) == 0
    s = read_json(run / "train_summary.json")
    assert s["info"]["device"] == "cpu" and s["backend"] == "cpu" and "train_peak_cuda_mb" not in s
    assert main(["eval", str(run), "--quiet"]) == 0
    r = read_json(run / "results.json")
    assert r["eval_device"] == "cpu" and r["backend"] == "cpu"


# ---------------------------------------------------------------------------- point 2: gsplat's extension
@pytest.fixture
def fake_gsplat(tmp_path, monkeypatch):
    """An importable `gsplat` package without its compiled extension. Importing its
    gsplat.cuda._backend (what compiles) is recorded in sys.modules' `gsplat_fake_compiled` flag."""
    pkg = tmp_path / "pkgs" / "gsplat"
    (pkg / "cuda").mkdir(parents=True)
    (pkg / "__init__.py").write_text('__version__ = "1.5.3"\n')
    (pkg / "cuda" / "__init__.py").write_text("")
    (pkg / "cuda" / "_backend.py").write_text("import sys\nsys.gsplat_fake_compiled = True\n_C = object()\n")
    for name in [n for n in sys.modules if n == "gsplat" or n.startswith("gsplat.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.syspath_prepend(str(tmp_path / "pkgs"))
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))
    monkeypatch.setattr(sys, "gsplat_fake_compiled", False, raising=False)
    monkeypatch.setattr(G, "_nvcc", lambda: None)
    yield pkg
    for name in [n for n in sys.modules if n == "gsplat" or n.startswith("gsplat.")]:
        del sys.modules[name]


def test_gsplat_without_extension_or_toolkit_is_not_picked(fake_cuda, fake_gsplat, caplog):
    _real_gsplat_check(fake_cuda)
    st = G.gsplat_status()
    assert st.state == G.NO_TOOLKIT and st.version == "1.5.3" and not st.usable
    cuda = torch.device("cuda", 0)
    with caplog.at_level("WARNING", logger="gsbench.render.backend_choice"):
        assert D.resolve_backend("auto", cuda) == "torch"
    assert "no CUDA toolkit" in caplog.text
    with pytest.raises(InputError, match="gsplat cannot render here"):
        D.resolve_backend("gsplat", cuda)
    with pytest.raises(InputError, match="no CUDA toolkit"):
        G.build_gsplat_extension()
    assert sys.gsplat_fake_compiled is False        # nothing was compiled or loaded by the checks


def test_gsplat_extension_states_are_read_from_files(fake_cuda, fake_gsplat, tmp_path, capsys):
    from gsbench.cli import main
    _real_gsplat_check(fake_cuda)
    fake_cuda.setattr(G, "_nvcc", lambda: "/opt/cuda/bin/nvcc")
    assert G.gsplat_status().state == G.NEEDS_BUILD
    assert D.resolve_backend("auto", torch.device("cuda", 0)) == "gsplat"
    assert main(["doctor"]) == 0
    out = capsys.readouterr().out
    assert "gsplat   1.5.3: needs-build: CUDA extension not built" in out and "--build-gsplat" in out
    build = tmp_path / "ext" / G.EXTENSION
    build.mkdir(parents=True, exist_ok=True)
    (build / f"{G.EXTENSION}.so").write_bytes(b"")
    assert G.gsplat_status().state == G.CACHED
    (fake_gsplat / "csrc.py").write_text("")          # a wheel that ships the extension
    assert G.gsplat_status().state == G.READY
    assert sys.gsplat_fake_compiled is False


def test_a_grid_builds_gsplat_once_before_its_workers_and_only_when_a_cell_uses_it(fake_cuda, fake_gsplat, caplog):
    _real_gsplat_check(fake_cuda)
    fake_cuda.setattr(G, "_nvcc", lambda: "/opt/cuda/bin/nvcc")
    cpu_cells = [load_config("vanilla", "cpu-small", []), load_config("gaussiands", "cpu-medium", [])]
    assert prebuild_for(cpu_cells) is False and sys.gsplat_fake_compiled is False
    with caplog.at_level("WARNING", logger="gsbench.render.gsplat_ext"):
        assert prebuild_for(cpu_cells + [load_config("vanilla", None, [])]) is True
    assert sys.gsplat_fake_compiled is True and "compiling its CUDA extension" in caplog.text
    assert G.gsplat_status().state == G.READY       # loaded in this process now


# ---------------------------------------------------------------------------- point 3: resume across kinds
def _trainer(tmp_path, backend="cpu"):
    from gsbench.train.trainer import Trainer
    from gsbench.train.views import TrainViews
    from gsbench.train.initial_field import init_field
    cfg = load_config("vanilla", "cpu-small", [])
    fld, _ = init_field(None, None, "random", 8, np.zeros(3), 1.0, 0, 0, seed=0)
    return Trainer(cfg, TrainViews({}, {}), 1.0, fld, tmp_path, lambda *a: None, backend=backend)


def test_resume_of_a_cuda_checkpoint_on_the_cpu_is_one_clear_error(tmp_path):
    st = _trainer(tmp_path).state()
    assert st["torch_gen"].numel() == 5056              # a CUDA generator's state is 16 bytes
    legacy = {k: v for k, v in st.items() if k not in ("device", "backend")}   # checkpoints before the tag
    legacy["torch_gen"] = torch.zeros(16, dtype=torch.uint8)
    with pytest.raises(InputError, match="another kind of device"):   # was: RuntimeError RNG state wrong size
        _trainer(tmp_path).load_state(legacy)
    cuda_st = dict(legacy, device="cuda:0", backend="gsplat")
    with pytest.raises(InputError, match=r"checkpoint\.pt: written training on cuda:0 with backend gsplat"):
        _trainer(tmp_path).load_state(cuda_st)
    assert st["device"] == "cpu" and st["backend"] == "cpu"
    _trainer(tmp_path).load_state(st)                 # the same kind still resumes


def test_resume_of_a_cpu_checkpoint_on_cuda_is_one_clear_error(tmp_path):
    st = _trainer(tmp_path).state()
    tr = _trainer(tmp_path, backend="gsplat")
    tr.device = torch.device("cuda", 0)               # what a CUDA machine resolves; nothing is allocated
    with pytest.raises(InputError, match="written training on cpu with backend cpu.*cuda:0 with backend gsplat"):
        tr.load_state(st)


# ---------------------------------------------------------------------------- point 4: executor GPU slots
def test_gpu_slots_keep_the_parents_device_names():
    from gsbench.grids.executors import gpu_slots
    assert gpu_slots(3, 2, None) == ["0", "1", "0"]
    assert gpu_slots(2, 2, "2,3") == ["2", "3"]
    assert gpu_slots(3, 2, "2, 3") == ["2", "3", "2"]
    uuids = "GPU-8f1c2a3b-0000-1111-2222-333344445555,GPU-9e0d1b2c-6666-7777-8888-999900001111"
    assert gpu_slots(2, 2, uuids) == uuids.split(",")
    assert gpu_slots(2, 1, "3,bogus") == ["3", "3"]   # torch sees the prefix before the invalid entry
    assert gpu_slots(4, 0, "2,3") == []
    with pytest.raises(InputError, match="CUDA_VISIBLE_DEVICES"):
        gpu_slots(2, 2, "3")


@pytest.mark.slow   # three spawned processes that import torch: ~15 s on 2 cores
def test_local_executor_workers_get_the_parents_gpus(monkeypatch):
    """Two spawned workers under CUDA_VISIBLE_DEVICES=2,3 get GPUs 2 and 3, not 0 and 1."""
    import gsbench.grids.executors as E
    monkeypatch.setattr(E, "_gpu_count", lambda: 2)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "2,3")
    # os.getenv(name, item): a function the spawned workers import without this test module
    got = E.LocalExecutor(jobs=2, progress=False).map(functools.partial(os.getenv, "CUDA_VISIBLE_DEVICES"),
                                                     ["<unset>", "<unset>"])
    assert sorted(got) == ["2", "3"]


# ---------------------------------------------------------------------------- point 5: Python version
def test_declared_python_is_the_one_that_runs_the_executor():
    """ProcessPoolExecutor(max_tasks_per_child=...) exists from 3.11: the declared minimum says so,
    and this suite (CI's) runs under that minimum or later."""
    import tomllib
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    low = tuple(int(x) for x in re.match(r">=\s*(\d+)\.(\d+)", meta["project"]["requires-python"]).groups())
    assert low >= (3, 11) and sys.version_info[:2] >= low
    assert meta["tool"]["ruff"]["target-version"] == f"py{low[0]}{low[1]}"


# ---------------------------------------------------------------------------- gsbench doctor
def test_doctor_on_this_machine(capsys):
    from gsbench.cli import main
    assert main(["doctor"]) == 0
    out = capsys.readouterr().out
    assert f"torch    {torch.__version__}" in out and "gsplat" in out and "numba" in out
    for preset in ("default", "cpu-small", "cpu-medium", "paper"):
        assert re.search(rf"^  {preset}\s.*-> ", out, re.M), out


def test_doctor_on_a_fake_cuda_machine(fake_cuda, capsys):
    from gsbench.cli import main
    assert main(["doctor"]) == 0
    out = capsys.readouterr().out
    assert "cuda     2 device(s)" in out and "cuda:1  Fake GPU, 80.0 GiB, compute capability 9.0" in out
    assert re.search(r"^  cpu-small .*-> cpu, backend cpu$", out, re.M), out
    assert re.search(r"^  paper .*-> cuda:0, backend gsplat$", out, re.M), out


# ---------------------------------------------------------------------------- point 6: the smaller points
def test_densify_stats_make_no_tensor_from_host_numbers_per_step(monkeypatch):
    """The (W/2, H/2) scale is built once per image size, not every step (a blocking copy on CUDA)."""
    from gsbench.train.densify import DensifyStats
    stats = DensifyStats(4)
    made = []
    real = torch.tensor
    monkeypatch.setattr(torch, "tensor", lambda *a, **k: made.append(a) or real(*a, **k))
    g = torch.tensor([[1.0, 0.0], [0.0, 1.0], [3.0, 4.0], [0.0, 0.0]])
    radii = torch.tensor([[1, 1], [2, 2], [1, 1], [0, 0]])
    made.clear()
    for _ in range(3):
        stats.update(g, radii, 20, 10)
    assert len(made) == 1
    # NDC units: (x * W/2, y * H/2) -> norms 10, 5, |(30, 20)| = sqrt(1300); the culled one is not counted
    assert torch.allclose(stats.grad, torch.tensor([30.0, 15.0, 3 * 1300 ** 0.5, 0.0]))
    assert torch.equal(stats.count, torch.tensor([3.0, 3.0, 3.0, 0.0]))


def test_method_background_is_made_once_per_device(tiny_run):
    from gsbench.methods import Method
    m = Method.load(tiny_run / "model.pt")
    assert m._background() is m._background()
    assert torch.equal(m._background(), torch.zeros(3))


def test_fps_synchronises_the_device_the_model_is_on(fake_cuda):
    from gsbench.evaluation.image import fps
    from gsbench.metrics.timing import time_fps
    synced = []
    fake_cuda.setattr(torch.cuda, "is_initialized", lambda: True)
    fake_cuda.setattr(torch.cuda, "synchronize", lambda device=None: synced.append(device))
    res = time_fps(lambda: None, warmup=1, repeats=3, device=torch.device("cuda", 1))
    assert synced == [torch.device("cuda", 1)] * 4 and res["sync"] == "torch.cuda.synchronize(cuda:1)"
    synced.clear()
    assert time_fps(lambda: None, warmup=1, repeats=2, device="cpu")["sync"] == "none (cpu, synchronous)"
    assert synced == []                       # a CPU model is not timed against CUDA work
    method = SimpleNamespace(device=torch.device("cuda", 1), render=lambda cam: None)
    block = fps(method, ["cam"], {"eval": {"fps_warmup": 0, "fps_repeats": 2}})
    assert block.timings["fps_sync"] == "torch.cuda.synchronize(cuda:1)" and set(synced) == {torch.device("cuda", 1)}


class _Recorder:
    """Stands in for a prior model class: records the device it was built for."""
    built: list = []

    def __init__(self, *args, device=None, **kwargs):
        _Recorder.built.append(device if device is not None else (args[1] if len(args) > 1 else None))
        self.id = "recorded"

    def predict(self, image, size):
        return np.ones((size[1], size[0]), np.float32)


def test_prior_models_run_on_the_training_device(fake_cuda, tiny_scene, tmp_path):
    import gsbench.priors.depth as PD
    import gsbench.priors.features as PF
    import gsbench.priors.masks as PM
    from gsbench.datasets import load_scene
    from gsbench.methods.base import fit_priors
    from gsbench.priors.pipeline import _compute_masks
    fake_cuda.setattr(PD, "DepthAnything", _Recorder)
    fake_cuda.setattr(PM, "Sam2Masks", _Recorder)
    fake_cuda.setattr(PF, "OpenClipFeatures", _Recorder)
    _Recorder.built = []
    scene = load_scene(tiny_scene)
    model = tmp_path / "depth-model"
    model.mkdir()
    cfg = load_config("gaussiands", "cpu-small", ["train.device=cuda:1", "backend=auto",
                                                 "priors.depth.provider=depth-anything",
                                                 f"priors.depth.model_path={model}", "train.max_width=16",
                                                 f"priors.cache_dir={tmp_path / 'cache'}"])
    fit_priors(scene, cfg, tmp_path / "run", progress=False)
    PF.get_feature_provider({"provider": "openclip", "checkpoint": "x"}, device="cuda:1")
    try:
        _compute_masks(scene, {"provider": "sam2"}, [0], [0], (16, 12), None, False, 0, False, device="cuda:1")
    except AttributeError:     # the recorder cannot segment; only its device matters here
        pass
    assert _Recorder.built == ["cuda:1", "cuda:1", "cuda:1"]
