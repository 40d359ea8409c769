"""gsbench.evaluation and gsbench.results: frame sets, named rules, ids, the results contract.
Each test fails on the pre-package behaviour it replaces (named in its docstring)."""
from __future__ import annotations

import math
import zlib

import numpy as np
import pytest
from tiny import TINY_SET

from gsbench.errors import InputError


@pytest.fixture(scope="module")
def lerf_scene(tmp_path_factory):
    from gsbench.datasets import load_scene
    from gsbench.datasets.synthetic import make_scene
    out = make_scene("tabletop-small", tmp_path_factory.mktemp("s") / "t", seed=0, views=17, resolution=(64, 48),
                     layout="lerf")
    return load_scene(out)


def _cfg(**train):
    return {"train": {"max_width": None, **train}, "eval": {}}


def test_frame_sets_cover_every_label_file(lerf_scene):
    """reference + held-out = every label file (the old evaluation scored only labelled test views)."""
    from gsbench.evaluation import frame_sets
    n_files = len(list((lerf_scene.meta and __import__("pathlib").Path(lerf_scene.meta["label_dir"])).glob("*.json")))
    fs = frame_sets(lerf_scene, _cfg())
    sets = fs.protocol_sets("lerf")
    assert n_files == 17
    assert len(sets["reference"]) + len(sets["held-out"]) == n_files
    assert set(sets["reference"]).isdisjoint(sets["held-out"])
    assert sets["held-out"] == [0, 8, 16]                 # the every-8th hold-out
    assert fs.reconstruction == [0, 8, 16]


def test_holdout_none_trains_on_every_view(lerf_scene):
    """train.holdout: none -> every labelled frame is a reference frame, nothing is held out."""
    from gsbench.datasets.splits import split_ids
    from gsbench.evaluation import frame_sets
    trained, held = split_ids(lerf_scene, _cfg(holdout="none"))
    assert trained == list(range(17)) and held == []
    fs = frame_sets(lerf_scene, _cfg(holdout="none"))
    assert fs.protocol_sets("lerf") == {"reference": list(range(17)), "held-out": []}
    with pytest.raises(InputError, match="train.holdout"):
        split_ids(lerf_scene, _cfg(holdout="every-7"))


def test_image_metrics_skip_with_reason_without_held_out_views(lerf_scene):
    from gsbench.evaluation.image import image_metrics
    b = image_metrics(None, lerf_scene, [], [], _cfg())
    assert b.metrics == {"psnr": None, "ssim": None, "ssim_valid": None, "lpips": None, "lpips_package": None}
    assert all("holdout" in b.skipped[k] for k in b.metrics)


def test_lerf_is_scored_at_label_resolution(lerf_scene):
    """eval.resolution reference: the LERF camera has the label file's size, not train.max_width's."""
    from gsbench.evaluation.frames import segmentation_camera
    cfg = {"train": {"max_width": 32}, "eval": {}}
    cam = segmentation_camera(lerf_scene, 3, "lerf", cfg)
    assert (cam.width, cam.height) == lerf_scene.label_sizes[3] == (64, 48)
    cfg["eval"]["resolution"] = "train"
    cam = segmentation_camera(lerf_scene, 3, "lerf", cfg)
    assert (cam.width, cam.height) == (32, 24)


def test_resize_nearest_samples_pixel_centres():
    """Centre sampling: target pixel j reads source floor((j + 0.5) * src / dst) (PIL NEAREST);
    cv2.INTER_NEAREST (the old rule) reads floor(j * src / dst)."""
    from gsbench.metrics import resize_nearest
    src = np.arange(8 * 6, dtype=np.int32).reshape(6, 8)
    out = resize_nearest(src, 2, 3)
    rows = np.floor((np.arange(3) + 0.5) * 6 / 3).astype(int)
    cols = np.floor((np.arange(2) + 0.5) * 8 / 2).astype(int)
    np.testing.assert_array_equal(out, src[np.ix_(rows, cols)])
    m = resize_nearest(src % 2 == 0, 4, 3)
    assert m.dtype == bool and m.shape == (3, 4)


