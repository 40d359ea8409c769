"""scripts/gpu_claims.py on a faked CUDA machine: the plan the script runs on a lent GPU (offline installs,
the gsplat build, the --jobs split over lanes, the cell deadline, the publish target), checked with a fake
interpreter that records every command and stands in for pip and gsbench, so no cell is trained, nothing
is installed and no GPU is needed. The GPU grids themselves are checked in-process with torch's CUDA
faked: every cell resolves to cuda:0 and gsplat, and to other run ids than the CPU store's."""
from __future__ import annotations

import importlib.util
import json
import socket
import stat
import sys
import time
from pathlib import Path

import pytest
import torch
import yaml

from gsbench.config import run_id
from gsbench.device import resolve_device
from gsbench.grids import claims_plan
from gsbench.grids.grid_file import load_grid
from gsbench.grids.planning import cell_config
from gsbench.render import backend_choice

ROOT = Path(__file__).resolve().parents[2]

# The fake interpreter: one JSON line per call (argv, offline env, own session); `-c` answers the CUDA
# check; ablate writes finished cells, and for grids named in FAKE_SLOW (stops on SIGINT) or FAKE_STUBBORN
# (ignores SIGINT) leaves one cell running and waits for the deadline. An ablate says it is ready (its
# SIGINT handling set, its cells written) with a file FAKE_READY/<pid>: the script's signals wait for it
# (_after_ready), so no test races a process it started.
FAKE_PYTHON = """#!{python}
import os, signal, sys
from pathlib import Path
argv = sys.argv[1:]
if argv[:3] == ["-m", "gsbench.cli", "ablate"]:
    # first, before any slow start-up under load: the deadline's SIGINT may come at once
    def _interrupted(*_):
        out = Path(argv[argv.index("--out") + 1]); out.mkdir(parents=True, exist_ok=True)
        (out / "interrupted").write_text("SIGINT")
        sys.exit(130)
    if Path(argv[argv.index("--grid") + 1]).stem in os.environ.get("FAKE_STUBBORN", ""):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    else:
        signal.signal(signal.SIGINT, _interrupted)
import json, time
with open(os.environ["FAKE_LOG"], "a") as f:
    f.write(json.dumps({{"argv": argv, "PIP_NO_INDEX": os.environ.get("PIP_NO_INDEX"),
                        "HF_HUB_OFFLINE": os.environ.get("HF_HUB_OFFLINE"),
                        "own_session": os.getsid(0) == os.getpid()}}) + "\\n")
if argv[0] == "-c":
    sys.exit(int(os.environ.get("FAKE_CUDA_RC", "0")))
if argv[-4:-3] == ["reuse"]:
    d = Path(argv[-3]) / "published0"; d.mkdir(parents=True)
    (d / "cell_status.json").write_text(json.dumps({{"state": "done", "published": "x"}}))
if argv[:3] == ["-m", "gsbench.cli", "ablate"]:
    grid, out = Path(argv[argv.index("--grid") + 1]), Path(argv[argv.index("--out") + 1])
    for i in range(int(os.environ["FAKE_CELLS"])):
        d = out / f"cell{{i}}"; d.mkdir(parents=True)
        (d / "cell_status.json").write_text(json.dumps({{"state": "done", "finished": time.time()}}))
    if grid.stem in os.environ.get("FAKE_SLOW", "") + os.environ.get("FAKE_STUBBORN", ""):
        d = out / "running"; d.mkdir(parents=True)
        (d / "cell_status.json").write_text(json.dumps({{"state": "running"}}))
    (Path(os.environ["FAKE_READY"]) / str(os.getpid())).write_text("ready")
    if grid.stem in os.environ.get("FAKE_SLOW", "") + os.environ.get("FAKE_STUBBORN", ""):
        time.sleep(60)
"""


