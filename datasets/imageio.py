"""Image files: reading as float RGB in [0, 1], header-only size checks, atomic PNG / NPY writes.

Every reader goes through these so that a missing or unreadable file is one InputError naming it.
Every reader applies a file's EXIF orientation, the size from the header and the decoded pixels alike
(a phone's JPEG stored sideways is read upright, as a viewer shows it), so a camera whose size comes
from the header fits the pixels training reads.
"""
from __future__ import annotations

import io
import struct
import warnings
from pathlib import Path

import cv2
import numpy as np

from gsbench.errors import InputError
from gsbench.store import write_bytes_atomic

# Images gsbench decodes: at most 100 megapixels (a 12000 x 8000 photo; the public datasets' largest are
# under 10), checked from the header so that a small file claiming a huge size is never decoded.
MAX_IMAGE_PIXELS = 100_000_000
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
EXIF_ORIENTATION = 0x0112     # the EXIF tag of how the stored pixels are turned for display
IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".JPG", ".JPEG", ".PNG", ".bmp", ".tif", ".tiff", ".exr", ".webp")


def list_images(folder: Path) -> list[Path]:
    """Image files of a folder, sorted by name (the index order of every layout)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: image folder not found")
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix in IMAGE_EXTS and not p.name.startswith("."))
    if not files:
        raise InputError(f"{folder}: no image files")
    return files


def orientation(path: Path) -> int:
    """The EXIF orientation of an image file (1..8: how the stored pixels are turned for display), 1
    when it has none or one outside 1..8, or when PIL cannot read the header (the decoder judges
    the file then). A PNG's eXIf chunk counts when it comes before the pixel data (PIL's lazy open
    reads that far and no further)."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                if im.format == "PNG" and "exif" not in im.info:
                    return 1
                value = im.getexif().get(EXIF_ORIENTATION, 1)
    except Exception:  # PIL raises several types for unreadable files
        return 1
    return value if isinstance(value, int) and 1 <= value <= 8 else 1


def apply_orientation(img: np.ndarray, value: int) -> np.ndarray:
    """The decoded pixels turned as EXIF orientation `value` says (what PIL's ImageOps.exif_transpose
    does): 2 mirrored, 3 turned half round, 4 flipped, 5 transposed, 6 turned a quarter clockwise,
    7 transversed, 8 a quarter counter-clockwise; 5 to 8 swap width and height."""
    turns = {2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1],
             5: lambda a: np.swapaxes(a, 0, 1), 6: lambda a: np.rot90(a, -1),
             7: lambda a: np.swapaxes(a[::-1, ::-1], 0, 1), 8: lambda a: np.rot90(a, 1)}
    return np.ascontiguousarray(turns[value](img)) if value in turns else img


def _stored_size(path: Path) -> tuple[int, int]:
    """(width, height) of the stored pixels from the header (before any EXIF orientation): a
    PNG's IHDR read directly, other formats through PIL's lazy open (its decompression-bomb warning
    silenced: the budget below decides)."""
    from PIL import Image

    with open(path, "rb") as fh:
        head = fh.read(24)
    if head[:8] == PNG_SIGNATURE and head[12:16] == b"IHDR":
        w, h = struct.unpack(">II", head[16:24])
    else:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                with Image.open(path) as im:
                    w, h = int(im.size[0]), int(im.size[1])
        except Image.DecompressionBombError:     # over PIL's own limit, which lies above the budget
            raise InputError(f"{path}: refused: more than {MAX_IMAGE_PIXELS} pixels, the most gsbench "
                             "decodes in one image") from None
    return w, h


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) as displayed (an EXIF orientation of 5 to 8 swaps them), from the file header,
    without decoding the pixels; an image of more than MAX_IMAGE_PIXELS pixels is refused here, before
    anything decodes it."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    try:
        w, h = _stored_size(path)
    except InputError:
        raise
    except Exception as e:  # PIL raises several types for unreadable files
        raise InputError(f"{path}: cannot read image header ({type(e).__name__}: {str(e)[:120]})") from None
    _check_pixels(path, w, h)
    return (h, w) if orientation(path) >= 5 else (w, h)


