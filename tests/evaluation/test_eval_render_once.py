"""Evaluation renders each frame once for every protocol and query mode and scores its features a
block of pixels at a time; the metrics must equal those of the earlier flow, which rendered (and
decoded whole maps) once per protocol, frame set and mode."""
from __future__ import annotations

import pytest

TINY = ["backend=cpu", "train.iterations=12", "train.max_width=32", "train.eval_every=0", "train.log_every=4",
        "train.checkpoint_every=0", "train.eval_views=0", "train.densify.enabled=false",
        "semantic.autoencoder.epochs=5", "train.init.max_points=200", "priors.masks.provider=gt"]


class _Counting:
    """A method wrapper counting renders and decodes; `per_call` hides semantic_feature_blocks, so the
    scorer falls back to one semantic_features call (one render, one whole decoded map) per mode, as
    before."""

    def __init__(self, method, per_call: bool):
        self.m, self.renders, self.decodes, self.per_call = method, 0, 0, per_call

    def __getattr__(self, name):
        if name == "semantic_feature_blocks" and self.per_call:
            raise AttributeError(name)
        return getattr(self.m, name)

    def semantic_features(self, cam, mode):
        self.renders += 1
        self.decodes += mode == "decode"
        return self.m.semantic_features(cam, mode)

    def semantic_feature_blocks(self, cam, modes):
        self.renders += 1
        self.decodes += "decode" in modes
        return self.m.semantic_feature_blocks(cam, modes)


def _old_flow(method, scene, protocols, sets, config):
    """The flow before frames were shared: every (protocol, frame set, mode) scores on its own,
    rendering (and decoding) each of its frames again."""
    from gsbench.config_keys import QUERY_MODES
    from gsbench.evaluation.block import Block
    from gsbench.evaluation.segmentation import query_mode, score_3dovs, score_lerf
    out = Block()
    for p in protocols:
        fn = score_3dovs if p == "3dovs" else score_lerf
        for frame_set, ids in sets[p].items():
            for m in QUERY_MODES:
                out.merge(fn(method, scene, ids, config, m, query_mode(config), frame_set))
    return out


@pytest.mark.slow
def test_render_once_gives_the_same_metrics(tmp_path):
    import torch

    from gsbench.config import load_config
    from gsbench.datasets.synthetic import make_scene
    from gsbench.evaluation import evaluate_run
    from gsbench.evaluation.frames import frame_sets
    from gsbench.evaluation.segmentation import resolve_protocols, segmentation
    from gsbench.evaluation.trained_run import load_run
    from gsbench.runs import train_run
    scene_dir = make_scene("tabletop-small", tmp_path / "s", seed=0, views=8, resolution=(40, 30))
    cfg = load_config("gaussiands", "cpu-small", TINY)
    run = train_run(cfg, scene_dir, tmp_path / "run", progress=False)
    res = evaluate_run(run, progress=False)
    method, config, scene = load_run(run)
    protocols, _ = resolve_protocols(scene, "auto")
    protocols = [p for p in protocols if p in ("3dovs", "lerf")]      # the protocols that render frames
    fs = frame_sets(scene, config)
    sets = {p: fs.protocol_sets(p) for p in protocols}
    old, new = _Counting(method, per_call=True), _Counting(method, per_call=False)
    with torch.no_grad():
        ref = _old_flow(old, scene, protocols, sets, config)
        got = segmentation(new, scene, protocols, sets, config)
    assert set(protocols) == {"3dovs", "lerf"} and ref.metrics
    assert got.metrics == ref.metrics and got.per_view == ref.per_view
    # the evaluated run's results.json holds exactly these segmentation values
    for k, v in ref.metrics.items():
        assert res["metrics"][k] == v, k
    n_frames = len({i for p in protocols for ids in sets[p].values() for i in ids})
    # same camera size for both protocols here: one render (and one decode) per frame, against
    # one per protocol and mode before
    assert new.renders == new.decodes == n_frames
    assert old.renders == 2 * 2 * n_frames and old.decodes == 2 * n_frames
    _check_previews_reuse_the_scored_frames(method, new, scene, protocols, sets, config)


def _check_previews_reuse_the_scored_frames(method, counting, scene, protocols, sets, config):
    """The pictures show the scored predictions without decoding again, and those equal, bit for bit,
    the predictions of a whole decoded map (how the pictures were made before)."""
    import numpy as np

    from gsbench.evaluation.block import to_numpy
    from gsbench.evaluation.frames import segmentation_camera
    from gsbench.evaluation.labels import scene_label_masks
    from gsbench.evaluation.previews import frame_preview, preview_keys
    from gsbench.evaluation.segmentation import query_mode, segmentation_frames
    from gsbench.metrics import lerf, ovs3d
    mode = query_mode(config)
    scored = segmentation_frames(counting, scene, protocols, sets, config)
    keys = preview_keys(protocols, sets, config, mode)
    assert keys and all(k in scored for k in keys)
    for p, m, i in sorted(keys):
        cam = segmentation_camera(scene, i, p, config)
        feats = to_numpy(method.semantic_features(cam, m))
        if p == "3dovs":
            whole = ovs3d.ovs3d_predict(feats, to_numpy(method.embed_text(list(scene.class_names), m)))
            assert np.array_equal(scored[(p, m, i)], whole)
        else:
            queries = list(scene_label_masks(scene, i, cam.width, cam.height)[0])
            whole = lerf.lerf_relevancy(feats, to_numpy(method.embed_text(queries, m)),
                                        to_numpy(method.embed_text(list(lerf.CANONICAL_NEGATIVES), m)))
            assert queries and np.array_equal(scored[(p, m, i)][0], whole)
        decodes = counting.decodes
        entry, arrays = frame_preview(counting, scene, i, p, "held-out", config, mode, 320, scored)
        assert counting.decodes == decodes                       # nothing decoded again
        alone, alone_arrays = frame_preview(method, scene, i, p, "held-out", config, mode, 320)
        assert entry == alone and entry["queries"]
        assert all(np.array_equal(arrays[k], alone_arrays[k]) for k in arrays)
