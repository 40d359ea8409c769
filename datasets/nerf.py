"""NeRF-synthetic / instant-ngp / nerfstudio `transforms.json`.

`transform_matrix` is an OpenGL camera-to-world (x right, y up, z back); OpenCV flips the y and z
camera axes. Intrinsics: `fl_x/fl_y/cx/cy/w/h` (instant-ngp, nerfstudio; per frame or global) or
`camera_angle_x` (NeRF synthetic: fx = fy = 0.5 W / tan(angle / 2), centred principal point).
Distortion (`k1 k2 k3 k4 p1 p2`) is recorded in `Camera.meta["distortion"]`, not applied.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gsbench.camera import Camera
from gsbench.errors import InputError
from gsbench.store import read_json

from .imageio import IMAGE_EXTS, image_size

GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
_DIST_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")


def read_json_input(path: Path) -> dict:
    try:
        return read_json(path)
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except ValueError as e:
        raise InputError(str(e)) from None


def _resolve_image(root: Path, file_path: str, json_path: Path) -> Path:
    p = (root / file_path)
    if p.is_file():
        return p
    for ext in IMAGE_EXTS:
        q = p.with_name(p.name + ext)
        if q.is_file():
            return q
    raise InputError(f"{json_path}: image {file_path!r} not found under {root}")


def _camera(frame: dict, glob: dict, img: Path, json_path: Path) -> Camera:
    def get(k, default=None):
        return frame.get(k, glob.get(k, default))

    w, h = image_size(img)
    W0, H0 = get("w"), get("h")
    if (W0 is not None and int(W0) != w) or (H0 is not None and int(H0) != h):
        raise InputError(f"{img}: image is {w}x{h}, {json_path.name} says {W0}x{H0}")
    if get("fl_x") is not None:
        fx = float(get("fl_x"))
        fy = float(get("fl_y", fx))
    elif get("camera_angle_x") is not None:
        ax = float(get("camera_angle_x"))
        if not 0 < ax < math.pi:
            raise InputError(f"{json_path}: camera_angle_x {ax} is not in (0, pi)")
        fx = 0.5 * w / math.tan(0.5 * ax)
        ay = get("camera_angle_y")
        fy = 0.5 * h / math.tan(0.5 * float(ay)) if ay is not None else fx
    else:
        raise InputError(f"{json_path}: no intrinsics (fl_x or camera_angle_x)")
    cx = float(get("cx", w / 2.0))
    cy = float(get("cy", h / 2.0))
    m = np.asarray(frame.get("transform_matrix"), dtype=np.float64)
    if m.shape == (3, 4):
        m = np.vstack([m, [0, 0, 0, 1]])
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError(f"{json_path}: frame {frame.get('file_path')!r} has no valid 4x4 transform_matrix")
    c2w = m @ GL_TO_CV
    meta = {}
    dist = {k: float(get(k)) for k in _DIST_KEYS if get(k) is not None}
    if any(v != 0 for v in dist.values()):
        meta["distortion"] = dist
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    return Camera(K, np.linalg.inv(c2w), w, h, name=img.name, meta=meta)


def read_transforms(root: Path) -> tuple[list[Camera], list[Path], list[int] | None, list[int] | None, dict]:
    """Cameras, image paths, explicit train / test ids (None when there is one file), meta."""
    root = Path(root)
    split_files = {s: root / f"transforms_{s}.json" for s in ("train", "test")}
    cams, paths, train, test = [], [], None, None
    meta: dict = {"convention": "opengl c2w -> opencv"}
    if all(p.is_file() for p in split_files.values()):
        train, test = [], []
        for split, jp in split_files.items():
            d = read_json_input(jp)
            frames = d.get("frames") if isinstance(d, dict) else None
            if not isinstance(frames, list) or not frames:
                raise InputError(f"{jp}: no 'frames' list")
            for fr in frames:
                img = _resolve_image(root, str(fr.get("file_path", "")), jp)
                (train if split == "train" else test).append(len(cams))
                cams.append(_camera(fr, d, img, jp))
                paths.append(img)
        meta["split"] = "transforms_train/test.json"
        if (root / "transforms_val.json").is_file():
            meta["ignored"] = "transforms_val.json"
        return cams, paths, train, test, meta
    jp = root / "transforms.json"
    d = read_json_input(jp)
    frames = d.get("frames") if isinstance(d, dict) else None
    if not isinstance(frames, list) or not frames:
        raise InputError(f"{jp}: no 'frames' list")
    frames = sorted(frames, key=lambda f: str(f.get("file_path", "")))
    for fr in frames:
        img = _resolve_image(root, str(fr.get("file_path", "")), jp)
        cams.append(_camera(fr, d, img, jp))
        paths.append(img)
    for k in ("aabb_scale", "scale", "offset", "applied_transform"):
        if k in d:
            meta[f"ignored_{k}"] = d[k]
    return cams, paths, None, None, meta