def test_pixel_accuracy_rules_by_hand():
    """reference = exact one-hot match over all pixels; labelled = GT-covered pixels, overlaps right for
    either class (the old code had only the second, under the reference's name)."""
    from gsbench.metrics import pixel_accuracy
    gt = np.zeros((2, 2, 3), bool)
    gt[0, 0, 0] = True             # class 0 only
    gt[0, 0, 1] = gt[1, 0, 1] = True   # pixel (0,1): classes 0 and 1 overlap
    gt[1, 1, 1] = True             # class 1 only at (1,1); pixels (0,2), (1,0), (1,2) unlabelled
    pred = np.array([[0, 1, 0], [0, 1, -1]])
    # reference: (0,0) right, (0,1) overlap -> wrong, (0,2) unlabelled vs class 0 -> wrong,
    #            (1,0) GT none vs 0 -> wrong, (1,1) right, (1,2) none vs none -> right  => 3 / 6
    assert pixel_accuracy(pred, gt, "reference") == pytest.approx(3 / 6)
    # labelled: covered = (0,0), (0,1), (1,1) -> all three right
    assert pixel_accuracy(pred, gt, "labelled") == pytest.approx(1.0)
    assert pixel_accuracy(pred, np.zeros_like(gt), "labelled") is None
    with pytest.raises(InputError):
        pixel_accuracy(pred, gt, "mean")


def test_lpips_id_names_the_input_range_and_the_ranges_differ():
    """lpips-[-1,1] and 3dgs-[0,1] are different numbers under different ids (old id: no range)."""
    from gsbench.metrics import build_lpips_network, lpips
    rng = np.random.default_rng(0)
    a, b = rng.random((40, 40, 3)), rng.random((40, 40, 3))
    net = build_lpips_network("vgg", random_init=True, seed=0)
    r1 = lpips(a, b, model=net, input_range="lpips-[-1,1]")
    r2 = lpips(a, b, model=net, input_range="3dgs-[0,1]")
    assert "[-1,1]" in r1.impl and "[0,1]" in r2.impl and r1.impl != r2.impl
    assert not math.isclose(r1.value, r2.value, rel_tol=1e-6)
    with pytest.raises(InputError):
        lpips(a, b, model=net, input_range="[0,255]")


def test_lerf_kernels_scale_with_label_width_and_say_so():
    from gsbench.metrics.lerf import LERF_IMPL, LerfKernels, lerf_kernels
    assert lerf_kernels(985) == LerfKernels() and lerf_kernels(1440) == LerfKernels()
    assert lerf_kernels(128, "reference") == LerfKernels()
    k = lerf_kernels(128)
    assert (k.blend, 2 * k.radius + 1) == (4, 3) and "kernels-scaled" in LERF_IMPL + k.tag
    assert lerf_kernels(985).tag == ""


def test_summarise_does_not_drop_missing_views():
    """The old _mean averaged what was left after dropping None / NaN."""
    from gsbench.results import summarise
    assert summarise([1.0, 3.0]) == (2.0, None)
    v, why = summarise([1.0, None, float("nan")], ["a", "b", "c"])
    assert v is None and "2 of 3" in why and "'b'" in why


def test_results_builders_key_skipped_by_metric_name():
    from gsbench.results import RESULTS_VERSION, check_skipped, failed_results
    with pytest.raises(ValueError, match="metric names"):
        check_skipped({"psnr": 1.0}, {"semantics": "free text"})
    with pytest.raises(ValueError, match="without a reason"):
        check_skipped({"psnr": None}, {})
    res = failed_results(identity={"run_id": "r", "method": "gaussiands", "protocols": ["lerf"]},
                         reason="run failed: boom", machine={})
    assert res["results_version"] == RESULTS_VERSION and res["status"] == "failed"
    assert set(res["skipped"]) == {k for k, v in res["metrics"].items() if v is None}
    assert "miou_lerf" in res["metrics"] and res["skipped"]["psnr"] == "run failed: boom"


