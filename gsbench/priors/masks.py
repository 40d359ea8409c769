"""Mask providers: per-view segments and view-consistent tracks.

- ``gt``: the scene's GT instances (ids already consistent): the upper bound.
- ``simulated`` (weight-free): per-view segments made from GT instances the way a per-frame
  segmenter fails, then propagated by the weight-free propagator (`gsbench.priors.propagation`).
  Failures, per view, seeded by (seed, view id), growing with ``severity`` (0 = perfect):
    * boundary jitter: the instance map is resampled through a smooth random displacement field
      whose per-pixel std is ``JITTER_PER_SEVERITY * severity`` of the image diagonal;
    * merges: each instance is merged with a random touching neighbour with probability
      ``MERGE_PER_SEVERITY * severity``;
    * splits: each segment is cut in two by a random line through its centroid with probability
      ``SPLIT_PER_SEVERITY * severity``;
    * segments smaller than ``MIN_SEGMENT_AREA`` pixels are dropped (as automatic segmenters do);
    * ids are permuted per view (ids mean nothing across views before propagation).
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

from gsbench.errors import InputError
from gsbench.priors.weights import require_weights

JITTER_PER_SEVERITY = 0.006
MERGE_PER_SEVERITY = 0.04
SPLIT_PER_SEVERITY = 0.04
MIN_SEGMENT_AREA = 8
SIM_VERSION = 1


def _neighbour_pairs(labels: np.ndarray) -> set[tuple[int, int]]:
    pairs = set()
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1, :], labels[1:, :])):
        m = (a != b) & (a >= 0) & (b >= 0)
        for x, y in np.unique(np.stack([a[m], b[m]], 1), axis=0) if m.any() else []:
            pairs.add((int(min(x, y)), int(max(x, y))))
    return pairs


def _jitter(labels: np.ndarray, amp: float, rng: np.random.Generator) -> np.ndarray:
    """Resample `labels` through a smooth random displacement field with per-pixel std `amp` px."""
    H, W = labels.shape
    if amp <= 0:
        return labels.copy()
    gh, gw = max(2, H // 16), max(2, W // 16)
    field = rng.standard_normal((gh, gw, 2)).astype(np.float32)
    field = cv2.resize(field, (W, H), interpolation=cv2.INTER_CUBIC)
    std = float(field.reshape(-1, 2).std())
    field *= amp / max(std, 1e-6)
    xs, ys = np.meshgrid(np.arange(W), np.arange(H))
    sx = np.clip(np.rint(xs + field[..., 0]), 0, W - 1).astype(np.int64)
    sy = np.clip(np.rint(ys + field[..., 1]), 0, H - 1).astype(np.int64)
    return labels[sy, sx]


def simulate_segments(instances: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Per-view segments (int32, -1 none, ids permuted) from a GT instance map (see module doc)."""
    if severity < 0:
        raise InputError(f"priors.masks.severity: must be >= 0, got {severity}")
    lab = np.asarray(instances).astype(np.int64)
    H, W = lab.shape
    diag = float(np.hypot(H, W))
    lab = _jitter(lab, JITTER_PER_SEVERITY * severity * diag, rng)
    # merges (union-find over touching instances)
    ids = [int(i) for i in np.unique(lab[lab >= 0])]
    parent = {i: i for i in ids}

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    p_merge = min(1.0, MERGE_PER_SEVERITY * severity)
    if p_merge > 0 and len(ids) > 1:
        neigh: dict[int, list[int]] = {i: [] for i in ids}
        for a, b in sorted(_neighbour_pairs(lab)):
            neigh[a].append(b)
            neigh[b].append(a)
        for i in ids:
            if neigh[i] and rng.random() < p_merge:
                j = neigh[i][int(rng.integers(len(neigh[i])))]
                parent[find(i)] = find(j)
    seg = np.full((H, W), -1, dtype=np.int64)
    for i in ids:
        seg[lab == i] = find(i)
    # splits
    p_split = min(1.0, SPLIT_PER_SEVERITY * severity)
    next_id = (max(ids) + 1) if ids else 0
    if p_split > 0:
        ys, xs = np.mgrid[0:H, 0:W]
        for s in [int(x) for x in np.unique(seg[seg >= 0])]:
            m = seg == s
            if m.sum() < 2 * MIN_SEGMENT_AREA or rng.random() >= p_split:
                continue
            cy, cx = ys[m].mean(), xs[m].mean()
            ang = rng.uniform(0, np.pi)
            side = ((xs - cx) * np.cos(ang) + (ys - cy) * np.sin(ang)) > 0
            seg[m & side] = next_id
            next_id += 1
    # drop tiny segments, permute ids
    present, counts = np.unique(seg[seg >= 0], return_counts=True)
    keep = present[counts >= MIN_SEGMENT_AREA]
    out = np.full((H, W), -1, dtype=np.int32)
    perm = rng.permutation(len(keep))
    for new, s in zip(perm, keep):
        out[seg == s] = int(new)
    return out


def gt_instance_map(scene, view: int, size: tuple[int, int]) -> np.ndarray:
    """GT instance ids of `view` at `size` (nearest), int32 with -1 none."""
    from gsbench.priors.warp import resize_nearest
    inst = scene.gt_instances(view)
    if inst is None:
        raise InputError(f"{scene.path}: scene has no GT instances (needed by priors.masks.provider=gt|simulated)")
    return resize_nearest(np.asarray(inst).astype(np.int32), size)


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
            import torch
            from sam2.automatic_mask_generator import SAM2AutomaticMaskGenerator
            from sam2.build_sam import build_sam2_video_predictor
        except ImportError as e:
            raise InputError(f"priors.masks.provider=sam2 needs the `models` extra "
                             f"(pip install -e .[models]): {e}") from None
        device = device or ("cuda" if torch.cuda.is_available() else "cpu")
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
