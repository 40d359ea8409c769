"""The harness's periodic segmentation score (gsbench/runs/training.py): evaluation's own scorer on the
eval views, in view order, with the configured query mode; nothing while the field has no semantics."""
from __future__ import annotations

from types import SimpleNamespace

import torch

from gsbench.runs import training


def _semantic_stub(has_semantics: bool = True):
    method = SimpleNamespace(autoencoder=object(), has_semantics=has_semantics, feature_provider=lambda: None)
    # Method.with_field: the method with another field, itself left as it was
    method.with_field = lambda fld: SimpleNamespace(**{**vars(method), "field": fld})
    scene = SimpleNamespace(has_semantics=True, has_labels=False)
    views = SimpleNamespace(eval_cameras={3: "cam3", 1: "cam1"})
    field = SimpleNamespace(features=torch.zeros(2, 3))
    return method, scene, views, field


def test_periodic_miou_scores_the_field_with_evaluations_code(monkeypatch):
    calls = []

    def scorer(m, scene, ids, cams, config):
        calls.append((m.field, ids, cams))
        return {"miou_3dovs": 0.25, "miou_lerf": None}, {}

    monkeypatch.setattr(training, "segmentation_metrics", scorer)
    method, scene, views, field = _semantic_stub()
    out = training._segmentation(method, scene, views, {"query": {"mode": "decode"}})(field)
    assert out == {"miou_3dovs": 0.25, "query_mode": "decode"}
    assert calls == [(field, [1, 3], ["cam1", "cam3"])]
    assert not hasattr(method, "field")      # the method itself is left as it was (a copy was scored)


def test_periodic_miou_is_empty_before_the_field_has_semantics(monkeypatch):
    monkeypatch.setattr(training, "segmentation_metrics", lambda *a: (_ for _ in ()).throw(AssertionError("called")))
    method, scene, views, field = _semantic_stub(has_semantics=False)
    assert training._segmentation(method, scene, views, {})(field) == {}


def test_no_periodic_miou_without_segmentation_ground_truth():
    method, _, views, _ = _semantic_stub()
    scene = SimpleNamespace(has_semantics=False, has_labels=False)
    assert training._segmentation(method, scene, views, {}) is None
