"""Hostile inputs: scene folders: cameras, poses, labels, polygons, paths, images (the battery:
gsbench/commands/hostile/__init__.py).

Each corruption edits a copy of the tiny scene (tabletop-small: COLMAP cameras, poses_bounds.npy,
3D-OVS masks, LERF-OVS labels, gsbench_scene.json) and names what the error must say. The battery
trains on it (`gsbench train` must stop with one line); tests/datasets/test_hostile_scenes.py also
runs `gsbench data check` on the same corruptions (a listed problem, exit 1).
"""
from __future__ import annotations

import json
import shutil
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from gsbench.colmap_lib import import_pycolmap
from gsbench.commands.hostile import Hostile, tiny_scene
from gsbench.datasets.colmap import read_colmap
from gsbench.datasets.imageio import EXIF_ORIENTATION

VIEW = "frame_00003.png"         # the view most corruptions break (index 2)
LABEL = Path("label") / "tabletop-small" / "frame_00003.json"
TRAIN_ARGS = ["--method", "vanilla", "--preset", "cpu-small", "--set", "train.iterations=2", "--set",
              "train.eval_every=0", "--no-progress", "--quiet"]


@dataclass(frozen=True)
class Corruption:
    """`corrupt(scene)` edits a scene copy in place; `expect` are substrings of the problem line
    (the file's name, the view, what is wrong)."""
    name: str
    corrupt: Callable[[Path], None]
    expect: tuple[str, ...]


# ------------------------------------------------------------------------------------ cameras
def _colmap(edit: Callable) -> Callable[[Path], None]:
    """A corruption that edits the scene's COLMAP model: `edit(reconstruction, image of VIEW)`."""
    def corrupt(scene: Path) -> None:
        pycolmap = import_pycolmap()  # lazy: only the camera corruptions need it
        model = scene / "sparse" / "0"
        rec = pycolmap.Reconstruction(str(model))
        (image,) = [im for im in rec.images.values() if im.name == VIEW]
        edit(rec, image)
        rec.write_binary(str(model))
    return corrupt


def _set_params(values: list[float]) -> Callable:
    def edit(rec, image) -> None:
        rec.cameras[image.camera_id].params = values
    return edit


def _zero_quaternion(rec, image) -> None:
    pycolmap = import_pycolmap()  # lazy: only the camera corruptions need it
    frame = rec.frames[image.frame_id]
    pose = frame.rig_from_world
    pose.rotation = pycolmap.Rotation3d(np.zeros(4))
    frame.rig_from_world = pose


def _nan_translation(rec, image) -> None:
    frame = rec.frames[image.frame_id]
    pose = frame.rig_from_world
    pose.translation = np.array([0.0, np.nan, 1.0])
    frame.rig_from_world = pose


def _nan_point(rec, image) -> None:
    point = rec.points3D[min(rec.points3D)]
    point.xyz = np.array([np.nan, 0.0, 1.0])


def _image_name(name: str) -> Callable:
    def edit(rec, image) -> None:
        image.name = name
    return edit


def _duplicate_name(rec, image) -> None:
    """A second image named VIEW: the COLMAP model holds two poses for one picture."""
    other = next(im for im in rec.images.values() if im.name != VIEW)
    other.name = VIEW


def _llff(edit: Callable[[np.ndarray], None]) -> Callable[[Path], None]:
    """A corruption of poses_bounds.npy (the poses once sparse/ is gone): `edit(3 x 5 matrix of VIEW)`."""
    def corrupt(scene: Path) -> None:
        shutil.rmtree(scene / "sparse")
        arr = np.load(scene / "poses_bounds.npy")
        m = arr[2, :15].reshape(3, 5)
        edit(m)
        arr[2, :15] = m.ravel()
        np.save(scene / "poses_bounds.npy", arr)
    return corrupt


def _rank2(m: np.ndarray) -> None:
    m[:, 2] = 0.0


def _tiny_rotation(m: np.ndarray) -> None:
    m[:, :3] *= 1e-12


def _mirror(m: np.ndarray) -> None:
    m[:, 0] *= -1.0


def _negative_focal(m: np.ndarray) -> None:
    m[2, 4] = -m[2, 4]


def _inf_position(m: np.ndarray) -> None:
    m[0, 3] = np.inf


