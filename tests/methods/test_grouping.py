"""The Gaussian Grouping-style baseline: its identity loss and 3D regulariser against hand computations,
query routing through the tracks' features, and a tiny train + eval with the metrics present."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from gsbench.cli import main
from gsbench.config import load_config
from gsbench.gaussians import GaussianField
from gsbench.methods.grouping import (
    GaussianGrouping,
    class_map,
    identity_loss,
    neighbour_kl,
    track_classes,
    track_table,
)
from gsbench.runs.training import train_method
from gsbench.store import load_torch, read_json, read_jsonl


def test_identity_loss_is_cross_entropy_over_log_classes():
    # pixel 1: equal logits, target 0 -> CE = ln 3; pixel 2: logits (ln 4, 0, 0), target 0 -> p = 4/6, CE = ln 1.5
    logits = torch.tensor([[0.0, 0.0, 0.0], [math.log(4.0), 0.0, 0.0]])
    target = torch.tensor([0, 0])
    want = (math.log(3.0) + math.log(1.5)) / 2 / math.log(3.0)        # = 0.684535...
    assert float(identity_loss(logits, target)) == pytest.approx(want, rel=1e-6)
    assert want == pytest.approx(0.6845351, abs=1e-6)
    # a confident right answer costs nearly nothing, a confident wrong one a lot
    assert float(identity_loss(torch.tensor([[20.0, 0.0, 0.0]]), torch.tensor([0]))) < 1e-6
    assert float(identity_loss(torch.tensor([[20.0, 0.0, 0.0]]), torch.tensor([1]))) == pytest.approx(
        20.0 / math.log(3.0), rel=1e-6)


def test_neighbour_kl_matches_a_float64_hand_computation():
    means = torch.tensor([[0.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0], [3.5, 0, 0]])
    p = np.array([[0.7, 0.2, 0.1], [0.1, 0.8, 0.1], [0.3, 0.3, 0.4], [0.6, 0.3, 0.1]], dtype=np.float64)
    # k = 2 nearest by position, the point itself included: 0 -> {0, 1}; 3 -> {3, 2}
    nbrs = {0: (0, 1), 3: (3, 2)}
    kl = []
    for s, js in nbrs.items():
        for j in js:
            kl.append(sum(p[s, c] * (math.log(p[s, c] + 1e-10) - math.log(p[j, c] + 1e-10)) for c in range(3)))
    want = float(np.mean(kl)) / 3.0
    got = neighbour_kl(means, torch.tensor(p, dtype=torch.float32), 2, torch.tensor([0, 3]))
    assert float(got) == pytest.approx(want, rel=1e-5)
    assert want > 0.01                                          # the case is not trivially zero
    # identical distributions everywhere: no penalty
    same = torch.tensor([[0.5, 0.25, 0.25]] * 4)
    assert float(neighbour_kl(means, same, 3, torch.arange(4))) == pytest.approx(0.0, abs=1e-7)


def test_tracks_become_classes_and_too_many_is_an_error():
    masks = {0: np.array([[5, 5], [-1, 9]]), 1: np.array([[9, -1], [2, 2]])}
    tracks, c = track_classes(masks, 4)
    assert tracks == [2, 5, 9] and c == 4
    assert track_classes(masks, None) == ([2, 5, 9], 4)          # null: one class per track + no mask
    assert class_map(masks[0], tracks).tolist() == [[2, 2], [0, 3]]
    from gsbench.errors import InputError
    with pytest.raises(InputError, match="3 tracks but grouping.num_classes=3"):
        track_classes(masks, 3)
    # a track's feature: the renormalised mean of its views' features; unowned rows are zero
    feats = {(0, 5): np.array([1.0, 0.0]), (1, 5): np.array([0.0, 1.0]), (0, 9): np.array([0.0, 2.0])}
    t = track_table(feats, tracks, 5, 2).numpy()
    assert t[2] == pytest.approx([math.sqrt(0.5), math.sqrt(0.5)], abs=1e-6)
    assert t[3] == pytest.approx([0.0, 1.0]) and not t[[0, 1, 4]].any()


def _hand_made(names):
    """Two tracks whose features are the text vectors of `names`, a classifier mapping identity e1 -> class 1,
    e2 -> class 2 and 0 -> class 0 (no mask), and two Gaussians with identities e1 and e2."""
    m = GaussianGrouping()
    m.config = load_config("grouping", "cpu-small")
    m.classifier = torch.nn.Linear(2, 3)
    with torch.no_grad():
        m.classifier.weight.copy_(torch.tensor([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]]))
        m.classifier.bias.copy_(torch.tensor([1.0, 0.0, 0.0]))
    text = torch.as_tensor(np.asarray(m.feature_provider().encode_text(names), dtype=np.float32))
    m.table = torch.cat([torch.zeros(1, text.shape[1]), text / text.norm(dim=1, keepdim=True)])
    m.tracks = [10, 20]
    n = 2
    m.field = GaussianField(torch.zeros(n, 3), torch.zeros(n, 3), torch.tensor([[1.0, 0, 0, 0]] * n),
                            torch.zeros(n), torch.zeros(n, 3), torch.tensor([[1.0, 0.0], [0.0, 1.0]]))
    return m


def test_queries_route_through_the_matching_track(monkeypatch):
    from gsbench.metrics.ovs3d import ovs3d_predict
    m = _hand_made(["ball", "globe"])
    ident = torch.zeros(2, 4, 2)
    ident[:, :2, 0] = 1.0        # left: track 10 (ball)
    ident[:, 2:, 1] = 1.0        # right: track 20 (globe)
    ident[0, 0] = 0.0            # one pixel with no identity: class 0, zero feature
    monkeypatch.setattr(m, "render", lambda cam: SimpleNamespace(features=ident))
    for mode in ("encode", "decode"):
        feats = m.semantic_features(None, mode)
        assert feats.shape == (2, 4, m.table.shape[1])
        assert float(feats[0, 0].abs().sum()) == 0.0
        pred = ovs3d_predict(feats.numpy(), m.embed_text(["ball", "globe"], mode).numpy())
        assert pred[:, 2:].tolist() == [[1, 1], [1, 1]] and pred[1, :2].tolist() == [0, 0]
    assert m.query_classes("ball") == [1] and m.query_classes("globe") == [2]
    # removal takes the Gaussians classified into the query's track (class probability > 0.3)
    kept, n = m.remove("globe")
    assert n == 1 and kept.field.features.tolist() == [[1.0, 0.0]]
    kept, n = m.remove("ball")
    assert n == 1 and kept.field.features.tolist() == [[0.0, 1.0]]


def test_grouping_trains_on_the_tiny_scene_and_evaluates(tiny_scene, tmp_path):
    run = tmp_path / "grouping"
    assert main(["train", "--method", "grouping", "--scene", str(tiny_scene), "--preset", "cpu-small",
                 "--set", "train.iterations=6", "--set", "train.eval_every=3", "--set", "train.log_every=2",
                 "--set", "grouping.reg3d.interval=2", "--set", "train.checkpoint_every=0",
                 "--no-progress", "--out", str(run)]) == 0
    log = list(read_jsonl(run / "train_log.jsonl"))
    losses = [r["loss"] for r in log if "loss" in r]
    assert all("identity" in x and "reg3d" in x for x in losses)      # every log window holds a step 2, 4, 6
    assert all(x["identity"] > 0 for x in losses)
    evals = [r["eval"] for r in log if "eval" in r]
    assert evals and all("miou_3dovs" in e and "miou_lerf" in e for e in evals)
    info = read_json(run / "train_summary.json")["info"]
    assert info["budget"] == {"rgb_steps": 6, "semantic_steps": 6, "schedule": "joint"}
    assert info["num_classes"] == info["tracks"] + 1 >= 2      # cpu-small: num_classes null
    assert main(["eval", str(run)]) == 0
    res = read_json(run / "results.json")
    for k in ("psnr", "miou_3dovs", "mbiou_3dovs", "miou_lerf", "removal_residual"):
        assert res["metrics"][k] is not None, k
    assert res["budget"] == {"rgb_steps": 6, "semantic_steps": 6, "schedule": "joint"}
    # the saved model carries the trained classifier (the checkpoint's copy) and the track table
    from gsbench.methods.base import Method
    m = Method.load(run / "model.pt", device="cpu")
    assert isinstance(m, GaussianGrouping) and m.has_semantics and m.table.shape[0] == info["num_classes"]
    ck = load_torch(run / "checkpoint.pt")["extra"]["classifier"]
    assert torch.equal(m.classifier.weight, ck["weight"])


def test_grouping_without_semantics_in_the_scene_is_rgb_only():
    from gsbench.methods.registry import resolve_for_scene

    class NoSem:
        path = "S"
        has_instances = has_semantics = has_labels = False
        has_depth = has_points = True
        instance_classes = class_names = None
        layout = "3dovs"
    cfg, dropped = resolve_for_scene(load_config("grouping"), NoSem())
    assert cfg["grouping"]["losses"] == {"identity": False, "reg3d": False}
    assert "grouping.losses.identity" in dropped and "priors.masks" in dropped and "priors.depth" in dropped


def test_a_resumed_run_ends_where_a_straight_one_does(tiny_scene, tmp_path):
    """The classifier, its Adam state and the 3D regulariser's sampler are checkpointed with the field."""
    from gsbench.datasets import load_scene
    from gsbench.methods.registry import resolve_for_scene
    scene = load_scene(tiny_scene)
    base = ["backend=torch", "train.eval_every=0", "train.checkpoint_every=0", "train.densify.enabled=false",
            "grouping.reg3d.interval=2", "grouping.reg3d.sample_size=50", f"priors.cache_dir={tmp_path / 'c'}"]

    def fit(run, iters):
        cfg, _ = resolve_for_scene(load_config("grouping", "cpu-small", base + [f"train.iterations={iters}"]), scene)
        m = GaussianGrouping()
        train_method(m, scene, run, cfg, progress=False)
        return m
    run_a, run_b = tmp_path / "a", tmp_path / "b"
    run_a.mkdir()
    run_b.mkdir()
    straight = fit(run_a, 6)
    mid = fit(run_b, 3).classifier.weight.clone()     # stops at step 3 with its checkpoint
    resumed = fit(run_b, 6)                           # picks the checkpoint up and runs steps 4..6
    assert not torch.allclose(mid, straight.classifier.weight)    # steps 4..6 did change the classifier
    assert torch.allclose(resumed.field.features, straight.field.features, atol=1e-6)
    assert torch.allclose(resumed.classifier.weight, straight.classifier.weight, atol=1e-6)
