"""Masks from labels on real layouts: a generated scene stripped of its instance maps and of
gsbench_scene.json, so that only what a real 3D-OVS / LERF-OVS download holds is left."""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy import ndimage

from gsbench.config import load_config
from gsbench.datasets import load_scene
from gsbench.datasets.synthetic import make_scene
from gsbench.methods.registry import resolve_for_scene
from gsbench.priors import clipspace as C
from gsbench.priors import labels as L
from gsbench.priors import prepare_priors


def real_layout(out: Path, layout: str, labelled, views: int = 16, resolution=(32, 24), seed: int = 0) -> Path:
    """A generated scene as a real download looks: no instance maps, no gsbench_scene.json, and labels
    only on the views in `labelled` (3D-OVS mask folders / LERF label files of the others removed)."""
    make_scene("tabletop-small", out, seed=seed, views=views, resolution=resolution, layout=layout)
    shutil.rmtree(out / "gt")
    (out / "gsbench_scene.json").unlink()
    for i in range(views):
        if i in labelled:
            continue
        if layout == "3dovs":
            shutil.rmtree(out / "segmentations" / f"{i:03d}")
        else:
            (out / "label" / "tabletop-small" / f"frame_{i + 1:05d}.json").unlink()
    return out


EVEN = range(0, 16, 2)


@pytest.fixture(scope="module")
def ovs_scene(tmp_path_factory):
    return real_layout(tmp_path_factory.mktemp("real") / "ovs", "3dovs", EVEN)


def gaussiands_cfg(*extra):
    return load_config("gaussiands", None, ["priors.masks.provider=gt", *extra])


def test_real_layout_has_no_instances_and_gt_masks_come_from_class_masks(ovs_scene):
    s = load_scene(ovs_scene)
    assert s.layout == "3dovs" and not s.has_instances and not s.has_depth and s.has_semantics
    assert s.semantic_view_ids == list(EVEN)
    _, dropped = resolve_for_scene(gaussiands_cfg(), s)
    assert not any(k.startswith(("semantic.loss", "priors.masks", "priors.features")) for k in dropped)
    # the weight-free simulated segmenter needs instance maps: the message names them and the way out
    _, dropped = resolve_for_scene(load_config("gaussiands", None, ["priors.masks.provider=simulated"]), s)
    why = dropped["semantic.loss"]
    assert "GT instance maps" in why and "3D-OVS class masks can feed priors.masks.provider=gt" in why
    assert "no semantics in the scene" not in why


