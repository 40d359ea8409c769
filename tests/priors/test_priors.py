"""prepare_priors end to end: contract of the returned Priors, cache reuse, progress, input errors."""
from __future__ import annotations

import numpy as np
import pytest
from sphere_scene import make_sphere_scene

from gsbench.errors import InputError
from gsbench.metrics import ordering as MO
from gsbench.priors import DepthPrior, Priors, prepare_priors
from gsbench.priors import cache as C
from gsbench.priors import depth as D
from gsbench.priors import features as F
from gsbench.priors import segmenter as S

CFG = {"ordering": "pose", "depth": {"provider": "gt", "noise": {"type": None, "severity": 0}},
       "masks": {"provider": "simulated", "severity": 1, "propagator": "flow"},
       "features": {"provider": "text-aligned", "noise": 0.05}}


@pytest.fixture(scope="module")
def scene():
    return make_sphere_scene(4, 64, 48)


def run(scene, cache_dir, cfg=CFG, views=(0, 1, 2, 3, 4, 5), **kw):
    args = dict(need_depth=True, need_masks=True, need_features=True, seed=0, progress=False)
    args.update(kw)
    return prepare_priors(scene, cfg, list(views), (64, 48), cache_dir, **args)


def test_priors_contract(scene):
    p = run(scene, None)
    assert isinstance(p, Priors)
    views = [0, 1, 2, 3, 4, 5]
    assert sorted(p.order) == views
    assert set(p.depth) == set(views) and all(isinstance(d, DepthPrior) for d in p.depth.values())
    assert set(p.masks) == set(views)
    for m in p.masks.values():
        assert m.dtype == np.int32 and m.shape == (48, 64) and m.min() >= -1
    for (v, t), f in p.mask_features.items():
        assert v in views and np.any(p.masks[v] == t)
        assert f.shape == (512,) and f.dtype == np.float32
    # every mask of every view has a feature
    for v in views:
        for t in np.unique(p.masks[v][p.masks[v] >= 0]):
            assert (v, int(t)) in p.mask_features
    assert set(p.providers) >= {"depth", "masks", "features", "ordering"}
    assert all(isinstance(p.providers[k], str) for k in ("depth", "masks", "features", "ordering"))
    assert p.feature_provider is not None and p.feature_provider.id == p.providers["features"]
    assert p.stats["ordering_adjacent_distance"] > 0
    assert 0 <= p.stats["ordering_adjacent_mask_iou"] <= 1


def test_not_needed_parts_are_none_and_recorded(scene):
    p = run(scene, None, need_depth=False, need_masks=False, need_features=False)
    assert p.depth is None and p.masks is None and p.mask_features is None and p.feature_provider is None
    assert set(p.skipped) >= {"depth", "masks", "features"}
    assert p.providers["depth"] is None and p.providers["ordering"] == "pose"


def test_second_call_reuses_the_cache(scene, tmp_path, monkeypatch):
    first = run(scene, tmp_path)
    assert {k: v["hit"] for k, v in first.cache.items()} == {"depth": False, "masks": False, "features": False,
                                                              "mask-stats": False}
    for part in ("depth", "masks", "features", "mask-stats"):
        entry = tmp_path / part / first.cache[part]["key"]
        assert (entry / "arrays.npz").is_file() and (entry / "meta.json").is_file()
    # no temp folders left behind
    assert not [q for q in tmp_path.rglob(".*") if q.is_dir()]

    def boom(*a, **k):
        raise AssertionError("provider called although the cache has the result")

    monkeypatch.setattr(D, "compute_depth", boom)
    monkeypatch.setattr(S, "segment_view", boom)
    monkeypatch.setattr(F.TextAlignedFeatures, "encode_masks", boom)
    # the ordering statistics (optical flow and depth warps over every view pair) come from the cache too
    monkeypatch.setattr(MO, "adjacent_mask_iou_flow", boom)
    monkeypatch.setattr(MO, "adjacent_mask_iou", boom)
    second = run(scene, tmp_path)
    assert all(v["hit"] for v in second.cache.values())
    assert second.stats == first.stats and second.skipped == first.skipped
    assert second.providers == first.providers and second.order == first.order
    for v in first.depth:
        assert np.array_equal(first.depth[v].values, second.depth[v].values)
        assert np.array_equal(first.depth[v].valid, second.depth[v].valid)
        assert first.depth[v].kind == second.depth[v].kind
        assert np.array_equal(first.masks[v], second.masks[v])
    assert first.mask_features.keys() == second.mask_features.keys()
    for k in first.mask_features:
        assert np.array_equal(first.mask_features[k], second.mask_features[k])


