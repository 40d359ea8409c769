"""A positive control must be given what its mechanism acts on. The L_ds control's depth prior must
leave Canny edges for E_d; the default prior (distortion 1) leaves none at the control's size, which is
why the control sets distortion 0 (docs/methods.md, 'When E_d is empty')."""
from __future__ import annotations

from gsbench.datasets.loader import load_scene
from gsbench.datasets.synthetic import make_scene
from gsbench.grids.spec import load_grid
from gsbench.methods.losses import EDGE_FLOOR, depth_edges, edge_coverage
from gsbench.priors.depth import compute_depth


def _coverage(scene, tree: dict, size: tuple[int, int]) -> tuple[float, int]:
    depth_cfg, e = tree["priors"]["depth"], tree["gaussiands"]["edges"]
    pri = compute_depth(scene, depth_cfg, list(range(len(scene.cameras))), size, seed=0)
    return edge_coverage({v: depth_edges(p.values, p.valid, e["canny_low"], e["canny_high"], int(e["dilate"]))
                          for v, p in pri.items()})


def test_the_ds_control_has_depth_edges_and_the_default_prior_has_none(tmp_path):
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
    assert share1 < EDGE_FLOOR and empty1 == 4