def test_label_masks_one_segment_per_class_component_none_on_unlabelled_views(ovs_scene):
    s = load_scene(ovs_scene)
    views = list(s.train_ids)
    p = prepare_priors(s, {"masks": {"provider": "gt"}, "features": {"noise": 0.0, "context": 0.0}}, views,
                       (32, 24), None, False, True, True, progress=False)
    assert p.providers["masks"] == "gt-labels:3dovs-class-components"
    labelled = [v for v in views if v % 2 == 0]
    assert p.stats["mask_labelled_views"] == len(labelled)
    text = np.stack([C.text_vector(c) for c in s.class_names])
    for v in views:
        seg = p.masks[v]
        if v not in labelled:
            assert (seg == -1).all() and not any(k[0] == v for k in p.mask_features)
            continue
        masks = s.gt_class_masks(v)
        n_expected = 0
        for k, c in enumerate(s.class_names):
            only = masks[c] & (sum(masks[o].astype(int) for o in s.class_names) == 1)
            _, n = ndimage.label(only, structure=np.ones((3, 3)))   # 8-connected components (scipy)
            n_expected += n
            ids = np.unique(seg[only])
            assert len(ids) == n and all(i // L.COMPONENT_STRIDE == k for i in ids)
        assert len(np.unique(seg[seg >= 0])) == n_expected
        # each segment's feature is named by its class: its nearest class text is its own class
        for t in np.unique(seg[seg >= 0]):
            f = p.mask_features[(v, int(t))]
            assert s.class_names[int(np.argmax(text @ f))] == s.class_names[int(t) // L.COMPONENT_STRIDE]


def test_unlabelled_views_get_no_semantic_target(ovs_scene):
    """The trainer's L_sem / L_ds average over `has_target` and are skipped for a view without any
    (methods/gaussiands, methods/twostage): an unlabelled view must have no target pixel."""
    from gsbench.train.semantic_targets import build_targets, fit_autoencoder
    s = load_scene(ovs_scene)
    views = [1, 2, 3]
    p = prepare_priors(s, {"masks": {"provider": "gt"}}, views, (32, 24), None, False, True, True, progress=False)
    ae, _ = fit_autoencoder(p.mask_features, {"epochs": 2, "hidden": (16,)}, 3, 0)
    t = build_targets(p.masks, p.mask_features, ae, {v: (32, 24) for v in views})
    assert not t.has_target[1].any() and not t.has_target[3].any()
    assert np.array_equal(t.has_target[2].numpy(), p.masks[2] >= 0) and t.has_target[2].any()


def test_components_split_one_class_into_two_segments_largest_first():
    cls = np.full((6, 8), -1, np.int32)
    cls[0:2, 0:2] = 1          # 4 px
    cls[3:6, 4:8] = 1          # 12 px, not touching the first (not even diagonally)
    cls[5, 0] = 0
    seg = L._components(cls, 2)
    assert seg[0, 0] == 1 * L.COMPONENT_STRIDE + 1 and seg[4, 5] == 1 * L.COMPONENT_STRIDE + 0
    assert seg[5, 0] == 0 and (seg[cls < 0] == -1).all()


def test_lerf_labels_one_segment_per_object_named_by_category(tmp_path):
    root = real_layout(tmp_path / "lerf", "lerf", EVEN)
    s = load_scene(root)
    assert s.layout == "lerf" and not s.has_semantics and not s.has_instances and s.label_view_ids == list(EVEN)
    _, dropped = resolve_for_scene(gaussiands_cfg(), s)
    assert "semantic.loss" not in dropped
    v = 2
    lv = L.label_view(s, v, (32, 24))
    objs = s.gt_labels(v)
    assert lv.names == s.queries
    # every object that keeps a pixel is one segment, of its own category
    for t in np.unique(lv.segments[lv.segments >= 0]):
        cat = lv.names[int(t) // L.COMPONENT_STRIDE]
        assert (lv.classes[lv.segments == t] == lv.names.index(cat)).all()
    assert len(np.unique(lv.segments[lv.segments >= 0])) <= len(objs)
    # a category's pixels are the union of its polygons (cv2.fillPoly, the protocol's rasteriser)
    for cat in {o.category for o in objs}:
        m = np.zeros((24, 32), np.uint8)
        for o in objs:
            if o.category == cat:
                for poly in o.polygons:
                    cv2.fillPoly(m, [np.asarray(poly).astype(np.int32).reshape(-1, 1, 2)], 1)
        assert np.array_equal(lv.classes == lv.names.index(cat), m.astype(bool))
    assert L.label_view(s, 1, (32, 24)) is None
    p = prepare_priors(s, {"masks": {"provider": "gt"}, "features": {"noise": 0.0, "context": 0.0}}, [1, 2],
                       (32, 24), None, False, True, True, progress=False)
    assert p.providers["masks"] == "gt-labels:lerf-label-objects" and (p.masks[1] == -1).all()
    text = np.stack([C.text_vector(c) for c in s.queries])
    for (view, t), f in p.mask_features.items():
        assert view == 2 and s.queries[int(np.argmax(text @ f))] == s.queries[t // L.COMPONENT_STRIDE]


def test_resolver_names_what_the_scene_lacks(tmp_path):
    # labels only on held-out views (0 and 8 are the every-8th test views)
    root = real_layout(tmp_path / "held", "3dovs", [0, 8], views=16)
    _, dropped = resolve_for_scene(gaussiands_cfg(), load_scene(root))
    assert "none of them trained on" in dropped["semantic.loss"]
    # with every view trained on, the same labels feed the loss
    _, dropped = resolve_for_scene(gaussiands_cfg("train.holdout=none"), load_scene(root))
    assert "semantic.loss" not in dropped
    # no labels at all
    shutil.rmtree(root / "segmentations")
    _, dropped = resolve_for_scene(gaussiands_cfg(), load_scene(root))
    why = dropped["semantic.loss"]
    assert "GT instance maps, 3D-OVS class masks or LERF-OVS labels" in why and "no semantics in the scene" in why


def test_edited_label_changes_the_masks_cache_key(ovs_scene, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(ovs_scene, root)
    before = L.label_digest(load_scene(root), [2, 4])
    assert L.label_digest(load_scene(root), [2, 4]) == before
    f = root / "segmentations" / "002" / "floor.png"
    m = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
    assert m[-4:].any()
    m[-4:] = 0
    cv2.imwrite(str(f), m)
    assert L.label_digest(load_scene(root), [2, 4]) != before


def constant_predictor_miou(scene, views) -> float:
    """The best mIoU of a field that predicts one class everywhere: IoU = the class's pixel share for
    that class, 0 for every other (3D-OVS: empty prediction and non-empty GT give 0; both empty, 0)."""
    c = len(scene.class_names)
    best = 0.0
    for name in scene.class_names:
        shares = [scene.gt_class_masks(v)[name].mean() for v in views]
        best = max(best, float(np.mean(shares)) / c)
    return best


@pytest.mark.slow
def test_gaussiands_lifts_class_masks_to_held_out_views(tmp_path):
    """Oracle masks from 3D-OVS class masks on every 2nd view, no instance maps: GaussianDS (cpu-small,
    200 iterations) segments the two held-out labelled views far better than a constant predictor."""
    from gsbench.evaluation import evaluate_run
    from gsbench.runs import train_run
    from gsbench.store import read_json, read_jsonl
    root = real_layout(tmp_path / "ovs", "3dovs", EVEN, resolution=(48, 36))
    # a real capture is scored at the 3D-OVS reference's 1/8 by default; this one is 48x36 already, so 1
    cfg = load_config("gaussiands", "cpu-small", ["priors.masks.provider=gt", "train.iterations=200",
                                                  "train.eval_every=0", "eval.ovs3d_downsample=1"])
    run = train_run(cfg, root, tmp_path / "run", progress=False)
    res = evaluate_run(run, progress=False)
    scene = load_scene(root)
    assert res["frames"]["3dovs/held-out"] == ["frame_00001.png", "frame_00009.png"]
    assert res["providers"]["masks"] == "gt-labels:3dovs-class-components"
    chance = constant_predictor_miou(scene, [0, 8])
    m = res["metrics"]
    # measured (loaded 2-core machine): held-out mIoU 0.50 decode / 0.26 encode at seed 0 (decode 0.35 and
    # 0.42 at seeds 1 and 2); the constant predictor scores 0.075 on these two views
    assert 0.05 < chance < 0.1
    assert m["miou_3dovs_decode_heldout"] > 3 * chance and m["miou_3dovs_encode_heldout"] > 2 * chance
    # 14 training views, 8 of them unlabelled; 200 steps = 14 full passes (112 unlabelled steps) + 4 more
    skipped = sum(r.get("skipped", {}).get("sem", 0) for r in read_jsonl(run / "train_log.jsonl") if "loss" in r)
    assert 112 <= skipped <= 116
    assert read_json(run / "train_summary.json")["dropped"].get("semantic.loss") is None


@pytest.mark.slow
def test_gaussiands_lifts_lerf_labels_to_held_out_views(tmp_path):
    """The same with LERF-OVS label polygons on every 2nd view (one segment per label object)."""
    from gsbench.datasets.ovs import label_masks
    from gsbench.evaluation import evaluate_run
    from gsbench.runs import train_run
    root = real_layout(tmp_path / "lerf", "lerf", EVEN, resolution=(48, 36))
    cfg = load_config("gaussiands", "cpu-small", ["priors.masks.provider=gt", "train.iterations=200",
                                                  "train.eval_every=0"])
    res = evaluate_run(train_run(cfg, root, tmp_path / "run", progress=False), progress=False)
    assert res["providers"]["masks"] == "gt-labels:lerf-label-objects"
    assert res["frames"]["lerf/held-out"] == ["frame_00001.png", "frame_00009.png"]
    # a predictor that selects the whole image scores each pair's GT share of the image
    s = load_scene(root)
    whole = np.mean([m.mean() for v in (0, 8) for m in label_masks(s.raw_labels[v], 36, 48).values()])
    m = res["metrics"]
    # measured (loaded 2-core machine, seed 0): held-out decode mIoU 0.59, localisation 0.83; whole image 0.028
    assert 0.01 < whole < 0.05
    assert m["miou_lerf_decode_heldout"] > 5 * whole and m["loc_acc_lerf_decode_heldout"] >= 0.5