def test_cache_key_changes_with_inputs(scene, tmp_path):
    a = run(scene, tmp_path)
    sev = {**CFG, "masks": {**CFG["masks"], "severity": 2}}
    b = run(scene, tmp_path, cfg=sev)
    assert b.cache["depth"]["hit"] and not b.cache["masks"]["hit"] and not b.cache["features"]["hit"]
    c = run(scene, tmp_path, cfg={**CFG, "ordering": "random"})
    assert c.cache["depth"]["hit"] and not c.cache["masks"]["hit"]      # propagation depends on the order
    d = run(scene, tmp_path, views=(0, 1, 2))
    assert not d.cache["depth"]["hit"]
    e = run(scene, tmp_path, seed=1)
    assert not e.cache["depth"]["hit"]
    assert len({a.cache["masks"]["key"], b.cache["masks"]["key"], c.cache["masks"]["key"]}) == 3
    other = make_sphere_scene(4, 64, 48, radius=3.2)       # different cameras and images
    f = run(other, tmp_path)
    assert not f.cache["depth"]["hit"]


def test_corrupt_cache_entry_is_recomputed(scene, tmp_path):
    a = run(scene, tmp_path, need_masks=False, need_features=False)
    entry = tmp_path / "depth" / a.cache["depth"]["key"]
    (entry / "arrays.npz").write_bytes(b"not a zip")
    b = run(scene, tmp_path, need_masks=False, need_features=False)
    assert not b.cache["depth"]["hit"]
    for v in a.depth:
        assert np.array_equal(a.depth[v].values, b.depth[v].values)
    c = run(scene, tmp_path, need_masks=False, need_features=False)
    assert c.cache["depth"]["hit"]


def test_cache_key_is_canonical():
    k1 = C.cache_key("depth", "x", 1, {"a": 1, "b": [1, 2]}, {"scene": "s"})
    k2 = C.cache_key("depth", "x", 1, {"b": [1, 2], "a": np.int64(1)}, {"scene": "s"})
    assert k1 == k2 and len(k1) == 64
    assert C.cache_key("depth", "x", 2, {"a": 1, "b": [1, 2]}, {"scene": "s"}) != k1


def test_scene_fingerprint_used_for_files(tmp_path):
    synthetic = pytest.importorskip("gsbench.datasets.synthetic")
    from gsbench.datasets import load_scene, scene_fingerprint
    root = synthetic.make_scene("tabletop-small", tmp_path / "s", seed=0, views=6, resolution=(32, 24))
    s = load_scene(root)
    assert C.scene_content_hash(s) == "fp:" + str(scene_fingerprint(root))


def test_progress_bars(scene, capsys):
    run(scene, None, progress=True)
    err = capsys.readouterr().err
    assert "priors: 100%" in err and "4/4" in err          # ordering, depth, masks, features
    assert "propagate masks" in err
    run(scene, None, progress=False)
    assert capsys.readouterr().err == ""


def test_input_errors(scene):
    with pytest.raises(InputError, match="out of range"):
        run(scene, None, views=(0, 99))
    with pytest.raises(InputError, match="duplicate"):
        run(scene, None, views=(0, 0))
    with pytest.raises(InputError, match="at least one view"):
        run(scene, None, views=())
    with pytest.raises(InputError, match="image_size"):
        prepare_priors(scene, CFG, [0], (0, 10), None, False, False, False, progress=False)


def test_single_view(scene):
    p = run(scene, None, views=(3,))
    assert p.order == [3] and p.stats["ordering_adjacent_distance"] is None
    assert p.stats["ordering_adjacent_mask_iou"] is None


@pytest.fixture(scope="module")
def tiny_scene_dir(tiny_scene):
    return tiny_scene


@pytest.mark.parametrize("flag,path,option", [
    ("priors.depth.provider=depth-anything", "priors.depth.model_path", "da-v2-small"),
    ("priors.masks.provider=sam2", "priors.masks.checkpoint", "sam2.1_hiera_tiny.pt"),
    ("priors.features.provider=openclip", "priors.features.checkpoint", "vit_b16.bin"),
])
def test_cli_missing_weights_one_line(tiny_scene_dir, tmp_path, capsys, flag, path, option):
    from gsbench.cli import main
    missing = tmp_path / "weights" / option
    rc = main(["train", "--method", "gaussiands", "--scene", str(tiny_scene_dir), "--preset", "cpu-small",
               "--set", flag, "--set", f"{path}={missing}", "--out", str(tmp_path / "run"), "--no-progress"])
    assert rc == 1
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1, lines
    assert f"{path}: {missing} not found" in lines[0] and f"--set {flag}" in lines[0]