def _script():
    spec = importlib.util.spec_from_file_location("gpu_claims_script", ROOT / "scripts" / "gpu_claims.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _after_ready(mod, ready: Path):
    """The script with its deadline signals held until the fake they go to is ready (FAKE_PYTHON), so a
    slow start under load can never meet the SIGINT before its handler is set; bounded at 60 s."""
    send = mod._signal_group

    def signal_when_ready(pid: int, sig: int) -> None:
        until = time.monotonic() + 60.0
        while not (ready / str(pid)).exists() and time.monotonic() < until:
            time.sleep(0.05)
        send(pid, sig)
    mod._signal_group = signal_when_ready
    return mod


@pytest.fixture
def machine(tmp_path, monkeypatch):
    """A fake interpreter, two carried wheels, and no network for this process."""
    exe = tmp_path / "python"
    exe.write_text(FAKE_PYTHON.format(python=sys.executable))
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    for w in ("gsplat-1.5.3-py3-none-any.whl", "pycolmap-3.12.6-cp312-cp312-manylinux_2_28_x86_64.whl"):
        (wheels / w).write_bytes(b"")
    log = tmp_path / "calls.jsonl"
    ready = tmp_path / "ready"
    ready.mkdir()
    monkeypatch.setenv("FAKE_LOG", str(log))
    monkeypatch.setenv("FAKE_READY", str(ready))
    monkeypatch.setenv("FAKE_CELLS", "2")

    def no_network(*a, **k):
        raise AssertionError("gpu_claims tried to open a network connection")
    monkeypatch.setattr(socket, "create_connection", no_network)
    monkeypatch.setattr(socket.socket, "connect", no_network)
    return {"exe": exe, "wheels": wheels, "log": log, "runs": tmp_path / "runs", "store": tmp_path / "gpu",
            "ready": ready}


def _calls(log: Path) -> list[dict]:
    return [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []


def _argv(m, *extra):
    return ["--python", str(m["exe"]), "--wheels", str(m["wheels"]), "--out", str(m["runs"]),
            "--store", str(m["store"]), *extra]


def _offline(calls):
    for c in calls:
        text = " ".join(c["argv"])
        assert "://" not in text and "download" not in text, text
        assert c["PIP_NO_INDEX"] == "1" and c["HF_HUB_OFFLINE"] == "1"
        if c["argv"][:2] == ["-m", "pip"]:
            assert "--no-index" in c["argv"] and "--no-deps" in c["argv"]


def test_budget_stops_running_grids_leaves_the_rest_and_publishes_finished_cells(machine, monkeypatch):
    m = machine
    monkeypatch.setenv("FAKE_SLOW", "ordering-cpu")
    monkeypatch.setenv("FAKE_STUBBORN", "depth_formulation-cpu")
    (m["store"] / "ordering-cpu").mkdir(parents=True)        # a grid with published cells: reused first
    t0 = time.monotonic()
    script = _after_ready(_script(), m["ready"])
    rc = script.main(_argv(m, "--grids", "ordering-cpu", "depth_formulation-cpu", "control_sem-cpu",
                           "--jobs", "5", "--lanes", "2", "--minutes", "0.15", "--reserve-s", "3",
                           "--grace-s", "1", "--min-start-s", "1"))
    took = time.monotonic() - t0
    calls = _calls(m["log"])
    assert rc == 0 and took < 30
    _offline(calls)
    kinds = [c["argv"][:2] if c["argv"][0] == "-m" else c["argv"][:1] for c in calls]
    assert kinds[:4] == [["-m", "pip"], ["-m", "pip"], ["-c"], ["-m", "gsbench.cli"]]
    assert sorted(Path(a).name for a in calls[0]["argv"] if a.endswith(".whl")) == sorted(
        p.name for p in m["wheels"].iterdir())
    assert calls[1]["argv"][-2:] == ["-e", str(ROOT)] and "--no-build-isolation" in calls[1]["argv"]
    assert calls[3]["argv"][2:] == ["doctor", "--build-gsplat"]
    ablates = {Path(c["argv"][c["argv"].index("--grid") + 1]).stem: c for c in calls if "ablate" in c["argv"]}
    assert set(ablates) == {"ordering-cpu", "depth_formulation-cpu"}          # control_sem-cpu: no time left
    assert sorted(int(c["argv"][c["argv"].index("--jobs") + 1]) for c in ablates.values()) == [2, 3]
    assert all(c["own_session"] for c in ablates.values())                    # its own group gets the SIGINT
    assert (m["runs"] / "ordering-cpu" / "interrupted").read_text() == "SIGINT"
    assert not (m["runs"] / "depth_formulation-cpu" / "interrupted").exists()  # ignored SIGINT: SIGKILLed
    reuses = [c["argv"][-4:] for c in calls if "reuse" in c["argv"]]
    assert reuses == [["reuse", str(m["runs"] / "ordering-cpu"), str(m["runs"] / "_grids" / "ordering-cpu.yaml"),
                       str(m["store"])]]
    publishes = sorted(c["argv"][2:] for c in calls if "publish" in c["argv"])
    assert publishes == sorted(["publish", str(m["runs"] / g), "--to", str(m["store"]), "--grids",
                                str(m["runs"] / "_grids" / f"{g}.yaml")]
                               for g in ("ordering-cpu", "depth_formulation-cpu"))
    grid = yaml.safe_load((m["runs"] / "_grids" / "ordering-cpu.yaml").read_text())
    assert grid["base"]["set"]["backend"] == "gsplat"
    summary = json.loads((m["runs"] / "gpu_claims.json").read_text())
    assert (summary["trained"], summary["reused"], summary["unfinished"]) == (4, 1, 2)
    assert summary["not_started"] == ["control_sem-cpu"]
    assert summary["grids"]["ordering-cpu"]["stopped_at_budget"] is True
    text = (m["runs"] / "gpu_claims.log").read_text()
    assert "minute 1: 4 cells" in text and "not started" in text


def test_no_cuda_stops_before_any_cell(machine, monkeypatch):
    m = machine
    monkeypatch.setenv("FAKE_CUDA_RC", "3")
    rc = _script().main(_argv(m, "--grids", "control_sem-cpu"))
    calls = _calls(m["log"])
    assert rc == 1 and calls[-1]["argv"][0] == "-c"
    assert not any("ablate" in c["argv"] or "publish" in c["argv"] for c in calls)
    assert "torch sees no CUDA device" in (m["runs"] / "gpu_claims.log").read_text()


def test_dry_run_runs_nothing_and_prints_the_whole_plan(machine, capsys):
    m = machine
    rc = _script().main(_argv(m, "--dry-run", "--jobs", "16", "--lanes", "2"))
    out = capsys.readouterr().out
    assert rc == 0 and _calls(m["log"]) == [] and not m["runs"].exists()
    names = claims_plan.CLAIM_GRIDS + claims_plan.CONTROL_GRIDS
    for name in names:
        assert f"ablate --grid {m['runs'] / '_grids' / name}.yaml --out {m['runs'] / name} --jobs 8" in out
        assert f"publish {m['runs'] / name} --to {m['store']}" in out
    assert "--jobs [8, 8] (sum 16)" in out and "-m pip install --no-index" in out


def test_jobs_split_over_lanes_and_the_plan_read_without_gsbench():
    s = _script()
    assert s.split_jobs(16, 2) == [8, 8] and s.split_jobs(5, 2) == [3, 2] and s.split_jobs(2, 4) == [1, 1]
    assert s.claims_grids() == list(claims_plan.CLAIM_GRIDS + claims_plan.CONTROL_GRIDS)
    assert s.per_minute([100.0, 130.0, 250.0, 274.0], 95.0) == [2, 0, 2]   # 5, 35, 155, 179 s in
    with pytest.raises(SystemExit, match="usage"):       # its gsbench imports resolve
        s.main(["reuse", "only-one-argument"])


def test_every_gpu_cell_renders_with_gsplat_on_cuda_and_has_its_own_run_id(tmp_path, monkeypatch):
    """torch's CUDA faked: the GPU grid's cells go to cuda:0 and gsplat; the shipped ones stay on the CPU."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    monkeypatch.setattr(backend_choice, "gsplat_available", lambda: True)
    s = _script()
    for name in claims_plan.CLAIM_GRIDS + claims_plan.CONTROL_GRIDS:
        gpu, cpu = load_grid(s.write_gpu_grid(name, tmp_path / "grids")), load_grid(name)
        assert gpu.name == name and len(gpu.cells()) == len(cpu.cells())
        assert all(c.overrides["backend"] == "gsplat" for c in gpu.cells())
        for k in (0, -1):      # resolved in full: the first and last cell of each grid
            gc, cc = gpu.cells()[k], cpu.cells()[k]
            g, c = cell_config(gc, tmp_path, gpu.axis_keys), cell_config(cc, tmp_path, cpu.axis_keys)
            dev = resolve_device(g)
            assert str(dev) == "cuda:0" and backend_choice.resolve_backend(g["backend"], dev) == "gsplat"
            assert str(resolve_device(c)) == "cpu"
            assert run_id(g, "scene") != run_id(c, "scene")
            assert {**g, "backend": None} == {**c, "backend": None}     # the backend is all that differs


def test_no_publish_once_the_budget_is_spent(machine, monkeypatch):
    m = machine
    monkeypatch.setenv("FAKE_STUBBORN", "control_sem-cpu")
    script = _after_ready(_script(), m["ready"])
    rc = script.main(_argv(m, "--grids", "control_sem-cpu", "--minutes", "0.05", "--reserve-s", "0.5",
                           "--grace-s", "1", "--min-start-s", "0"))     # killed at 3.5 s, after the 3 s budget
    assert rc == 1 and not any("publish" in c["argv"] for c in _calls(m["log"]))
    assert "control_sem-cpu: 2 finished cells not published" in (m["runs"] / "gpu_claims.log").read_text()