def test_query_modes_have_different_ids():
    from gsbench.metric_table import seg_metric
    assert seg_metric("miou", "lerf", "decode", "held-out") == "miou_lerf_decode_heldout"
    assert seg_metric("pixel_acc", "3dovs") == "pixel_acc_3dovs"




@pytest.mark.slow
@pytest.mark.parametrize("holdout", ["every-8", "none"])
def test_evaluate_run_scores_every_labelled_frame(tmp_path, holdout):
    """End to end on a tiny run: every label file is scored under reference or held-out and listed
    in results.json; holdout none skips the reconstruction metrics with a reason; query modes have
    their own ids; the resolution of each frame set is recorded."""
    from gsbench.config import load_config
    from gsbench.datasets.synthetic import make_scene
    from gsbench.evaluation import evaluate_run
    from gsbench.runs import train_run
    scene = make_scene("tabletop-small", tmp_path / "s", seed=0, views=10, resolution=(48, 36))
    cfg = load_config("gaussiands", "cpu-small", TINY_SET + [f"train.holdout={holdout}"])
    run = train_run(cfg, scene, tmp_path / "run", progress=False)
    res = evaluate_run(run, progress=False)
    n_labels = len(list((scene / "label" / "tabletop-small").glob("*.json")))
    for p in ("lerf", "3dovs"):
        scored = res["frames"].get(f"{p}/reference", []) + res["frames"].get(f"{p}/held-out", [])
        assert len(scored) == len(set(scored)) == n_labels == 10
        assert res["resolution"][f"{p}/reference"] == "48x36"
    assert res["metric_impl"]["miou_lerf_encode"] != res["metric_impl"]["miou_lerf_decode"]
    if holdout == "none":
        assert res["metrics"]["psnr"] is None and "holdout" in res["skipped"]["psnr"]
        assert res["metrics"]["miou_lerf_heldout"] is None and res["skipped"]["miou_lerf_heldout"]
        assert len(res["frames"]["lerf/reference"]) == 10
    else:
        assert res["metrics"]["psnr"] is not None and len(res["frames"]["lerf/held-out"]) == 2


def test_eval_protocol_key_is_read():
    """eval.protocol used to change the run id without being read by anything."""
    from gsbench.evaluation.run import requested_protocol
    assert requested_protocol(None, {"eval": {"protocol": "lerf"}}) == "lerf"
    assert requested_protocol("3dovs", {"eval": {"protocol": "lerf"}}) == "3dovs"
    assert requested_protocol(None, {}) == "auto"


class _Out:
    def __init__(self, rgb):
        self.rgb = rgb


class _ExactUpToRounding:
    """A method whose render is the GT image plus noise below half an 8-bit step."""

    def __init__(self, scene):
        self.scene = scene
        self.rng = np.random.default_rng(0)

    def render(self, cam):
        i = next(k for k, c in enumerate(self.scene.cameras) if c.name == cam.name)
        gt = np.asarray(self.scene.image(i), np.float64)
        q = np.floor(gt * 255 + 0.5) / 255
        return _Out(q + self.rng.uniform(-0.4, 0.4, q.shape) / 255)


