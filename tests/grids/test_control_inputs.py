"""A positive control must be given what its mechanism acts on. The L_ds control's depth prior must
leave Canny edges for E_d. The control sets distortion 0; since the gt prior models its edges at the
estimator's working size (docs/priors.md), the default prior (distortion 1) leaves them too at the
control's size (docs/methods.md, 'When E_d is empty')."""
from __future__ import annotations

from gsbench.datasets.loader import load_scene
from gsbench.datasets.synthetic import make_scene
from gsbench.grids.claims_plan import plan_grids
from gsbench.grids.grid_file import load_grid
from gsbench.priors.depth import compute_depth
from gsbench.train.losses import EDGE_FLOOR, depth_edges, edge_coverage


def _coverage(scene, tree: dict, size: tuple[int, int]) -> tuple[float, int]:
    depth_cfg, e = tree["priors"]["depth"], tree["gaussiands"]["edges"]
    pri = compute_depth(scene, depth_cfg, list(range(len(scene.cameras))), size, seed=0)
    return edge_coverage({v: depth_edges(p.values, p.valid, e["canny_low"], e["canny_high"], int(e["dilate"]))
                          for v, p in pri.items()})


def test_the_ds_control_has_depth_edges_and_so_has_the_default_prior(tmp_path):
    grid = load_grid("control_ds-cpu")
    tree = grid.base_tree()
    assert tree["train"]["max_width"] == 256
    # the control's scene at the control's training size (tabletop-medium is 4:3), four views
    make_scene("tabletop-medium", tmp_path / "s", seed=0, views=4, resolution=(256, 192), layout="3dovs")
    scene = load_scene(tmp_path / "s")
    share, empty = _coverage(scene, tree, (256, 192))
    assert share > 5 * EDGE_FLOOR and empty == 0
    default = {**tree, "priors": {**tree["priors"], "depth": {**tree["priors"]["depth"], "distortion": 1.0}}}
    share1, empty1 = _coverage(scene, default, (256, 192))
    assert share1 > 5 * EDGE_FLOOR and empty1 == 0


def test_the_depth_controls_follow_the_few_view_protocol():
    """control_depth: 3, 6 and 9 training views of a 24-view scene (every 8th held out leaves 21),
    lambda_depth 0 (the reference) to 1, 5 seeds; the depth-noise control at 3 views and
    lambda_depth 1. Under `claims --quick` the scenes keep their 24 views, so 9 views still fit."""
    depth = load_grid("control_depth-cpu")
    assert [s.views for s in depth.scenes] == [24]
    cells = depth.cells()
    assert {c.overrides["train.views"] for c in cells} == {3, 6, 9}
    assert {c.overrides["gaussiands.lambdas.depth"] for c in cells} == {0.0, 0.01, 0.1, 1.0}
    assert len(depth.seeds) >= 5 and len(cells) == 3 * 4 * len(depth.seeds)
    assert depth.base_tree()["priors"]["depth"]["distortion"] == 0
    noise = load_grid("control_depth_noise-cpu")
    tree = noise.base_tree()
    assert tree["train"]["views"] == 3 and tree["gaussiands"]["lambdas"]["depth"] == 1.0
    assert [s.views for s in noise.scenes] == [24]
    for g in plan_grids(quick=True, names=("control_depth-cpu", "control_depth_noise-cpu")):
        assert [s.views for s in g.scenes] == [24]
