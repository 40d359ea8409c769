"""Real prior providers with tiny randomly initialised models built offline (the `models` extra).

Run in the separate venv: `bash scripts/test_models.sh`. In the main .venv these tests skip
(transformers / open_clip / sam2 are not installed there, on purpose: they pull torchvision).
Random weights give meaningless outputs: the tests check the plumbing (local loading, shapes,
kinds, ids, cache, crops fed to the model, mask propagation over the ordered frames), not quality.
"""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest

pytestmark = pytest.mark.models

from sphere_scene import make_sphere_scene  # noqa: E402

from gsbench.errors import InputError  # noqa: E402
from gsbench.priors import features as F  # noqa: E402
from gsbench.priors import get_feature_provider, prepare_priors  # noqa: E402


# ------------------------------------------------------------------------------ Depth Anything
@pytest.fixture(scope="module")
def tiny_depth_anything(tmp_path_factory):
    pytest.importorskip("torchvision")
    transformers = pytest.importorskip("transformers")
    import torch
    torch.manual_seed(0)
    backbone = transformers.Dinov2Config(image_size=56, patch_size=14, hidden_size=32, num_hidden_layers=4,
                                         num_attention_heads=2, intermediate_size=64, out_indices=[1, 2, 3, 4],
                                         apply_layernorm=True, reshape_hidden_states=False)
    cfg = transformers.DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=32,
                                           neck_hidden_sizes=[8, 16, 32, 32], fusion_hidden_size=16,
                                           head_hidden_size=8, patch_size=14)
    model = transformers.DepthAnythingForDepthEstimation(cfg).eval()
    folder = tmp_path_factory.mktemp("weights") / "depth-anything-tiny"
    model.save_pretrained(folder)
    transformers.DPTImageProcessor(do_resize=True, size={"height": 56, "width": 56}, keep_aspect_ratio=True,
                                   ensure_multiple_of=14, do_pad=False).save_pretrained(folder)
    return folder, model


def test_depth_anything_from_local_folder(tiny_depth_anything, tmp_path):
    import torch
    import transformers
    folder, model = tiny_depth_anything
    scene = make_sphere_scene(2, 48, 36)
    cfg = {"depth": {"provider": "depth-anything", "model_path": str(folder)}}
    p = prepare_priors(scene, cfg, [0, 1], (40, 30), tmp_path, True, False, False, progress=False)
    assert p.providers["depth"] == "depth-anything:depth-anything-tiny"
    for v in (0, 1):
        d = p.depth[v]
        assert d.kind == "disparity" and d.values.shape == (30, 40) and np.isfinite(d.values).all()
        assert d.valid.all()
    # reference: the same tiny model run by hand through its processor, resized to (30, 40), on the
    # device the provider picks (CUDA where present: its TF32 convolutions differ from the CPU's ~1e-3)
    dev = "cuda" if torch.cuda.is_available() else "cpu"
    proc = transformers.AutoImageProcessor.from_pretrained(folder, local_files_only=True)
    u8 = np.clip(np.rint(scene.image(1) * 255), 0, 255).astype(np.uint8)
    with torch.no_grad():
        inputs = {k: v.to(dev) for k, v in proc(images=u8, return_tensors="pt").items()}
        ref = copy.deepcopy(model).to(dev)(**inputs).predicted_depth
        ref = torch.nn.functional.interpolate(ref[:, None], size=(30, 40), mode="bicubic", align_corners=False)[0, 0]
        ref = ref.cpu()
    assert np.allclose(p.depth[1].values, ref.numpy(), rtol=1e-4, atol=1e-6 * float(ref.abs().max() + 1e-12))
    q = prepare_priors(scene, cfg, [0, 1], (40, 30), tmp_path, True, False, False, progress=False)
    assert q.cache["depth"]["hit"]


