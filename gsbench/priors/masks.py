"""Mask providers: per-view segments and view-consistent tracks.

- ``gt``: the scene's GT instances (ids already consistent): the upper bound. A scene without
  instance maps (a real layout) gives its labels instead (`gsbench.priors.labels`: 3D-OVS class
  components or LERF label objects; provider id ``gt-labels:<source>``).
- ``simulated`` (weight-free): per-view segments from `gsbench.priors.segmenter` (a SAM-like
  segmenter with five failure knobs), then carried along the pseudo-video by
  `gsbench.priors.propagation`, which replaces each view's own partition by the carried one.
- ``sam2``: SAM2 automatic masks on the first pseudo-video frame, then the SAM2 video predictor
  carries them along the ordered frames (local checkpoint, CPU float32). Optional keys:
  ``generator`` (kwargs of SAM2AutomaticMaskGenerator, e.g. points_per_side) and
  ``model_overrides`` (extra hydra overrides of the model config).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Mapping, Sequence

import cv2
import numpy as np
from tqdm.auto import tqdm

from gsbench.device import default_device
from gsbench.errors import InputError
from gsbench.priors.weights import require_weights
from gsbench.resize import resize_nearest

SIM_VERSION = 2


def gt_instance_map(scene, view: int, size: tuple[int, int]) -> np.ndarray:
    """GT instance ids of `view` at `size` (nearest), int32 with -1 none."""
    inst = scene.gt_instances(view)
    if inst is None:
        raise InputError(f"{scene.path}: scene has no GT instances (needed by priors.masks.provider=gt|simulated)")
    return resize_nearest(np.asarray(inst).astype(np.int32), *size)


# --------------------------------------------------------------------------------------- SAM2
def _labels_from_masks(masks: Sequence[np.ndarray], shape: tuple[int, int]) -> np.ndarray:
    """Paint boolean masks into one int map, larger masks first so smaller ones stay visible."""
    out = np.full(shape, -1, dtype=np.int32)
    order = sorted(range(len(masks)), key=lambda i: -int(np.asarray(masks[i]).sum()))
    for k, i in enumerate(order):
        out[np.asarray(masks[i], dtype=bool)] = k
    return out


class Sam2Masks:
    """SAM2 from a local checkpoint: automatic masks + video-predictor propagation (CPU float32)."""

    version = 1

    def __init__(self, masks_cfg: Mapping, device: str | None = None):
        ckpt = masks_cfg.get("checkpoint")
        model_cfg = masks_cfg.get("model_config")
        require_weights("priors.masks.checkpoint", ckpt, "SAM2", "priors.masks.provider=sam2")
        if not model_cfg:
            raise InputError("priors.masks.model_config: not set (the SAM2 model config name matching "
                             "the checkpoint, e.g. configs/sam2.1/sam2.1_hiera_t.yaml)")
        try:
            from sam2.automatic_mask_generator import SAM2AutomaticMaskGenerator
            from sam2.build_sam import build_sam2_video_predictor
        except ImportError as e:
            raise InputError(f"priors.masks.provider=sam2 needs the `models` extra "
                             f"(pip install -e .[models]): {e}") from None
        device = device or default_device()
        self.checkpoint = str(ckpt)
        self.model_config = str(model_cfg)
        self.generator_kwargs = dict(masks_cfg.get("generator", {}) or {})
        overrides = [str(o) for o in (masks_cfg.get("model_overrides") or [])]
        try:
            self.predictor = build_sam2_video_predictor(self.model_config, self.checkpoint, device=device,
                                                        hydra_overrides_extra=overrides)
        except Exception as e:  # hydra / state-dict errors: name the files
            raise InputError(f"priors.masks: cannot build SAM2 from model_config={self.model_config} "
                             f"checkpoint={self.checkpoint}: {type(e).__name__}: {e}") from None
        self.predictor = self.predictor.float().eval()
        self.generator = SAM2AutomaticMaskGenerator(self.predictor, **self.generator_kwargs)
        # SAM2's image predictor assumes the 1024 px model's feature sizes; derive them from the
        # model so that configs with another image_size work too (identical for 1024).
        s = int(self.predictor.image_size)
        self.generator.predictor._bb_feat_sizes = [(s // 4, s // 4), (s // 8, s // 8), (s // 16, s // 16)]
        self.id = f"sam2:{Path(self.checkpoint).name}:{Path(self.model_config).stem}"

    def automatic(self, image: np.ndarray) -> np.ndarray:
        """Automatic masks of one image (float HxWx3 in [0, 1]) as an int map (-1 none)."""
        import torch
        u8 = np.clip(np.rint(image * 255), 0, 255).astype(np.uint8)
        with torch.inference_mode():
            anns = self.generator.generate(u8)
        return _labels_from_masks([a["segmentation"] for a in anns], u8.shape[:2])

    def per_frame(self, views: Sequence[int], images: Mapping[int, np.ndarray], progress: bool = False
                  ) -> dict[int, np.ndarray]:
        return {v: self.automatic(images[v])
                for v in tqdm(views, desc="sam2 masks", disable=not progress, leave=False)}

    def propagate(self, order: Sequence[int], images: Mapping[int, np.ndarray], progress: bool = False
                  ) -> dict[int, np.ndarray]:
        """Automatic masks on order[0], carried along `order` by the video predictor."""
        import torch
        first = self.automatic(images[order[0]])
        H, W = first.shape
        out = {v: np.full((H, W), -1, dtype=np.int32) for v in order}
        out[order[0]] = first
        obj_ids = [int(i) for i in np.unique(first[first >= 0])]
        if not obj_ids or len(order) == 1:
            return out
        with tempfile.TemporaryDirectory(prefix="gsbench-sam2-") as tmp:
            for k, v in enumerate(order):
                u8 = np.clip(np.rint(images[v] * 255), 0, 255).astype(np.uint8)
                path = os.path.join(tmp, f"{k:05d}.jpg")
                if not cv2.imwrite(path, cv2.cvtColor(u8, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95]):
                    raise OSError(f"{path}: could not write a SAM2 frame")
            with torch.inference_mode():
                state = self.predictor.init_state(video_path=tmp)
                for i in obj_ids:
                    self.predictor.add_new_mask(state, frame_idx=0, obj_id=i, mask=first == i)
                bar = tqdm(total=len(order), desc="sam2 propagate", disable=not progress, leave=False)
                for fidx, ids, logits in self.predictor.propagate_in_video(state):
                    lg = logits.float().cpu().numpy()[:, 0]               # (objects, H, W)
                    if lg.shape[-2:] != (H, W):
                        lg = np.stack([cv2.resize(x, (W, H), interpolation=cv2.INTER_LINEAR) for x in lg])
                    best = lg.argmax(0)
                    lab = np.asarray(ids, dtype=np.int32)[best]
                    lab[lg.max(0) <= 0.0] = -1
                    out[order[int(fidx)]] = lab
                    bar.update(1)
                bar.close()
                self.predictor.reset_state(state)
        return out
