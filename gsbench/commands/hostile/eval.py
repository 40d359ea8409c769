"""Hostile inputs: predicted masks and the scoring of gsbench eval --masks (the battery:
gsbench/commands/hostile/__init__.py).

Masks in another value convention (0/1, 16-bit, float TIFF, a palette map) must be read right (the
case checks mIoU 1 for predictions equal to the GT) or refused naming the file and its values; sizes
the protocol does not score (1x1, a 16000x12000 PNG) are refused from the header. The empty-class
case checks that empty/empty pairs are scored by the 3D-OVS reference's rule and said so.
"""
from __future__ import annotations

import io
import json
import shutil
import struct
import zlib
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from PIL import Image

from gsbench.commands.hostile import Hostile, tiny_scene

LABELS = Path("label") / "tabletop-small"
FRAME = "frame_00001"


def write_zero_png(path: Path, width: int, height: int) -> None:
    """A valid all-zero 8-bit grey PNG of width x height, written row by row (never held whole):
    16000 x 12000 is a 0.2 MB file that decodes to 192 MB."""
    comp = zlib.compressobj(9)
    row = bytes(width + 1)                          # filter byte 0, then zero pixels
    data = b"".join(comp.compress(row) for _ in range(height)) + comp.flush()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b""))


def _gt_masks(scene: Path) -> dict[str, dict[str, np.ndarray]]:
    """{view folder: {class: bool GT mask}} read with PIL (255 = the class)."""
    out = {}
    for vd in sorted(d for d in (scene / "segmentations").iterdir() if d.is_dir()):
        out[vd.name] = {f.stem: np.asarray(Image.open(f)) == 255 for f in sorted(vd.glob("*.png"))}
    return out


def _ovs_case(encode: Callable[[np.ndarray, Path], None]) -> Callable[[Path], list[str]]:
    """build(): the tiny scene and per-class predictions equal to its GT, written by `encode(mask, path)`."""
    def build(folder: Path) -> list[str]:
        scene = tiny_scene(folder / "scene")
        for view, masks in _gt_masks(scene).items():
            for c, m in masks.items():
                (folder / "pred" / view).mkdir(parents=True, exist_ok=True)
                encode(m, folder / "pred" / view / f"{c}.png")
        return ["eval", "--masks", str(folder / "pred"), "--layout", str(scene), "--protocol", "3dovs",
                "--out", str(folder / "out")]
    return build


def _miou_is(name: str, expected: float) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        res = json.loads((folder / "out" / "results.json").read_text())
        got = res["metrics"][name]
        return None if got is not None and abs(got - expected) < 1e-12 else f"{name} {got}, expected {expected}"
    return check


def _save(mode_of: Callable[[np.ndarray], Image.Image], fmt: str = "PNG") -> Callable[[np.ndarray, Path], None]:
    return lambda m, path: mode_of(m).save(path, format=fmt)


def _palette_map(folder: Path) -> list[str]:
    """A class-index map stored as a palette PNG whose colours are not the indices."""
    scene = tiny_scene(folder / "scene")
    for view, masks in _gt_masks(scene).items():
        index = np.full(next(iter(masks.values())).shape, 255, np.uint8)
        for k, c in enumerate(sorted(masks)):
            index[masks[c]] = k
        im = Image.fromarray(index).convert("P")
        im.putpalette([v for k in range(256) for v in ((k * 37) % 256, (k * 91) % 256, 200)])
        (folder / "pred").mkdir(exist_ok=True)
        im.save(folder / "pred" / f"{view}.png")
    return ["eval", "--masks", str(folder / "pred"), "--layout", str(scene), "--protocol", "3dovs",
            "--out", str(folder / "out")]


def _lerf_case(width: int, height: int) -> Callable[[Path], list[str]]:
    """build(): one all-zero width x height mask for the first query of the tiny scene's first frame."""
    def build(folder: Path) -> list[str]:
        scene = tiny_scene(folder / "scene")
        query = json.loads((scene / LABELS / f"{FRAME}.json").read_text())["objects"][0]["category"]
        write_zero_png(folder / "pred" / FRAME / f"{query}.png", width, height)
        return ["eval", "--masks", str(folder / "pred"), "--layout", str(scene / LABELS), "--protocol", "lerf",
                "--out", str(folder / "out")]
    return build


EXTRA_CLASSES = 992


