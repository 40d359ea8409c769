"""The size limits of a LERF-OVS label file, so that reading and filling it stays fast for any
label gsbench accepts.

A label file is drawn on a W x H grid (its `info.width` x `info.height`, else its image's size),
which holds at most `MAX_IMAGE_PIXELS` pixels. On that grid:

- at most `MAX_LABEL_BYTES` of JSON, refused before parsing (the LERF-OVS label files are 10 to
  100 kB; Python's parser takes about 2 s per 8 MiB of short [x, y] lists);
- at most `MAX_OBJECTS` objects and `MAX_POLYGONS` polygons in the file;
- a polygon has at most `POINTS_PER_SIDE * (W + H)` points (twice the grid's perimeter: a traced
  outline visits each border pixel about once);
- every coordinate is finite and lies within one grid size of the grid: x in [-W, 2W], y in [-H, 2H];
- the fill work stays under `MAX_FILL_WORK`. cv2.fillPoly keeps, per pixel row, the list of edges
  crossing that row sorted by x, and re-sorts it row by row; its time grows with the square of
  that count where edges cross each other (a self-intersecting scribble: 20,000 random points take
  10 s on a 32 x 24 grid). The fill work is the sum over polygons and rows of (edges crossing the
  row)^2: a real outline crosses a row a few times (a 1000-row object: about 4e3), and random
  scribbles at the limit, on grids from 32 x 24 to 100 megapixels, filled in under 0.7 s.

`label_problems` checks a parsed file against them; `too_many_points` refuses a huge segmentation
before it is converted to an array.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

MAX_LABEL_BYTES = 8 * 2**20
MAX_OBJECTS = 1000
MAX_POLYGONS = 10_000
POINTS_PER_SIDE = 4
MAX_FILL_WORK = 100_000_000
MAX_CATEGORY_CHARS = 200


def max_points(width: int, height: int) -> int:
    """The most points one polygon may have on a width x height grid."""
    return POINTS_PER_SIDE * (int(width) + int(height))


def too_many_points(path: Path, k: int, n: int, width: int, height: int) -> Optional[str]:
    """Why a segmentation of `n` entries (points or polygons) is refused before conversion, or None."""
    limit = max(max_points(width, height), MAX_POLYGONS)
    if n > limit:
        return (f"{path}: object {k}: 'segmentation' has {n} entries, more than {limit} (a polygon holds at "
                f"most {max_points(width, height)} points on the {width}x{height} label grid)")
    return None


def fill_work(points: np.ndarray) -> int:
    """Sum over pixel rows of (edges of the polygon crossing the row)^2, with the points truncated to
    integers as cv2.fillPoly takes them. Every row between the lowest and the highest point counts at
    least 4 (a closed outline crosses it twice), so computing it costs less than the work it finds."""
    y = np.trunc(np.asarray(points, dtype=np.float64)[:, 1]).astype(np.int64)
    y -= y.min()
    nxt = np.roll(y, -1)
    lo, hi = np.minimum(y, nxt), np.maximum(y, nxt)
    rows = int(y.max()) + 2
    change = np.bincount(lo, minlength=rows) - np.bincount(hi + 1, minlength=rows)
    active = np.cumsum(change)[: rows - 1]
    return int(np.sum(active * active))


def _polygon_problem(where: str, poly: np.ndarray, width: int, height: int) -> Optional[str]:
    limit = max_points(width, height)
    if len(poly) > limit:
        return (f"{where} has {len(poly)} points, more than {limit} ({POINTS_PER_SIDE} x (width + height) of "
                f"the {width}x{height} label grid)")
    if not np.all(np.isfinite(poly)):
        return f"{where} has non-finite coordinates"
    x, y = poly[:, 0], poly[:, 1]
    out = (x < -width) | (x > 2 * width) | (y < -height) | (y > 2 * height)
    if out.any():
        px, py = poly[int(np.argmax(out))]
        return (f"{where} has a point at ({px:.6g}, {py:.6g}), outside x {-width}..{2 * width}, "
                f"y {-height}..{2 * height} (the {width}x{height} label grid and one grid size around it)")
    return None


def label_problems(path: Path, objects: list, width: int, height: int) -> list[str]:
    """Every limit a parsed label file (LabelObject list) breaks on its width x height grid, one line
    each naming the file and the object; the fill work is judged once the polygons are sane."""
    out = []
    if len(objects) > MAX_OBJECTS:
        out.append(f"{path}: {len(objects)} objects, more than the {MAX_OBJECTS} a label file may hold")
    n_polygons = sum(len(o.polygons) for o in objects)
    if n_polygons > MAX_POLYGONS:
        out.append(f"{path}: {n_polygons} polygons, more than the {MAX_POLYGONS} a label file may hold")
    if out:
        return out
    work = 0
    for k, o in enumerate(objects):
        if len(o.category) > MAX_CATEGORY_CHARS:
            out.append(f"{path}: object {k}: category of {len(o.category)} characters, more than "
                       f"{MAX_CATEGORY_CHARS}")
        for j, poly in enumerate(o.polygons):
            problem = _polygon_problem(f"{path}: object {k} ({o.category[:40]!r}): polygon {j}", poly, width, height)
            if problem:
                out.append(problem)
            elif work <= MAX_FILL_WORK:     # past the limit the sum is not needed (nor its cost)
                work += fill_work(poly)
    if not out and work > MAX_FILL_WORK:
        out.append(f"{path}: refused: its polygons cross the pixel rows so often that filling them would be "
                   f"slow (fill work {work:.3g}, at most {MAX_FILL_WORK:.0e}: the sum over polygons and rows of "
                   "the squared number of edges crossing the row; a self-intersecting scribble?)")
    return out
