"""What every layout reader checks before it trusts a scene file: the cameras and the paths.

Cameras: a reader collects what its file says (`RawCamera`) and `build_cameras` runs the one shared
check of `gsbench.camera` (finite values, focal lengths > 0, principal point inside the image, a
proper rotation) on all of them before any `Camera` exists. Every bad view is one line naming the
file and the view; `CameraProblems` carries them all (`gsbench data check` lists them, a run stops
on the first with a count of the rest).

Paths: a path a scene file names (an image of transforms.json or of a COLMAP model, the GT folder
of gsbench_scene.json) must stay inside the scene folder: an absolute path or one whose `..` climbs
out of it is refused, unless the environment sets GSBENCH_ALLOW_OUTSIDE_PATHS=1. The check is on
the path as written, normalised without following links, so a link the user placed inside the
folder (an `images` folder on another disk) is followed as before.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from gsbench.camera import Camera, intrinsics_problems, pose_problems
from gsbench.errors import InputError

OUTSIDE_PATHS_ENV = "GSBENCH_ALLOW_OUTSIDE_PATHS"


@dataclass
class RawCamera:
    """One view's camera as its layout file states it, before the check. The pose is given either
    as world-to-camera or as camera-to-world (checked as written, inverted only once it passed)."""

    K: np.ndarray
    width: int
    height: int
    name: str                       # the view's image name, named in each problem
    intrinsics_from: Path           # the file the intrinsics come from
    pose_from: Path                 # the file the pose comes from (the same file in most layouts)
    world_to_camera: Optional[np.ndarray] = None
    camera_to_world: Optional[np.ndarray] = None
    meta: dict = field(default_factory=dict)

    def pose(self) -> np.ndarray:
        return self.world_to_camera if self.world_to_camera is not None else self.camera_to_world


class CameraProblems(InputError):
    """Every bad camera of a scene, one line each; the message is the first line and a count."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        more = len(self.problems) - 1
        tail = f" (and {more} more camera problems; `gsbench data check` lists them)" if more else ""
        super().__init__(self.problems[0] + tail)


def raw_camera_problems(raw: RawCamera) -> list[str]:
    """The problems of one view, each as '<file>: view <name>: <what is wrong>'."""
    out = [f"{raw.intrinsics_from}: view {raw.name}: {p}"
           for p in intrinsics_problems(raw.K, raw.width, raw.height)]
    out += [f"{raw.pose_from}: view {raw.name}: {p}" for p in pose_problems(raw.pose())]
    return out


def build_cameras(raws: list[RawCamera]) -> list[Camera]:
    """The cameras of `raws` in order, after the shared check; CameraProblems lists every bad view."""
    problems = [p for raw in raws for p in raw_camera_problems(raw)]
    if problems:
        raise CameraProblems(problems)
    cams = []
    for raw in raws:
        w2c = raw.world_to_camera if raw.world_to_camera is not None else np.linalg.inv(raw.camera_to_world)
        cams.append(Camera(raw.K, w2c, raw.width, raw.height, name=raw.name, meta=raw.meta))
    return cams


def outside_paths_allowed() -> bool:
    """Whether the user allowed scene files to name paths outside the scene folder."""
    return os.environ.get(OUTSIDE_PATHS_ENV, "") not in ("", "0")


def inside_scene(root: Path, named: str, source: Path, what: str) -> Path:
    """`root / named`, refused when `named` (written in `source`) leaves the scene folder `root`:
    absolute, or climbing out with `..` (module docstring). `what` says what the path is."""
    root = Path(root)
    if "\x00" in named:
        raise InputError(f"{source}: {what} holds a NUL character")
    path = root / named
    if outside_paths_allowed():
        return path
    base = os.path.normpath(os.path.abspath(root))
    full = os.path.normpath(os.path.abspath(path))
    if full != base and not full.startswith(base.rstrip(os.sep) + os.sep):
        shown = named if len(named) <= 120 else named[:117] + "..."
        raise InputError(f"{source}: {what} {shown!r} lies outside the scene folder {root} "
                         f"(set {OUTSIDE_PATHS_ENV}=1 to allow paths outside it)")
    return path
