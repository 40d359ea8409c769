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

from .guard import RawCamera, build_cameras, inside_scene
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
    p = inside_scene(root, file_path, json_path, "file_path")
    if p.is_file():
        return p
    for ext in IMAGE_EXTS:
        q = p.with_name(p.name + ext)
        if q.is_file():
            return q
    raise InputError(f"{json_path}: image {file_path[:120]!r} not found under {root}")


def _number(value, key: str, json_path: Path) -> float:
    """A JSON intrinsics value as a float (NaN and inf pass: the camera check names them per view)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"{json_path}: {key} is not a number ({str(value)[:40]!r})") from None


def _focals(get, w: int, h: int, json_path: Path) -> tuple[float, float]:
    """(fx, fy) from fl_x / fl_y, else from the field of view (camera_angle_x / camera_angle_y)."""
    if get("fl_x") is not None:
        fx = _number(get("fl_x"), "fl_x", json_path)
        return fx, _number(get("fl_y", fx), "fl_y", json_path)
    if get("camera_angle_x") is None:
        raise InputError(f"{json_path}: no intrinsics (fl_x or camera_angle_x)")
    angles = []
    for key, size in (("camera_angle_x", w), ("camera_angle_y", h)):
        a = get(key)
        if a is None:
            continue
        a = _number(a, key, json_path)
        if not 0 < a < math.pi:         # tan(a / 2) is 0 or negative or undefined outside
            raise InputError(f"{json_path}: {key} {a} is not in (0, pi)")
        angles.append(0.5 * size / math.tan(0.5 * a))
    return angles[0], angles[-1]


def _camera(frame: dict, glob: dict, img: Path, json_path: Path) -> RawCamera:
    def get(k, default=None):
        return frame.get(k, glob.get(k, default))

    w, h = image_size(img)
    W0, H0 = get("w"), get("h")
    if (W0 is not None and _number(W0, "w", json_path) != w) or (H0 is not None and _number(H0, "h", json_path) != h):
        raise InputError(f"{img}: image is {w}x{h}, {json_path.name} says {W0}x{H0}")
    fx, fy = _focals(get, w, h, json_path)
    cx = _number(get("cx", w / 2.0), "cx", json_path)
    cy = _number(get("cy", h / 2.0), "cy", json_path)
    try:
        m = np.asarray(frame.get("transform_matrix"), dtype=np.float64)
    except (TypeError, ValueError):
        m = np.zeros(0)
    if m.shape == (3, 4):
        m = np.vstack([m, [0, 0, 0, 1]])
    if m.shape != (4, 4):
        raise InputError(f"{json_path}: frame {str(frame.get('file_path'))[:80]!r} has no 4x4 transform_matrix")
    meta = {}
    dist = {k: _number(get(k), k, json_path) for k in _DIST_KEYS if get(k) is not None}
    if any(v != 0 for v in dist.values()):
        meta["distortion"] = dist
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    return RawCamera(K, w, h, img.name, json_path, json_path, camera_to_world=m @ GL_TO_CV, meta=meta)


def _frames(jp: Path) -> tuple[dict, list[dict]]:
    """The document and its 'frames' list (each frame an object)."""
    d = read_json_input(jp)
    frames = d.get("frames") if isinstance(d, dict) else None
    if not isinstance(frames, list) or not frames:
        raise InputError(f"{jp}: no 'frames' list")
    if not all(isinstance(fr, dict) for fr in frames):
        raise InputError(f"{jp}: a frame of 'frames' is not an object")
    return d, frames


def read_transforms(root: Path) -> tuple[list[Camera], list[Path], list[int] | None, list[int] | None, dict]:
    """Cameras, image paths, explicit train / test ids (None when there is one file), meta."""
    root = Path(root)
    split_files = {s: root / f"transforms_{s}.json" for s in ("train", "test")}
    raws, paths, train, test = [], [], None, None
    meta: dict = {"convention": "opengl c2w -> opencv"}
    if all(p.is_file() for p in split_files.values()):
        train, test = [], []
        for split, jp in split_files.items():
            d, frames = _frames(jp)
            for fr in frames:
                img = _resolve_image(root, str(fr.get("file_path", "")), jp)
                (train if split == "train" else test).append(len(raws))
                raws.append(_camera(fr, d, img, jp))
                paths.append(img)
        meta["split"] = "transforms_train/test.json"
        meta["poses_from"] = " + ".join(str(p) for p in split_files.values())
        if (root / "transforms_val.json").is_file():
            meta["ignored"] = "transforms_val.json"
        return build_cameras(raws), paths, train, test, meta
    jp = root / "transforms.json"
    d, frames = _frames(jp)
    frames = sorted(frames, key=lambda f: str(f.get("file_path", "")))
    for fr in frames:
        img = _resolve_image(root, str(fr.get("file_path", "")), jp)
        raws.append(_camera(fr, d, img, jp))
        paths.append(img)
    meta["poses_from"] = str(jp)
    for k in ("aabb_scale", "scale", "offset", "applied_transform"):
        if k in d:
            meta[f"ignored_{k}"] = d[k]
    return build_cameras(raws), paths, None, None, meta