def nerf_scene(scene: Path, edit: Callable[[dict], None] = lambda frame: None) -> None:
    """Turn the scene into the nerf layout (transforms.json from its COLMAP cameras, then sparse/ and
    poses_bounds.npy removed) and let `edit` change the frame of VIEW."""
    cams, _, _, _ = read_colmap(scene / "sparse" / "0")
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    frames = []
    for name in sorted(cams):
        c = cams[name]
        frames.append({"file_path": f"images/{name}", "fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy,
                       "w": c.width, "h": c.height, "transform_matrix": (c.camera_to_world @ flip).tolist()})
    edit(frames[2])
    shutil.rmtree(scene / "sparse")
    (scene / "poses_bounds.npy").unlink()
    (scene / "transforms.json").write_text(json.dumps({"frames": frames}))


def _nerf(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    return lambda scene: nerf_scene(scene, edit)


def _singular(frame: dict) -> None:
    m = np.asarray(frame["transform_matrix"])
    m[:3, :3] = 0.0
    frame["transform_matrix"] = m.tolist()


def _absolute_path(frame: dict) -> None:
    frame["file_path"] = "/etc/hostname"


# ------------------------------------------------------------------------------------ labels, paths, images
def _label(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    """A corruption of the LERF label file of VIEW: `edit(document)`."""
    def corrupt(scene: Path) -> None:
        f = scene / LABEL
        d = json.loads(f.read_text())
        edit(d)
        f.write_text(json.dumps(d))
    return corrupt


def _polygon(points: Callable[[], list]) -> Callable[[dict], None]:
    """Replace the first object's polygon by `points()` (made when the case runs, not on import)."""
    def edit(d: dict) -> None:
        d["objects"][0]["segmentation"] = points()
    return edit


def _random_points(n: int, width: float, height: float, as_int: bool = False) -> list:
    pts = np.random.default_rng(0).uniform(0, [width, height], (n, 2))
    return (pts.astype(int) if as_int else np.round(pts, 1)).tolist()


def _five_million_points(scene: Path) -> None:
    """The first object's polygon as 5 million integer points, written as text (40 MB, fast)."""
    f = scene / LABEL
    d = json.loads(f.read_text())
    d["objects"][0]["segmentation"] = "@points@"
    n = 5_000_000
    f.write_text(json.dumps(d).replace('"@points@"', "[" + "[16, 12], " * (n - 1) + "[16, 12]]"))


def _scribble(d: dict) -> None:
    """A self-intersecting polygon within the point limit of a 3200 x 2400 label grid (the image's
    aspect ratio): cheap to read, slow to fill."""
    d["info"]["width"], d["info"]["height"] = 3200, 2400
    d["objects"][0]["segmentation"] = _random_points(15000, 3200, 2400, as_int=True)


def _many_objects(d: dict) -> None:
    d["objects"] = [dict(d["objects"][0]) for _ in range(1001)]


def _huge_label_grid(d: dict) -> None:
    d["info"]["width"], d["info"]["height"] = 40000, 30000


def _class_outside(scene: Path) -> None:
    f = scene / "segmentations" / "classes.txt"
    f.write_text(f.read_text() + "../../outside\n")


def _gt_dir_outside(scene: Path) -> None:
    f = scene / "gsbench_scene.json"
    d = json.loads(f.read_text())
    d["gt_dir"] = str(scene.parent.resolve())
    f.write_text(json.dumps(d))


def png_header(path: Path, width: int, height: int) -> None:
    """A PNG that is only its header (IHDR of width x height, no pixel data): 33 bytes that claim
    any size."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))


def _truncate(path: Path, lose: int = 0) -> None:
    """The file cut short (a download that stopped): its last `lose` bytes gone, or (0) its second
    half; its header still reads."""
    data = path.read_bytes()
    path.write_bytes(data[:len(data) - lose] if lose else data[:len(data) // 2])


JPG = VIEW.replace(".png", ".jpg")


def write_jpeg(path: Path, pixels: np.ndarray, orientation: int = 1, quality: int = 95) -> None:
    """An 8-bit RGB JPEG of `pixels` (H x W x 3), with an EXIF orientation tag when it is not 1."""
    from PIL import Image  # lazy: only the JPEG cases write one

    im = Image.fromarray(pixels)
    exif = Image.Exif()
    if orientation != 1:
        exif[EXIF_ORIENTATION] = orientation
    im.save(path, format="JPEG", quality=quality, exif=exif.tobytes())


def _as_jpeg(scene: Path, pixels: np.ndarray, orientation: int = 1) -> None:
    """VIEW replaced by a JPEG of `pixels`, in gsbench_scene.json's image names too."""
    write_jpeg(scene / "images" / JPG, pixels, orientation)
    (scene / "images" / VIEW).unlink()
    meta = scene / "gsbench_scene.json"
    d = json.loads(meta.read_text())
    d["image_names"] = [JPG if n == VIEW else n for n in d["image_names"]]
    meta.write_text(json.dumps(d))


def _sideways_jpeg(scene: Path, size_in_json: str) -> None:
    """The nerf layout whose VIEW is a JPEG stored turned a quarter counter-clockwise with EXIF
    orientation 6 (shown upright: the 32x24 view), as a phone stores a picture taken upright.
    size_in_json: "none" (no w/h: the size comes from the file), "stored" (w/h of the stored pixels)."""
    from PIL import Image  # lazy: only the JPEG cases read one

    upright = np.asarray(Image.open(scene / "images" / VIEW).convert("RGB"))
    _as_jpeg(scene, np.ascontiguousarray(np.rot90(upright, 1)), orientation=6)

    def edit(frame: dict) -> None:
        frame["file_path"] = f"images/{JPG}"
        if size_in_json == "none":
            del frame["w"], frame["h"]
        else:
            frame["w"], frame["h"] = frame["h"], frame["w"]
    nerf_scene(scene, edit)


def _truncated_jpeg(scene: Path) -> None:
    """The nerf layout whose VIEW is a JPEG cut in half."""
    from PIL import Image  # lazy: only the JPEG cases read one

    _as_jpeg(scene, np.asarray(Image.open(scene / "images" / VIEW).convert("RGB")))
    _truncate(scene / "images" / JPG, lose=40)     # the header (EXIF, tables) is most of a 32x24 JPEG
    nerf_scene(scene, lambda frame: frame.update(file_path=f"images/{JPG}"))


CORRUPTIONS: list[Corruption] = [
    Corruption("colmap-negative-focal", _colmap(_set_params([-30.0, 30.0, 16.0, 12.0])),
               ("cameras.bin", VIEW, "fx=-30 is not positive")),
    Corruption("colmap-zero-focal", _colmap(_set_params([0.0, 30.0, 16.0, 12.0])),
               ("cameras.bin", VIEW, "fx=0 is not positive")),
    Corruption("colmap-nan-intrinsics", _colmap(_set_params([30.0, float("nan"), 16.0, 12.0])),
               ("cameras.bin", VIEW, "NaN or inf")),
    Corruption("colmap-principal-point-outside", _colmap(_set_params([30.0, 30.0, 100.0, 12.0])),
               ("cameras.bin", VIEW, "principal point (100, 12) lies outside the 32x24 image")),
    Corruption("colmap-zero-quaternion", _colmap(_zero_quaternion),
               ("images.bin", VIEW, "not a proper rotation: det 0")),
    Corruption("colmap-nan-translation", _colmap(_nan_translation), ("images.bin", VIEW, "pose holds NaN or inf")),
    Corruption("colmap-nan-sparse-point", _colmap(_nan_point),
               ("points3D.bin", "1 of", "sparse points hold NaN or inf")),
    Corruption("colmap-image-outside", _colmap(_image_name("../../outside.png")),
               ("images.bin", "'images/../../outside.png' lies outside the scene folder",
                "GSBENCH_ALLOW_OUTSIDE_PATHS=1")),
    Corruption("llff-rank2-rotation", _llff(_rank2), ("poses_bounds.npy", VIEW, "not a proper rotation: det 0")),
    Corruption("llff-rotation-scaled-1e-12", _llff(_tiny_rotation),
               ("poses_bounds.npy", VIEW, "not a proper rotation: det 1e-36")),
    Corruption("llff-mirrored-rotation", _llff(_mirror), ("poses_bounds.npy", VIEW, "not a proper rotation: det -1")),
    Corruption("llff-negative-focal", _llff(_negative_focal), ("poses_bounds.npy", VIEW, "is not positive")),
    Corruption("llff-inf-position", _llff(_inf_position), ("poses_bounds.npy", VIEW, "pose holds NaN or inf")),
    Corruption("nerf-singular-rotation", _nerf(_singular), ("transforms.json", VIEW, "not a proper rotation: det 0")),
    Corruption("nerf-absolute-file-path", _nerf(_absolute_path),
               ("transforms.json", "file_path '/etc/hostname' lies outside the scene folder")),
    Corruption("lerf-polygon-20000-points", _label(_polygon(lambda: _random_points(20000, 32, 24))),
               ("frame_00003.json", "object 0", "20000 entries, more than")),
    Corruption("lerf-polygon-5M-points", _five_million_points, ("frame_00003.json", "bytes, more than the 8 MiB")),
    Corruption("lerf-polygon-300-points", _label(_polygon(lambda: _random_points(300, 32, 24))),
               ("frame_00003.json", "polygon 0 has 300 points, more than 224")),
    Corruption("lerf-polygon-far-outside", _label(_polygon(lambda: [[1, 1], [20, 1], [1e6, 5]])),
               ("frame_00003.json", "polygon 0 has a point at (1e+06, 5), outside x -32..64")),
    Corruption("lerf-polygon-scribble", _label(_scribble), ("frame_00003.json", "fill work")),
    Corruption("lerf-1001-objects", _label(_many_objects), ("frame_00003.json", "1001 objects, more than the 1000")),
    Corruption("lerf-label-grid-1.2-gigapixels", _label(_huge_label_grid),
               ("frame_00003.json", "label size 40000x30000 is more than the 100000000 pixels")),
    Corruption("class-name-outside", _class_outside, ("classes.txt", "'../../outside' is not a plain file name")),
    Corruption("gt-dir-outside", _gt_dir_outside, ("gsbench_scene.json", "gt_dir", "lies outside the scene folder")),
    Corruption("image-header-20000x20000", lambda s: png_header(s / "images" / VIEW, 20000, 20000),
               (VIEW, "image is 20000x20000, more than the 100000000 pixels")),
    Corruption("colmap-two-images-one-name", _colmap(_duplicate_name), ("images.bin", "both named", VIEW)),
    Corruption("image-truncated-png", lambda s: _truncate(s / "images" / VIEW), (VIEW, "cannot decode image")),
    Corruption("image-truncated-jpeg", _truncated_jpeg, (JPG, "cannot decode image")),
    Corruption("exif-orientation-6-against-stored-w-h", lambda s: _sideways_jpeg(s, "stored"),
               (JPG, "image is 32x24", "transforms.json says 24x32")),
]


def _train_case(c: Corruption) -> Hostile:
    def build(folder: Path) -> list[str]:
        scene = tiny_scene(folder / "scene")
        c.corrupt(scene)
        return ["train", "--scene", str(scene), "--out", str(folder / "run"), *TRAIN_ARGS]
    return Hostile("data", c.name, build, c.expect)


def _sideways_case(folder: Path) -> list[str]:
    scene = tiny_scene(folder / "scene")
    _sideways_jpeg(scene, "none")
    return ["train", "--scene", str(scene), "--out", str(folder / "run"), *TRAIN_ARGS]


def _trained_upright(folder: Path, code: int, err: str) -> Optional[str]:
    """The sideways JPEG is read upright: its camera is 32x24 like the pixels training reads, and those
    are the view's own (JPEG-close to the PNG it was made from)."""
    from PIL import Image  # lazy: only this check reads one

    from gsbench.datasets import load_scene  # lazy: the check only

    scene = load_scene(folder / "scene")
    i = [Path(p).name for p in scene.image_paths].index(JPG)
    cam, img = scene.cameras[i], scene.image(i)
    if (cam.width, cam.height) != (32, 24) or img.shape != (24, 32, 3):
        return f"camera {cam.width}x{cam.height}, pixels {img.shape[1]}x{img.shape[0]}: expected 32x24 for both"
    stored = np.asarray(Image.open(folder / "scene" / "images" / JPG).convert("RGB"), dtype=np.float32) / 255
    upright = np.rot90(stored, -1)
    err_px = float(np.abs(img - upright).mean())      # two JPEG decoders: close, not always equal
    return None if err_px < 0.02 else f"pixels differ from the stored ones turned upright by {err_px:.3f} on average"


CASES: list[Hostile] = [_train_case(c) for c in CORRUPTIONS] + [
    Hostile("data", "exif-orientation-6-without-w-h trains upright", _sideways_case, exit_code=0,
            check=_trained_upright),
]
