"""Predicted mask files of `gsbench eval --masks`: the size from the file header before any pixel is
decoded, then the values, so that a mask stored in another convention is read right or refused with
the file's name and what it holds, and never scored as an empty mask.

Size (`check_prediction_size`): a prediction is scored at its own size, which is the GT's size or a
downscale of it of the same aspect ratio, at most `MAX_DOWNSCALE` times smaller per side (the 3D-OVS
reference scores at 1/8 of its images) and never under `MIN_SIDE` pixels a side (a GT side shorter
than that must be matched). Larger, smaller or stretched predictions are refused from the header, so
a huge file is never decoded.

Values (`read_binary_mask`): one channel (colour channels must be equal) holding 0 and one
foreground value, which is 1 or the full scale of the image (255 at 8 bits, 65535 at 16 bits, 1.0
for a float TIFF); an all-zero mask is empty. Anything else (soft masks, {0, 128}, NaN) is refused.
Class-index maps (`read_class_map`): one channel of 8- or 16-bit integers, 255 = no class; a
palette PNG is read as its indices.

EXIF orientation: a file's orientation tag is applied to its size and its pixels alike, with the
datasets' helpers (`orientation`, `apply_orientation`), so a mask stored sideways is scored upright,
as a viewer shows it, exactly as the training images are read.
"""
from __future__ import annotations

import struct
import warnings
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from gsbench.datasets.imageio import apply_orientation, orientation
from gsbench.errors import InputError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
MAX_DOWNSCALE = 8
MIN_SIDE = 8
NO_CLASS = 255
# PIL mode -> the full-scale value of a binary mask in it (the foreground may also be 1)
FULL_SCALE = {"1": 1, "L": 255, "LA": 255, "P": 255, "RGB": 255, "RGBA": 255,
              "I;16": 65535, "I;16B": 65535, "I;16L": 65535, "I": 65535, "F": 1.0}
INDEX_MODES = ("1", "L", "P", "I;16", "I;16B", "I;16L", "I")
BIT_DEPTH = {"b1": "1-bit", "u1": "8-bit", "u2": "16-bit", "i4": "32-bit integer", "f4": "float"}


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) as displayed (an EXIF orientation of 5 to 8 swaps them), read from the file
    header without decoding a pixel."""
    w, h = _stored_size(path)
    return (h, w) if orientation(path) >= 5 else (w, h)


def _stored_size(path: Path) -> tuple[int, int]:
    """(width, height) of the stored pixels from the header. PNG's IHDR is read directly (PIL's open
    refuses very large images without saying their size); other formats (a float mask is a TIFF)
    through PIL's lazy open."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError as e:
        raise InputError(f"{path}: cannot read the file ({e.strerror})") from None
    if head[:8] == PNG_SIGNATURE:
        if len(head) < 24 or head[12:16] != b"IHDR":
            raise InputError(f"{path}: truncated PNG (no IHDR header)")
        return struct.unpack(">II", head[16:24])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                return im.size
    except Image.DecompressionBombError:
        raise InputError(f"{path}: image of more than {2 * Image.MAX_IMAGE_PIXELS} pixels, "
                         "refused before decoding") from None
    except (UnidentifiedImageError, OSError):
        raise InputError(f"{path}: not an image file (neither PNG nor a format PIL reads)") from None


def check_prediction_size(path: Path, pw: int, ph: int, w: int, h: int, what: str) -> None:
    """Refuse a prediction size the protocol does not score against a w x h GT (module docstring).
    One pixel of rounding per side is allowed in the aspect ratio (a floor or round of w*s x h*s)."""
    if pw > w or ph > h:
        raise InputError(f"{path}: prediction size {pw}x{ph} is larger than {what} ({w}x{h}); "
                         "predictions are scored at the GT's size or a downscale of it")
    least_w, least_h = (min(n, max(n // MAX_DOWNSCALE, MIN_SIDE)) for n in (w, h))
    if pw < least_w or ph < least_h:
        raise InputError(f"{path}: prediction size {pw}x{ph} is too small for {what} ({w}x{h}; the smallest "
                         f"scored size is {least_w}x{least_h}: 1/{MAX_DOWNSCALE}, at least {MIN_SIDE} px a side)")
    if abs(pw * h - ph * w) > w + h:
        raise InputError(f"{path}: prediction size {pw}x{ph} has another aspect ratio than {what} ({w}x{h})")


def _decode(path: Path, modes, palette_colours: bool) -> tuple[np.ndarray, str]:
    """The pixels (H, W[, C]) and PIL mode of an image whose mode is in `modes`; a palette image as
    its colours (palette_colours) or as its indices, turned as its EXIF orientation says."""
    try:
        with Image.open(path) as im:
            if im.mode not in modes:
                raise InputError(f"{path}: a {im.mode} image (PIL mode), not a mask: "
                                 "masks are one channel of 1, 8 or 16 bits (or a float TIFF)")
            mode = im.mode
            a = np.asarray(im.convert("RGB") if mode == "P" and palette_colours else im)
    except (UnidentifiedImageError, OSError) as e:
        raise InputError(f"{path}: cannot decode the image ({type(e).__name__})") from None
    return apply_orientation(a, orientation(path)), mode


def _values_text(a: np.ndarray) -> str:
    """A short description of the values an image holds (for error lines)."""
    vals = np.unique(a)
    if vals.size <= 4:
        return "values " + ", ".join(f"{v:g}" for v in vals.astype(np.float64))
    return f"{vals.size} distinct values from {float(vals[0]):g} to {float(vals[-1]):g}"


def read_binary_mask(path: Path) -> np.ndarray:
    """A binary mask file -> (H, W) bool; InputError naming the file and its values otherwise."""
    a, mode = _decode(path, FULL_SCALE, palette_colours=True)
    if a.ndim == 3:
        if a.shape[2] >= 3 and not (np.array_equal(a[..., 0], a[..., 1]) and np.array_equal(a[..., 0], a[..., 2])):
            raise InputError(f"{path}: a colour image (its channels differ); a mask has one channel")
        a = a[..., 0]
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise InputError(f"{path}: the mask holds NaN or inf")
    full = FULL_SCALE[mode]
    hi = a.max()
    foreground = a == hi
    if hi == 0 and a.min() == 0:
        return np.zeros(a.shape, bool)
    if np.any(~foreground & (a != 0)) or hi not in (1, full):
        kind = BIT_DEPTH.get(a.dtype.kind + str(a.dtype.itemsize), str(a.dtype))
        allowed = "0 and 1" if full == 1 else f"0 and {full:g}, or 0 and 1"
        raise InputError(f"{path}: not a binary mask: {_values_text(a)} ({kind} image; a mask holds {allowed})")
    return foreground


def read_class_map(path: Path, n_classes: int) -> np.ndarray:
    """A class-index map file -> (H, W) int32, -1 where it says no class (255)."""
    if n_classes > NO_CLASS:
        raise InputError(f"{path}: a class-index map names classes 0 to {NO_CLASS - 1} ({NO_CLASS} = none), but "
                         f"the scene has {n_classes} classes: write one <class>.png per class instead")
    a, _ = _decode(path, INDEX_MODES, palette_colours=False)
    a = a.astype(np.int32)
    bad = ((a >= n_classes) & (a != NO_CLASS)) | (a < 0)
    if np.any(bad):
        raise InputError(f"{path}: class index {int(a[bad].max())} >= {n_classes} ({NO_CLASS} = none)")
    return np.where(a == NO_CLASS, -1, a)