def test_ssim_reads_quantised_renders(lerf_scene):
    """SSIM (like PSNR) is computed on the 8-bit values: a render equal to the GT up to rounding
    scores exactly 1 (the old code fed the float render to SSIM and read below 1)."""
    from gsbench.evaluation.image import image_metrics
    from gsbench.metrics import ssim
    ids = [0, 8]
    cams = [lerf_scene.cameras[i] for i in ids]
    b = image_metrics(_ExactUpToRounding(lerf_scene), lerf_scene, ids, cams, _cfg())
    assert b.metrics["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert b.metrics["psnr"] == pytest.approx(100.0)
    assert b.metric_impl["ssim"].endswith("+uint8-input")
    raw = _ExactUpToRounding(lerf_scene).render(cams[0]).rgb
    assert ssim(np.clip(raw, 0, 1), lerf_scene.image(0)) < 1.0 - 1e-6


def test_both_ssim_and_lpips_conventions_are_kept_with_their_ids(lerf_scene, monkeypatch):
    """`ssim` / `lpips` are the 3DGS forms (zero-padded SSIM, LPIPS on [0, 1] inputs) and
    `ssim_valid` / `lpips_package` the other conventions; each value equals the metric computed
    directly with that convention (LPIPS: a seeded random-init network, weight-free)."""
    from gsbench.evaluation.image import image_metrics
    from gsbench.metrics import image as MI
    from gsbench.metrics import perceptual as MP
    net = MP.build_lpips_network("vgg", random_init=True, seed=0)
    monkeypatch.setattr(MP, "load_lpips", lambda name="vgg", weights_dir=None: (net, None))
    cam = lerf_scene.cameras[0]
    render = np.clip(lerf_scene.image(0) + np.random.default_rng(1).normal(0, 0.1, (48, 64, 3)), 0, 1)
    method = type("Noisy", (), {"render": lambda self, c: _Out(render)})()
    b = image_metrics(method, lerf_scene, [0], [cam], _cfg())
    pred = MI.quantize_uint8(render)
    gt = MI.quantize_uint8(lerf_scene.image(0))
    assert "zeropad-3dgs" in b.metric_impl["ssim"] and "/valid/" in b.metric_impl["ssim_valid"]
    assert "input3dgs-[0,1]" in b.metric_impl["lpips"] and "inputlpips-[-1,1]" in b.metric_impl["lpips_package"]
    assert b.metrics["ssim"] == pytest.approx(MI.ssim(pred, gt, border="zeropad"), abs=1e-12)
    assert b.metrics["ssim_valid"] == pytest.approx(MI.ssim(pred, gt, border="valid"), abs=1e-12)
    l3 = MP.lpips(pred, gt, model=net, input_range="3dgs-[0,1]").value
    lp = MP.lpips(pred, gt, model=net, input_range="lpips-[-1,1]").value
    assert b.metrics["lpips"] == pytest.approx(l3, rel=1e-6)
    assert b.metrics["lpips_package"] == pytest.approx(lp, rel=1e-6)
    assert abs(l3 - lp) > 1e-6                                   # two different numbers, each under its own name


class _RandomSemantics:
    """Seeded random features and text embeddings: enough to drive the protocol code."""

    def embed_text(self, texts, mode):
        return np.stack([np.random.default_rng(zlib.crc32(f"{t}|{mode}".encode())).normal(size=4) for t in texts])

    def semantic_features(self, cam, mode):
        return np.random.default_rng(cam.width).normal(size=(cam.height, cam.width, 4))


def test_lerf_scoring_ids_sizes_and_frames(lerf_scene):
    """Each query mode has its own id; the plain name is the configured mode; frames and the label
    size are recorded; the kernels scaled to the 64 px labels are named in the id."""
    from gsbench.evaluation.segmentation import score_lerf
    cfg = {"train": {"max_width": 32}, "eval": {}}
    ids = [1, 2, 3]
    enc = score_lerf(_RandomSemantics(), lerf_scene, ids, cfg, "encode", "encode", "reference")
    dec = score_lerf(_RandomSemantics(), lerf_scene, ids, cfg, "decode", "encode", "reference")
    assert enc.metric_impl["miou_lerf_encode"] != dec.metric_impl["miou_lerf_decode"]
    assert enc.metric_impl["miou_lerf_encode"].endswith("+query-encode")
    assert "kernels-scaled-box2-maj3" in enc.metric_impl["miou_lerf"]
    assert "miou_lerf" in enc.metrics and "miou_lerf" not in dec.metrics
    assert enc.frames["lerf/reference"] == [lerf_scene.cameras[i].name for i in ids]
    assert enc.resolution["lerf/reference"] == "64x48"
    assert len(enc.per_view["miou_lerf"]) == 3
    held = score_lerf(_RandomSemantics(), lerf_scene, [], cfg, "encode", "encode", "held-out")
    assert held.metrics["miou_lerf_heldout"] is None and "held-out" in held.skipped["miou_lerf_heldout"]


def test_gt_and_training_images_are_resized_as_3dgs_loads_them(lerf_scene):
    """3DGS loads an image with PIL and resizes it with Image.resize's default (bicubic) on the
    8-bit image; the evaluation GT and the training images follow it (the old rule, cv2 INTER_AREA
    on floats, differed by up to several 8-bit steps)."""
    import cv2
    from PIL import Image

    from gsbench.resize import resize_rgb
    from gsbench.train.views import load_views
    path = lerf_scene.image_paths[0]
    with Image.open(path) as im:
        ref = np.asarray(im.convert("RGB").resize((32, 24), Image.BICUBIC), np.float32) / 255.0
    ours = resize_rgb(np.asarray(lerf_scene.image(0), np.float32), 32, 24)
    assert ours.shape == (24, 32, 3)
    np.testing.assert_allclose(ours, ref, atol=1e-7)
    area = cv2.resize(np.asarray(lerf_scene.image(0), np.float32), (32, 24), interpolation=cv2.INTER_AREA)
    assert np.abs(area - ref).max() > 1.5 / 255                    # the rule matters
    cfg = {"seed": 0, "train": {"max_width": 32, "eval_views": 0, "holdout": "every-8", "data_on": "device"}}
    views, size = load_views(lerf_scene, cfg)
    assert size == (32, 24)
    np.testing.assert_allclose(views.images[1].numpy(), np.asarray(
        Image.open(lerf_scene.image_paths[1]).convert("RGB").resize((32, 24), Image.BICUBIC), np.float32) / 255.0,
        atol=1e-7)


def test_3dovs_scored_at_the_reference_size_on_a_real_capture(tmp_path_factory):
    """The 3D-OVS reference scores at int(W / 8) x int(H / 8) of its images (--downsample_test 8).
    A real capture gets that by default, a generated scene (stored at its scoring size) 1; an
    explicit eval.ovs3d_downsample wins; the size and the rule are recorded."""
    from gsbench.datasets import load_scene
    from gsbench.datasets.synthetic import make_scene
    from gsbench.evaluation.frames import segmentation_camera
    from gsbench.evaluation.segmentation import score_3dovs
    out = make_scene("tabletop-small", tmp_path_factory.mktemp("o") / "t", seed=0, views=9, resolution=(128, 96))
    gen = load_scene(out)
    real = load_scene(out)
    real.meta.pop("synthetic")                       # as a downloaded 3D-OVS capture: no generator record
    cfg = {"train": {"max_width": None}, "eval": {}}
    i = real.semantic_view_ids[0] if real.semantic_view_ids else 0
    c = segmentation_camera(gen, i, "3dovs", cfg)
    assert (c.width, c.height) == (128, 96)
    c = segmentation_camera(real, i, "3dovs", cfg)
    assert (c.width, c.height) == (128 // 8, 96 // 8)
    c = segmentation_camera(real, i, "3dovs", {"train": {}, "eval": {"ovs3d_downsample": 2}})
    assert (c.width, c.height) == (64, 48)
    b = score_3dovs(_RandomSemantics(), real, [i], cfg, "encode", "encode", "reference")
    assert b.resolution["3dovs/reference"] == "16x12"
    assert b.notes["3dovs_size"] == ("1/8 of the 128x96 images "
                                     "(real capture: the 3D-OVS reference's --downsample_test 8)")
    assert "+size-1/8+query-encode" in b.metric_impl["miou_3dovs"]
    g = score_3dovs(_RandomSemantics(), gen, [i], cfg, "encode", "encode", "reference")
    assert g.resolution["3dovs/reference"] == "128x96" and "+size-1/1" in g.metric_impl["miou_3dovs"]