def test_depth_anything_bad_folder(tmp_path):
    pytest.importorskip("transformers")
    empty = tmp_path / "empty-model"
    empty.mkdir()
    scene = make_sphere_scene(2, 16, 12)
    with pytest.raises(InputError) as e:
        prepare_priors(scene, {"depth": {"provider": "depth-anything", "model_path": str(empty)}}, [0], (16, 12),
                       None, True, False, False, progress=False)
    assert "priors.depth.model_path" in str(e.value) and str(empty) in str(e.value)


# ------------------------------------------------------------------------------ OpenCLIP
@pytest.fixture(scope="module")
def tiny_openclip(tmp_path_factory):
    pytest.importorskip("torchvision")
    open_clip = pytest.importorskip("open_clip")
    import torch
    d = tmp_path_factory.mktemp("openclip")
    cfg = {"embed_dim": 512,
           "vision_cfg": {"image_size": 32, "layers": 2, "width": 64, "patch_size": 16, "head_width": 32},
           "text_cfg": {"context_length": 77, "vocab_size": 49408, "width": 64, "heads": 2, "layers": 2}}
    (d / "gsbench-tiny-clip.json").write_text(json.dumps(cfg))
    open_clip.add_model_config(d)
    torch.manual_seed(0)
    model = open_clip.create_model("gsbench-tiny-clip").eval()
    ckpt = d / "tiny_clip.pt"
    torch.save({"state_dict": model.state_dict()}, ckpt)
    return ckpt, model


