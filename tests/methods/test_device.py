"""train.device and backend resolution: CUDA asked for on a machine without it is a one-line error;
auto picks the device's backend; CUDA runs skip cleanly without CUDA."""
import pytest
import torch
from render_fields import look_at, random_field
from tiny import device_run_overrides

from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.render import resolve_backend

NO_CUDA = not torch.cuda.is_available()


def test_resolve_device_choices():
    assert resolve_device({"train": {"device": "cpu"}}) == torch.device("cpu")
    auto = resolve_device({"train": {"device": "auto"}})
    assert auto.type == ("cuda" if torch.cuda.is_available() else "cpu")
    for bad in ("gpu", "cuda:x", "tpu"):
        with pytest.raises(InputError, match="train.device"):
            resolve_device({"train": {"device": bad}})


@pytest.mark.skipif(not NO_CUDA, reason="checks the error on a machine without CUDA")
def test_cuda_without_cuda_is_an_error():
    with pytest.raises(InputError, match="CUDA is not available"):
        resolve_device({"train": {"device": "cuda"}})


def test_backend_for_cpu_device():
    cpu = torch.device("cpu")
    assert resolve_backend("auto", cpu) == "cpu"
    assert resolve_backend("torch", cpu) == "torch"
    with pytest.raises(InputError, match="gsplat"):
        resolve_backend("gsplat", cpu)


def test_backend_for_cuda_device_without_gsplat_warns_once(monkeypatch, caplog):
    import gsbench.render.backend_choice as D
    monkeypatch.setattr(D, "gsplat_available", lambda: False)
    cuda = torch.device("cuda", 0)            # resolution only: nothing is allocated
    with caplog.at_level("WARNING", logger="gsbench.render.backend_choice"):
        assert resolve_backend("auto", cuda) == "torch"
    assert len(caplog.records) == 1 and "gsplat" in caplog.records[0].getMessage()
    with pytest.raises(InputError, match="CPU only"):
        resolve_backend("cpu", cuda)
    monkeypatch.setattr(D, "gsplat_available", lambda: True)
    assert resolve_backend("auto", cuda) == "gsplat"


def test_methods_and_render_take_the_one_backend_rule(monkeypatch):
    """A config's backend (gsbench/train/render_backend.py) and render()'s `auto` are gsbench.render's rule,
    not copies."""
    import gsbench.render.backend_choice as D
    from gsbench.config import load_config
    from gsbench.render import render
    from gsbench.train.render_backend import resolve_render_backend
    cfg = load_config("vanilla", None, [])
    cuda = torch.device("cuda", 0)            # resolution only: nothing is allocated
    for usable, want in ((False, "torch"), (True, "gsplat")):
        monkeypatch.setattr(D, "gsplat_available", lambda u=usable: u)
        assert resolve_render_backend(cfg, cuda) == D.resolve_backend("auto", cuda) == want
    assert resolve_render_backend(cfg, torch.device("cpu")) == "cpu"
    with pytest.raises(InputError, match="gsplat"):
        resolve_render_backend({**cfg, "backend": "gsplat"}, torch.device("cpu"))
    assert render(random_field(4, 0), look_at(8, 6, eye=(0.0, 0.0, 3.0)), backend="auto").backend == "cpu"


@pytest.mark.skipif(not NO_CUDA, reason="checks the error on a machine without CUDA")
def test_cli_train_device_cuda_without_cuda_is_one_line_error(tmp_path, capsys):
    from gsbench.cli import main
    from gsbench.datasets.synthetic import make_scene
    scene = make_scene("tabletop-small", tmp_path / "s", seed=0, views=6, resolution=(32, 24))
    rc = main(["train", "--method", "vanilla", "--scene", str(scene), "--preset", "cpu-small",
               "--set", "train.device=cuda", "--set", "train.iterations=2", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc != 0
    errors = [ln for ln in err.strip().splitlines() if "error" in ln]   # other lines: 'dropped' notes
    assert len(errors) == 1 and "CUDA is not available" in errors[0], err




@pytest.mark.cuda
@pytest.mark.skipif(NO_CUDA, reason="needs a CUDA device")
def test_cpu_and_cuda_runs_reach_similar_psnr(tmp_path):
    """The same short run on cpu and on cuda: PSNR within 0.5 dB (backends differ in float order)."""
    from gsbench.config import load_config
    from gsbench.datasets.synthetic import make_scene
    from gsbench.runs import train_run
    from gsbench.store import read_json
    scene = make_scene("tabletop-small", tmp_path / "s", seed=0, views=10, resolution=(64, 48))
    ps = {}
    for dev in ("cpu", "cuda"):
        cfg = load_config("vanilla", "cpu-small", device_run_overrides(dev))
        run = train_run(cfg, scene, tmp_path / dev, progress=False)
        s = read_json(run / "train_summary.json")
        assert s["info"]["device"].startswith(dev)
        ps[dev] = s["last_eval"]["psnr"]
    assert abs(ps["cpu"] - ps["cuda"]) < 0.5, ps


def test_camera_device_tensors_are_cached_per_device_and_never_pickled():
    import pickle

    import numpy as np

    from gsbench.camera import Camera
    w2c = np.eye(4)
    w2c[:3, 3] = [0.5, -1.0, 2.0]
    cam = Camera(np.array([[50.0, 0, 16], [0, 50.0, 12], [0, 0, 1]]), w2c, 32, 24)
    K, v, c = cam.device_tensors("cpu")
    assert cam.device_tensors("cpu")[0] is K                     # second call: no new copy
    assert torch.equal(K, torch.tensor(cam.K, dtype=torch.float32))
    assert torch.equal(v, torch.tensor(w2c, dtype=torch.float32))
    assert np.allclose(c.numpy(), cam.center, atol=1e-6)
    assert cam.device_tensors("cpu", torch.float64)[0].dtype == torch.float64
    small = cam.resized(16, 12)
    assert float(small.device_tensors("cpu")[0][0, 0]) == 25.0   # its own K, not the parent's cache
    back = pickle.loads(pickle.dumps(cam))
    assert back._tensor_cache == {} and np.array_equal(back.K, cam.K) and back.width == 32
