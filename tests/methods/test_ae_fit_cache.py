"""The autoencoder's fit is kept in the priors cache and restored by later runs with the same features,
settings and seed: the restored fit must be the bits a new fit gives, and restoring it must not draw
from the global random generator (the field's initialisation and the training draw from it after)."""
from __future__ import annotations

import logging

import numpy as np
import torch
from tiny import TINY_SET

from gsbench.config import load_config
from gsbench.runs import train_run
from gsbench.store import read_jsonl
from gsbench.train.semantic_targets import fit_autoencoder

CFG = {"hidden": [32, 16], "epochs": 20, "lr": 1e-3}


def _features(n: int = 12, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    return {(v, t): rng.standard_normal(64).astype(np.float32) for v in range(3) for t in range(n // 3)}


def _entries(cache) -> list:
    return sorted(p.name for p in (cache / "autoencoder").iterdir() if not p.name.startswith("."))


def test_a_restored_fit_is_the_new_fits_bits_and_draws_nothing(tmp_path, caplog):
    feats, cache = _features(), tmp_path / "cache"
    torch.manual_seed(123)
    before = torch.get_rng_state()
    new, new_stats = fit_autoencoder(feats, CFG, 3, seed=7, cache_dir=cache)
    assert torch.equal(torch.get_rng_state(), before)
    with caplog.at_level(logging.INFO, logger="gsbench.train.semantic_targets"):
        kept, kept_stats = fit_autoencoder(feats, CFG, 3, seed=7, cache_dir=cache)
    assert "restored" in caplog.text
    assert torch.equal(torch.get_rng_state(), before)
    assert kept_stats == new_stats
    fresh, fresh_stats = fit_autoencoder(feats, CFG, 3, seed=7)          # no cache: a fit of its own
    assert fresh_stats == new_stats
    for k, v in fresh.state_dict().items():
        assert torch.equal(kept.state_dict()[k], v), k
    assert not kept.training and not any(p.requires_grad for p in kept.parameters())
    x = torch.from_numpy(np.stack(list(feats.values())))
    assert torch.equal(kept(x), fresh(x))
    assert len(_entries(cache)) == 1


def test_other_features_settings_or_seed_fit_anew(tmp_path):
    feats, cache = _features(), tmp_path / "cache"
    fit_autoencoder(feats, CFG, 3, seed=7, cache_dir=cache)
    fit_autoencoder(feats, CFG, 3, seed=8, cache_dir=cache)
    fit_autoencoder(feats, dict(CFG, epochs=21), 3, seed=7, cache_dir=cache)
    fit_autoencoder(feats, CFG, 4, seed=7, cache_dir=cache)
    other = dict(feats)
    other[(0, 0)] = other[(0, 0)] + np.float32(1e-3)
    fit_autoencoder(other, CFG, 3, seed=7, cache_dir=cache)
    assert len(_entries(cache)) == 5


def test_an_entry_that_does_not_hold_the_fit_is_replaced_and_said(tmp_path, caplog):
    feats, cache = _features(), tmp_path / "cache"
    new, stats = fit_autoencoder(feats, CFG, 3, seed=7, cache_dir=cache)
    entry = cache / "autoencoder" / _entries(cache)[0]
    with np.load(entry / "arrays.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays.pop(sorted(arrays)[0])                       # a weight missing: not this fit
    np.savez_compressed(entry / "arrays.npz", **arrays)
    with caplog.at_level(logging.WARNING, logger="gsbench.train.semantic_targets"):
        again, again_stats = fit_autoencoder(feats, CFG, 3, seed=7, cache_dir=cache)
    assert "replacing it with a new fit" in caplog.text and again_stats == stats
    for k, v in new.state_dict().items():
        assert torch.equal(again.state_dict()[k], v), k
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="gsbench.train.semantic_targets"):
        fit_autoencoder(feats, CFG, 3, seed=7, cache_dir=cache)        # the new fit replaced the entry
    assert "restored" in caplog.text and "replacing" not in caplog.text


def test_two_runs_sharing_the_cache_train_the_same_bits(tiny_scene, tmp_path):
    """The second run restores the first's fit; its log and parameters equal the first's."""
    cfg = load_config("gaussiands", "cpu-small", [*TINY_SET, "train.densify.until_iter=20"])
    runs = [train_run(cfg, tiny_scene, tmp_path / name, progress=False) for name in ("a", "b")]
    assert len(_entries(tmp_path / ".gsbench_cache")) == 1
    logs = [[{k: v for k, v in r.items() if k != "wall_s"} for r in read_jsonl(r / "train_log.jsonl")]
            for r in runs]
    assert logs[0] == logs[1] and len(logs[0]) >= 2
    p = [torch.load(r / "checkpoint.pt", weights_only=False)["params"] for r in runs]
    for k in p[0]:
        assert torch.equal(p[0][k], p[1][k]), k