def test_openclip_text_and_masked_crops(tiny_openclip):
    import open_clip
    import torch
    from PIL import Image
    ckpt, model = tiny_openclip
    fp = get_feature_provider({"provider": "openclip", "checkpoint": str(ckpt), "model": "gsbench-tiny-clip"})
    assert fp.id == "openclip:gsbench-tiny-clip:tiny_clip.pt"
    assert fp.canonical_negatives == ("object", "things", "stuff", "texture")
    t = fp.encode_text(["a red ball", "table"] + list(fp.canonical_negatives))
    assert t.shape == (6, 512) and np.allclose(np.linalg.norm(t, axis=1), 1, atol=1e-5)
    tok = open_clip.get_tokenizer("gsbench-tiny-clip")
    with torch.no_grad():
        ref = model.encode_text(tok(["a red ball"])).numpy()[0]
    assert np.allclose(t[0], ref / np.linalg.norm(ref), atol=1e-5)

    scene = make_sphere_scene(1, 64, 48)
    img, labels = scene.image(0), scene.gt_instances(0)
    feats = fp.encode_masks(scene, 0, img, labels)
    assert set(feats) == {int(i) for i in np.unique(labels[labels >= 0])}
    # reference crop for instance 0 built by hand: black background, bbox, pad to square
    m = labels == 0
    ys, xs = np.nonzero(m)
    crop = (img * m[..., None])[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    h, w = crop.shape[:2]
    s = max(h, w)
    sq = np.zeros((s, s, 3), np.float32)
    sq[(s - h) // 2:(s - h) // 2 + h, (s - w) // 2:(s - w) // 2 + w] = crop
    _, _, pre = open_clip.create_model_and_transforms("gsbench-tiny-clip", pretrained=str(ckpt))
    x = pre(Image.fromarray(np.clip(np.rint(sq * 255), 0, 255).astype(np.uint8)))[None]
    with torch.no_grad():
        r = model.encode_image(x).numpy()[0]
    assert np.allclose(feats[0], r / np.linalg.norm(r), atol=1e-4)


def test_openclip_through_prepare_priors(tiny_openclip, tmp_path):
    ckpt, _ = tiny_openclip
    scene = make_sphere_scene(2, 48, 36)
    cfg = {"masks": {"provider": "gt"},
           "features": {"provider": "openclip", "checkpoint": str(ckpt), "model": "gsbench-tiny-clip"}}
    p = prepare_priors(scene, cfg, [0, 1], (48, 36), tmp_path, False, True, True, progress=False)
    assert p.providers["features"].startswith("openclip:")
    assert all(f.shape == (512,) for f in p.mask_features.values())
    q = prepare_priors(scene, cfg, [0, 1], (48, 36), tmp_path, False, True, True, progress=False)
    assert q.cache["features"]["hit"]


def test_openclip_corrupt_checkpoint(tmp_path):
    pytest.importorskip("open_clip")
    bad = tmp_path / "broken.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError) as e:
        F.OpenClipFeatures(str(bad), model="ViT-B-16")
    assert "priors.features.checkpoint" in str(e.value) and str(bad) in str(e.value)


# ------------------------------------------------------------------------------ SAM2
SAM2_OVERRIDES = ["++model.image_size=256", "++model.image_encoder.trunk.stages=[1,1,2,1]",
                  "++model.image_encoder.trunk.global_att_blocks=[3]", "++model.memory_attention.num_layers=1",
                  "++model.memory_attention.layer.self_attention.feat_sizes=[16,16]",
                  "++model.memory_attention.layer.cross_attention.feat_sizes=[16,16]",
                  "++model.memory_attention.layer.dim_feedforward=256"]
SAM2_CONFIG = "configs/sam2.1/sam2.1_hiera_t.yaml"


@pytest.fixture(scope="module")
def tiny_sam2(tmp_path_factory):
    pytest.importorskip("torchvision")
    pytest.importorskip("sam2")
    import torch
    from sam2.build_sam import build_sam2_video_predictor
    torch.manual_seed(0)
    model = build_sam2_video_predictor(SAM2_CONFIG, None, device="cpu", hydra_overrides_extra=SAM2_OVERRIDES)
    ckpt = tmp_path_factory.mktemp("sam2") / "sam2_tiny_random.pt"
    torch.save({"model": model.state_dict()}, ckpt)
    return ckpt


def sam2_cfg(ckpt):
    return {"provider": "sam2", "checkpoint": str(ckpt), "model_config": SAM2_CONFIG,
            "model_overrides": SAM2_OVERRIDES,
            "generator": {"points_per_side": 4, "pred_iou_thresh": 0.0, "stability_score_thresh": 0.0,
                          "box_nms_thresh": 0.99}}


def test_sam2_video_propagation_over_ordered_frames(tiny_sam2, monkeypatch):
    from gsbench.priors import masks as M
    sam = M.Sam2Masks(sam2_cfg(tiny_sam2))
    assert sam.id == "sam2:sam2_tiny_random.pt:sam2.1_hiera_t"
    scene = make_sphere_scene(2, 32, 24)
    order = [2, 0, 1]
    images = {v: scene.image(v) for v in order}
    first = np.full((24, 32), -1, np.int32)
    first[4:14, 4:20] = 0
    first[14:, :] = 1
    monkeypatch.setattr(sam, "automatic", lambda img: first.copy())
    out = sam.propagate(order, images)
    assert set(out) == set(order)
    for v in order:
        assert out[v].dtype == np.int32 and out[v].shape == (24, 32)
        assert set(np.unique(out[v])) <= {-1, 0, 1}


def test_sam2_automatic_masks_through_prepare_priors(tiny_sam2, tmp_path):
    scene = make_sphere_scene(2, 32, 24)
    cfg = {"masks": sam2_cfg(tiny_sam2)}
    p = prepare_priors(scene, cfg, [0, 1], (32, 24), tmp_path, False, True, False, per_frame_masks=True,
                       progress=False)
    assert p.providers["masks"].endswith("+per-frame")
    for v in (0, 1):
        assert p.masks[v].shape == (24, 32) and p.masks[v].dtype == np.int32
    q = prepare_priors(scene, cfg, [0, 1], (32, 24), tmp_path, False, True, False, per_frame_masks=True,
                       progress=False)
    assert q.cache["masks"]["hit"]


def test_sam2_bad_checkpoint(tmp_path):
    pytest.importorskip("sam2")
    from gsbench.priors import masks as M
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"nope")
    with pytest.raises(InputError) as e:
        M.Sam2Masks({"checkpoint": str(bad), "model_config": SAM2_CONFIG})
    assert str(bad) in str(e.value)
