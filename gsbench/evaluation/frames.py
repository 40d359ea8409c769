"""Frame sets named by protocol, and the camera each set is scored at (each protocol's rule: its file).

  reconstruction: the held-out test views (every 8th), at the training resolution;
  reference:      the labelled frames that were trained on - what the references score;
  held-out:       the labelled frames that were not trained on (a novel-view variant).
reference + held-out = every labelled frame, so no label file goes unscored without a listed reason.
Resolution (`eval.resolution`): "reference" scores 3D-OVS at the image size divided by
`eval.ovs3d_downsample` (null: 8 on a real capture, as the 3D-OVS reference tests with
--downsample_test 8; 1 on a scene gsbench generated, which is stored at its scoring size) and LERF
at each label file's size; "train" scores everything at the training resolution.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from gsbench.camera import training_size
from gsbench.config import setting
from gsbench.config_keys import EVAL_RESOLUTIONS as RESOLUTIONS
from gsbench.datasets.splits import split_ids
from gsbench.errors import InputError
from gsbench.metric_table import FRAME_SETS

from .protocol_registry import get_protocol, protocols


@dataclass
class FrameSets:
    trained: list[int]
    reconstruction: list[int]
    labelled: dict            # protocol -> sorted view ids with GT for it

    def protocol_sets(self, protocol: str) -> dict[str, list[int]]:
        """{"reference": [...], "held-out": [...]} of a segmentation protocol."""
        trained = set(self.trained)
        ids = self.labelled.get(protocol, [])
        return {"reference": [i for i in ids if i in trained], "held-out": [i for i in ids if i not in trained]}


def frame_sets(scene, config: dict) -> FrameSets:
    """The split's frame sets; `labelled` holds, for each registered protocol the scene supports, the
    frames it scores (its `frames`)."""
    trained, held = split_ids(scene, config)
    labelled = {p.name: sorted(p.frames(scene)) for p in protocols() if p.supports(scene) is None}
    return FrameSets(trained=trained, reconstruction=held, labelled=labelled)


def view_name(scene, i: int) -> str:
    return scene.cameras[i].name or str(i)


def train_camera(camera, max_width):
    """The camera at the training resolution (train.max_width, the rule training uses)."""
    w, h = training_size(camera, max_width)
    return camera if (w, h) == (camera.width, camera.height) else camera.resized(w, h)


def scoring_camera(scene, i: int, config: dict, size: Callable[[Any], tuple[int, int]]):
    """The camera view i is scored at: the training resolution under `eval.resolution: train`, else the
    protocol's own size `size(camera)` -> (w, h) (asked only then)."""
    res, _ = eval_settings(config)
    cam = scene.cameras[i]
    if res == "train":
        return train_camera(cam, setting(config, "train.max_width"))
    w, h = size(cam)
    return cam if (w, h) == (cam.width, cam.height) else cam.resized(w, h)


OVS3D_REFERENCE_DOWNSAMPLE = 8     # the 3D-OVS reference scores at int(W / 8) x int(H / 8) of its images


def eval_settings(config: dict) -> tuple[str, int | None]:
    """(eval.resolution, eval.ovs3d_downsample) checked; the factor None means the reference's rule."""
    res = setting(config, "eval.resolution")
    if res not in RESOLUTIONS:
        raise InputError(f"eval.resolution must be one of {', '.join(RESOLUTIONS)}, got {res!r}")
    down = setting(config, "eval.ovs3d_downsample")
    if down is not None and (isinstance(down, bool) or not isinstance(down, int) or down < 1):
        raise InputError(f"eval.ovs3d_downsample must be null or an integer >= 1, got {down!r}")
    return res, down


def ovs3d_downsample(scene, config: dict) -> tuple[int, str]:
    """The factor 3D-OVS frames are scored at (1/factor of the images) and why."""
    _, down = eval_settings(config)
    if down is not None:
        return down, "eval.ovs3d_downsample"
    if (getattr(scene, "meta", None) or {}).get("synthetic") is not None:
        return 1, "generated scene, stored at its scoring size"
    return OVS3D_REFERENCE_DOWNSAMPLE, "real capture: the 3D-OVS reference's --downsample_test 8"


def segmentation_camera(scene, i: int, protocol: str, config: dict):
    """The camera view i of `protocol` is scored at: the protocol's resolution rule (its `camera`)."""
    return get_protocol(protocol).camera(scene, i, config)


def size_text(cams) -> str:
    """"WxH" when every camera has that size, else the distinct sizes joined by ", "."""
    sizes = sorted({f"{c.width}x{c.height}" for c in cams})
    return ", ".join(sizes)


__all__ = ["FRAME_SETS", "FrameSets", "frame_sets", "ovs3d_downsample", "segmentation_camera", "train_camera",
           "view_name"]