def _check_pixels(path: Path, w: int, h: int) -> None:
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError(f"{path}: refused: image is {w}x{h}, more than the {MAX_IMAGE_PIXELS} pixels "
                         "gsbench decodes in one image")


def _decode(path: Path, flags: int) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    try:
        _check_pixels(path, *_stored_size(path))       # w * h: the orientation does not matter
    except InputError:
        raise
    except Exception:   # a header PIL cannot read (a corrupt file, EXR): OpenCV's decoder judges it,
        pass            # within its own limit of 2^30 pixels
    data = np.fromfile(str(path), dtype=np.uint8)
    img = cv2.imdecode(data, flags) if data.size else None
    if img is None:
        raise InputError(f"{path}: cannot decode image (corrupt or unsupported format)")
    return apply_orientation(img, orientation(path))     # IMREAD_UNCHANGED leaves EXIF orientation out


def _to_unit(img: np.ndarray, path: Path) -> np.ndarray:
    if img.dtype == np.uint8:
        return img.astype(np.float32) / 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float32) / 65535.0
    if img.dtype in (np.float32, np.float64):
        return np.clip(img.astype(np.float32), 0.0, 1.0)
    raise InputError(f"{path}: unsupported image dtype {img.dtype}")


def read_rgb(path: Path, expect_size: tuple[int, int] | None = None, background: float = 0.0) -> np.ndarray:
    """float32 H x W x 3 in [0, 1]. RGBA is composited over `background` (a grey level).

    `expect_size` = (width, height) of the camera; a different size is an InputError.
    """
    img = _decode(path, cv2.IMREAD_UNCHANGED)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
        img = _to_unit(img, path)
    elif img.shape[2] == 4:
        f = _to_unit(img, path)
        rgb = f[:, :, 2::-1]
        a = f[:, :, 3:4]
        img = rgb * a + background * (1.0 - a)
    elif img.shape[2] == 3:
        img = _to_unit(img[:, :, ::-1], path)
    else:
        raise InputError(f"{path}: unsupported channel count {img.shape[2]}")
    img = np.ascontiguousarray(img, dtype=np.float32)
    if expect_size is not None and (img.shape[1], img.shape[0]) != tuple(expect_size):
        raise InputError(
            f"{path}: image is {img.shape[1]}x{img.shape[0]}, camera says {expect_size[0]}x{expect_size[1]}"
        )
    return img


def read_gray(path: Path, expect_size: tuple[int, int] | None = None) -> np.ndarray:
    """Single-channel image as stored (uint8 / uint16), first channel of colour files."""
    img = _decode(path, cv2.IMREAD_UNCHANGED)
    if img.ndim == 3:
        img = img[:, :, 0] if img.shape[2] != 4 else img[:, :, 0]
    if expect_size is not None and (img.shape[1], img.shape[0]) != tuple(expect_size):
        raise InputError(f"{path}: mask is {img.shape[1]}x{img.shape[0]}, image is {expect_size[0]}x{expect_size[1]}")
    return img


def _put(path: Path, data: bytes, atomic: bool) -> None:
    if atomic:
        write_bytes_atomic(path, data)
    else:  # inside a temporary folder that is renamed into place as a whole
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_bytes(data)


def write_png(path: Path, img: np.ndarray, atomic: bool = True) -> None:
    """PNG write. float RGB in [0, 1] -> 8-bit; uint8 / uint16 arrays written as they are."""
    a = np.asarray(img)
    if a.dtype in (np.float32, np.float64):
        a = np.clip(np.round(a * 255.0), 0, 255).astype(np.uint8)
    if a.ndim == 3:
        a = a[:, :, ::-1]  # RGB -> BGR for OpenCV
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(a))
    if not ok:
        raise OSError(f"{path}: PNG encoding failed")
    _put(path, buf.tobytes(), atomic)


def write_npy(path: Path, arr: np.ndarray, atomic: bool = True) -> None:
    buf = io.BytesIO()
    np.save(buf, np.asarray(arr), allow_pickle=False)
    _put(path, buf.getvalue(), atomic)


def read_npy(path: Path) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        return np.load(path, allow_pickle=False)
    except Exception as e:
        raise InputError(f"{path}: corrupt or unreadable .npy ({type(e).__name__}: {e})") from None