def _empty_classes(folder: Path) -> list[str]:
    """One view of the tiny scene, its 8 classes predicted exactly, and 992 more classes in
    classes.txt that neither the GT nor the prediction holds (empty mask files on both sides)."""
    scene = tiny_scene(folder / "scene")
    seg = scene / "segmentations"
    for vd in sorted(d for d in seg.iterdir() if d.is_dir())[1:]:
        shutil.rmtree(vd)
    masks = _gt_masks(scene)
    view, gt = next(iter(masks.items()))
    extra = [f"zz_absent_{k:03d}" for k in range(EXTRA_CLASSES)]
    (seg / "classes.txt").write_text("\n".join([*gt, *extra]) + "\n")
    buf = io.BytesIO()
    Image.fromarray(np.zeros(next(iter(gt.values())).shape, np.uint8)).save(buf, format="PNG")
    (folder / "pred" / view).mkdir(parents=True)
    for c, m in gt.items():
        Image.fromarray(m.astype(np.uint8) * 255).save(folder / "pred" / view / f"{c}.png")
    for c in extra:                                 # one encoded empty PNG, written 2 x 992 times
        (seg / view / f"{c}.png").write_bytes(buf.getvalue())
        (folder / "pred" / view / f"{c}.png").write_bytes(buf.getvalue())
    return ["eval", "--masks", str(folder / "pred"), "--layout", str(scene), "--protocol", "3dovs",
            "--out", str(folder / "out")]


def _empty_classes_said(folder: Path, code: int, err: str) -> Optional[str]:
    """The reference's rule (empty/empty = 0): 8 perfect classes of 1000 give mIoU 0.008, and the
    results and the log say why."""
    why = _miou_is("miou_3dovs", 8 / 1000)(folder, code, err)
    if why:
        return why
    note = json.loads((folder / "out" / "results.json").read_text())["notes"].get("3dovs_empty_gt", "")
    if f"{EXTRA_CLASSES} of them an empty prediction" not in note or "1.0000" not in note:
        return f"notes.3dovs_empty_gt does not count the {EXTRA_CLASSES} empty/empty pairs: {note[:200]!r}"
    return None if "empty GT and an empty prediction" in err else "no warning on stderr"


def _gray(values: np.ndarray) -> Callable[[np.ndarray], Image.Image]:
    """mask -> image of `values[0]` where False and `values[1]` where True, in values' dtype."""
    return lambda m: Image.fromarray(np.where(m, values[1], values[0]).astype(values.dtype))


def _colour(m: np.ndarray) -> Image.Image:
    rgb = np.zeros((*m.shape, 3), np.uint8)
    rgb[m] = (255, 0, 0)
    return Image.fromarray(rgb)


def _dotdot_class(folder: Path) -> list[str]:
    """classes.txt naming a class '../../secret': its mask file would lie outside the view folder."""
    scene = tiny_scene(folder / "scene")
    classes = scene / "segmentations" / "classes.txt"
    classes.write_text(classes.read_text() + "../../secret\n")
    (folder / "pred").mkdir()
    return ["eval", "--masks", str(folder / "pred"), "--layout", str(scene), "--protocol", "3dovs",
            "--out", str(folder / "out")]


CASES: list[Hostile] = [
    Hostile("eval", "masks stored 0/1 (8-bit) are read as binary",
            _ovs_case(_save(_gray(np.array([0, 1], np.uint8)))), exit_code=0,
            check=_miou_is("miou_3dovs", 1.0)),
    Hostile("eval", "16-bit masks 0/65535 are read as binary",
            _ovs_case(_save(_gray(np.array([0, 65535], np.uint16)))), exit_code=0,
            check=_miou_is("miou_3dovs", 1.0)),
    Hostile("eval", "16-bit masks 0/1 are read as binary",
            _ovs_case(_save(_gray(np.array([0, 1], np.uint16)))), exit_code=0,
            check=_miou_is("miou_3dovs", 1.0)),
    Hostile("eval", "float TIFF masks 0.0/1.0 are read as binary",
            _ovs_case(_save(_gray(np.array([0.0, 1.0], np.float32)), "TIFF")), exit_code=0,
            check=_miou_is("miou_3dovs", 1.0)),
    Hostile("eval", "float TIFF soft masks 0.0/0.5 are refused with their values",
            _ovs_case(_save(_gray(np.array([0.0, 0.5], np.float32)), "TIFF")),
            expect=(".png", "not a binary mask", "values 0, 0.5")),
    Hostile("eval", "8-bit masks 0/128 are refused with their values",
            _ovs_case(_save(_gray(np.array([0, 128], np.uint8)))), expect=(".png", "values 0, 128")),
    Hostile("eval", "colour masks (channels differ) are refused",
            _ovs_case(_save(_colour)), expect=(".png", "colour image")),
    Hostile("eval", "a palette class-index map is read as its indices",
            _palette_map, exit_code=0, check=_miou_is("miou_3dovs", 1.0)),
    Hostile("eval", "1x1 predictions are refused (size)", _lerf_case(1, 1),
            expect=(".png", "1x1", "too small", "32x24")),
    Hostile("eval", "a 16000x12000 PNG is refused from its header",
            _lerf_case(16000, 12000), expect=(".png", "16000x12000", "larger than", "32x24"), limit_s=10.0),
    Hostile("eval", "a '../' class name in classes.txt is refused (paths stay in the scene)",
            _dotdot_class, expect=("classes.txt", "not a plain file name")),
    Hostile("eval", "1000 classes, 992 empty in GT and prediction: the reference's 0, said",
            _empty_classes, exit_code=0, check=_empty_classes_said),
]
