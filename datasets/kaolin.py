"""The kaolin rendered layout: `views/{i}_rgb.png`, `views/{i}_semantic.png`, `views/{i}_metadata.json`.

`camera_properties.tf_mat` is the USD world-to-camera (view) matrix in row-vector convention,
p_cam = [p_world, 1] @ tf_mat, for a camera looking down -Z with +Y up: OpenCV world-to-camera
= diag(1, -1, -1, 1) @ tf_mat.T. Focal length in pixels = image width * focal_length /
horizontal_aperture (square pixels, principal point at the image centre). Views are ordered by
their number i. Semantics: class 0 "background" (value 0), class 1 = the object (value 255).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from gsbench.camera import Camera
from gsbench.errors import InputError

from .guard import RawCamera, build_cameras
from .imageio import image_size
from .nerf import read_json_input

RGB_RE = re.compile(r"^(\d+)_rgb\.png$")
USD_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def is_kaolin(root: Path) -> bool:
    v = Path(root) / "views"
    return v.is_dir() and any(RGB_RE.match(p.name) for p in v.iterdir())


def read_kaolin(root: Path) -> tuple[list[Camera], list[Path], list[Path]]:
    """Cameras, RGB paths and semantic-mask paths, ordered by view number."""
    views = Path(root) / "views"
    ids = sorted(int(m.group(1)) for p in views.iterdir() if (m := RGB_RE.match(p.name)))
    if not ids:
        raise InputError(f"{views}: no {{i}}_rgb.png files")
    raws, rgbs, sems = [], [], []
    for i in ids:
        rgb = views / f"{i}_rgb.png"
        sem = views / f"{i}_semantic.png"
        mp = views / f"{i}_metadata.json"
        if not sem.is_file():
            raise InputError(f"{sem}: semantic mask missing for {rgb.name}")
        md = read_json_input(mp)
        try:
            cp = md["camera_properties"]
            tf = np.asarray(cp["tf_mat"], dtype=np.float64)
            focal = float(cp["focal_length"])
            aperture = float(cp["horizontal_aperture"])
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"{mp}: missing or malformed camera_properties ({str(e)[:80]})") from None
        if tf.shape != (4, 4) or not aperture > 0:     # the aperture is divided by below
            raise InputError(f"{mp}: tf_mat must be a 4x4 and horizontal_aperture positive")
        w, h = image_size(rgb)
        f = w * focal / aperture
        K = np.array([[f, 0, w / 2.0], [0, f, h / 2.0], [0, 0, 1.0]])
        raws.append(RawCamera(K, w, h, rgb.name, mp, mp, world_to_camera=USD_TO_CV @ tf.T))
        rgbs.append(rgb)
        sems.append(sem)
    return build_cameras(raws), rgbs, sems
