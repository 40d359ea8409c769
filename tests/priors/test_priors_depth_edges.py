"""The gt depth prior's edges: modelled at the estimator's working size, so they span a few working
pixels at any output size, and GaussianDS's edge map E_d finds them at the default distortion."""
from __future__ import annotations

import numpy as np
import pytest
from bench_scripts import load_benchmark
from sphere_scene import make_sphere_scene

from gsbench.config import load_config
from gsbench.datasets import load_scene
from gsbench.errors import InputError
from gsbench.methods.registry import build_priors_request
from gsbench.priors import depth as D
from gsbench.priors import prepare_priors
from gsbench.train.losses import EDGE_FLOOR, depth_edges, edge_coverage


def step_depth(width: int, height: int) -> np.ndarray:
    """z = 1 left of the middle column, 2 right of it: one vertical depth step."""
    z = np.ones((height, width))
    z[:, width // 2:] = 2.0
    return z


def ramp_width(row: np.ndarray, half: int) -> int:
    """Pixels strictly between 10 % and 90 % of the way across the step in the middle of `row`, in a
    window of +-`half` pixels around it (the distortion's smooth warp barely changes inside it)."""
    c = row.size // 2
    w = np.asarray(row[c - half:c + half], dtype=np.float64)
    left, right = float(w[:3].mean()), float(w[-3:].mean())
    t = (w - left) / (right - left)
    return int(((t > 0.1) & (t < 0.9)).sum())


def step_width(size: tuple[int, int], distortion: float, working_size: int = 518) -> int:
    """`ramp_width` of the middle row of the prior of `step_depth(size)`, window 16 working pixels."""
    vals, _ = D.gt_disparity_prior(step_depth(*size), np.random.default_rng(1), distortion,
                                   working_size=working_size)
    half = max(4, round(16 * min(size) / working_size))
    return ramp_width(vals[size[1] // 2], half)


def test_working_shape_keeps_the_aspect_with_the_short_side_given():
    assert D.working_shape((756, 1008), 518) == (518, 691)
    assert D.working_shape((24, 32), 518) == (518, 691)
    assert D.working_shape((1000, 500), 100) == (200, 100)
    with pytest.raises(ValueError):
        D.working_shape((0, 10))


@pytest.mark.parametrize("distortion", [0.0, 1.0, 2.0])
def test_step_edge_is_a_few_working_pixels_wide_at_any_output_size(distortion):
    widths = {}
    for size in ((864, 648), (2072, 1554)):         # 1.25x and 3x the 691x518 working image
        vals, valid = D.gt_disparity_prior(step_depth(*size), np.random.default_rng(1), distortion)
        assert valid.all() and vals.shape == (size[1], size[0]) and np.isfinite(vals).all()
        widths[size] = step_width(size, distortion)
    work = [w / (size[0] / 691) for size, w in widths.items()]     # back in working pixels
    # the same width in working pixels at both sizes (within the pixel rounding) ...
    assert abs(work[0] - work[1]) <= 1.5
    # ... and a few of them: blur sigma 0.5 + 0.5 per unit of distortion -> 10-90 % over ~2.6 sigma
    assert all(1.0 <= w <= 6.0 for w in work)
    # in output pixels it grows with the output size (2072 / 864 = 2.4 x), not like the old share of the diagonal
    assert widths[(2072, 1554)] >= 2 * widths[(864, 648)] - 1


def test_edge_smearing_grows_with_distortion():
    w = [step_width((1036, 777), d) for d in (0.0, 1.0, 2.0, 4.0)]
    assert w[0] < w[1] < w[2] < w[3]


def test_small_output_keeps_a_sharp_edge():
    assert step_width((64, 48), 1.0) <= 2


def test_working_size_sets_the_edge_width_in_output_pixels():
    fine, coarse = step_width((1036, 777), 1.0, 518), step_width((1036, 777), 1.0, 259)
    assert coarse >= 1.5 * fine


def test_prior_from_a_larger_gt_depth_keeps_validity_at_the_output_size():
    z = step_depth(128, 96)
    z[:10] = 0.0                                    # invalid rows (no depth)
    vals, valid = D.gt_disparity_prior(z, np.random.default_rng(0), 1.0, size=(32, 24))
    assert vals.shape == valid.shape == (24, 32)
    assert not valid[:2].any() and valid[3:].all()


def _edge_shares(scene, cfg, distortion=None):
    req = build_priors_request(cfg, scene)
    dcfg = dict(req["priors"]["depth"])
    if distortion is not None:
        dcfg["distortion"] = distortion
    p = prepare_priors(scene, {"depth": dcfg}, req["view_ids"], tuple(req["size"]), None, True, False, False,
                       seed=req["seed"], progress=False)
    e = cfg["gaussiands"]["edges"]
    return edge_coverage({v: depth_edges(d.values, d.valid, e["canny_low"], e["canny_high"], int(e["dilate"]))
                          for v, d in p.depth.items()})


def test_e_d_is_not_empty_on_the_tiny_scene_at_the_default_distortion(tiny_scene):
    cfg = load_config("gaussiands")
    depth = cfg["priors"]["depth"]
    assert depth["distortion"] == 1.0 and depth["working_size"] == D.WORKING_SIZE == 518
    share, n_empty = _edge_shares(load_scene(tiny_scene), cfg)
    assert n_empty == 0 and share >= EDGE_FLOOR


def test_e_d_is_not_empty_at_640x480_at_the_default_distortion():
    # the old prior (blur by a share of the diagonal) left E_d empty here
    scene = make_sphere_scene(2, 640, 480)
    cfg = load_config("gaussiands")
    cfg["train"]["holdout"] = "none"
    share, n_empty = _edge_shares(scene, cfg)
    assert n_empty == 0 and share >= 2 * EDGE_FLOOR


def test_working_size_is_in_the_provider_id_and_the_cache_key_and_checked(tmp_path):
    scene = make_sphere_scene(2, 32, 24)
    keys, ids = set(), set()
    for ws in (518, 256):
        p = prepare_priors(scene, {"depth": {"provider": "gt", "working_size": ws}}, [0], (32, 24), tmp_path,
                           True, False, False, progress=False)
        keys.add(p.cache["depth"]["key"])
        ids.add(p.providers["depth"])
    assert len(keys) == 2 and ids == {"gt-sim-disparity-v3:d1:w518", "gt-sim-disparity-v3:d1:w256"}
    for bad in (8, 5000, 100.5, "big"):
        with pytest.raises(InputError, match="priors.depth.working_size"):
            prepare_priors(scene, {"depth": {"provider": "gt", "working_size": bad}}, [0], (32, 24), None, True,
                           False, False, progress=False)


def test_edge_share_benchmark_prints_the_table(tmp_path, capsys):
    bench = load_benchmark("edge_share")
    assert bench.main(["--work", str(tmp_path), "--presets", "tabletop-small", "--sizes", "32x24",
                       "--distortions", "0", "1", "--views", "3"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| tabletop-small")]
    assert len(rows) == 1
    cells = rows[0].split("|")[3:-1]
    assert len(cells) == 3 and all(c.strip().endswith("/2]") for c in cells)
