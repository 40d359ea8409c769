"""The layout registry (docs/datasets.md "Adding a layout"): the built-ins in their detection order, the
`register` hook, and the refusals. (A layout from an entry point: tests/evaluation/test_protocol_plugins.py.)"""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.camera import Camera
from gsbench.datasets import layout_registry as R
from gsbench.datasets import load_scene
from gsbench.datasets.base import Scene
from gsbench.datasets.check import check_folder
from gsbench.errors import InputError


def test_builtin_layouts_in_detection_order():
    assert R.layout_names() == ("auto", "kaolin", "3dovs+lerf", "both", "3dovs", "lerf", "colmap", "llff", "nerf")
    assert R.get_layout("both").name == "3dovs+lerf"
    with pytest.raises(InputError, match="unknown layout 'mine'; choose one of auto, kaolin"):
        R.get_layout("mine")


def _read(root) -> Scene:
    cam = Camera(K=np.eye(3), world_to_camera=np.eye(4), width=4, height=3, name="only")
    return Scene(name=root.name, path=str(root), layout="marker", cameras=[cam], train_ids=[0], test_ids=[],
                 image_paths=[])


def test_a_registered_layout_is_detected_read_and_checked(tmp_path):
    (tmp_path / "marker.txt").write_text("x")
    (tmp_path / "poses_bounds.npy").write_bytes(b"")      # would read as llff without the new layout
    layout = R.Layout("marker", detect=lambda root: (root / "marker.txt").is_file(), read=_read, priority=5)
    R.register(layout)
    try:
        assert R.detect_layout(tmp_path) == "marker"        # priority 5: asked before llff (60)
        scene = load_scene(tmp_path)
        assert scene.layout == "marker" and len(scene.cameras) == 1
        # one camera and no points: the shared-centre extent rule of every layout with extras gives 1.0
        assert scene.extent == 1.0
        rep = check_folder(tmp_path)
        assert rep.layout == "marker" and rep.ok and "decoded   0 of 0 images whole" in rep.facts
        with pytest.raises(InputError, match="'marker' is already taken"):
            R.register(layout)
    finally:
        R.unregister("marker")
    assert R.detect_layout(tmp_path) == "llff"


def test_a_layout_without_a_reader_is_refused():
    with pytest.raises(InputError, match="has no reader"):
        R.register(R.Layout("empty", detect=lambda root: False))
    with pytest.raises(InputError, match="not a gsbench Layout"):
        R.register("colmap")
    assert "empty" not in R.layout_names()
