"""The report's pictures: per scene, for the labelled frames each run saved (gsbench.preview_files), a
grid with one row per method (render, rendered depth, each query's predicted mask over the render)
under a ground-truth row (image, each query's GT mask over it), every tile with its metrics; and
for removal, the render before and after beside the GT without the object.

The report only reads what `gsbench eval` saved; it never loads a model or renders, so what is
shown is what was scored. One run per (scene, method) of the main runs: the lowest seed.
"""
from __future__ import annotations

import html
import io
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
from PIL import Image

from gsbench.errors import InputError
from gsbench.methods.gaussiands.study_table import MAIN_STUDIES
from gsbench.preview_files import FRAME_ARRAYS, REMOVAL_ARRAYS, read_arrays, read_manifest
from gsbench.reports.data import Results, is_null
from gsbench.reports.display import method_label
from gsbench.store import write_bytes_atomic

log = logging.getLogger(__name__)
e = html.escape
PICTURES_DIR = "pictures"
PRED_RGB = (255, 90, 30)    # predicted masks: orange
GT_RGB = (20, 200, 110)     # GT masks: green
NO_SURFACE = (48, 48, 48)   # depth where the render is transparent
DEPTH_CMAP = "turbo"
PROTOCOL_TITLE = {"3dovs": "3D-OVS", "lerf": "LERF-OVS"}
ROW_PX = 960                # width the tiles of one row share on the page (the label column aside)
TILE_PX = (88, 168)         # smallest and largest tile width


def tile_width(columns: int) -> int:
    """Tile width so that a row of `columns` tiles fits the page, within TILE_PX (wider rows scroll)."""
    return max(TILE_PX[0], min(TILE_PX[1], ROW_PX // max(columns, 1) - 6))


def _table(rows: list[str], columns: int) -> str:
    return (f'<div class="tablewrap"><table class="pics" style="--tile: {tile_width(columns)}px">'
            f'{"".join(rows)}</table></div>')


@dataclass
class PictureRun:
    run_id: str
    method: str
    scene: str
    run_dir: Path
    manifest: dict


# ------------------------------------------------------------------ pixels
def overlay(img: np.ndarray, mask: np.ndarray, rgb: tuple[int, int, int]) -> np.ndarray:
    """The image dimmed outside the mask, tinted inside, with the mask's outline drawn in `rgb`."""
    m = np.asarray(mask, bool)
    base = img.astype(np.float32)
    col = np.asarray(rgb, np.float32)
    out = np.where(m[..., None], 0.45 * base + 0.55 * col, 0.4 * base)
    pad = np.pad(m, 1, mode="edge")
    inner = pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:] & m
    out[m & ~inner] = col
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def depth_image(depth: np.ndarray, alpha: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Depth coloured over [lo, hi] (near = blue, far = red); transparent pixels dark grey."""
    from matplotlib import colormaps
    d = np.asarray(depth, np.float64)
    span = hi - lo if hi > lo else 1.0
    t = np.clip(np.nan_to_num((d - lo) / span, nan=1.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    rgb = (colormaps[DEPTH_CMAP](t)[..., :3] * 255.0 + 0.5).astype(np.uint8)
    rgb[np.asarray(alpha) < 128] = NO_SURFACE
    return rgb


def _write_png(path: Path, rgb: np.ndarray) -> None:
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb)).save(buf, format="PNG")
    write_bytes_atomic(path, buf.getvalue())


# ------------------------------------------------------------------ runs
def _slug(s: Any) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(s))


def picture_runs(res: Results, notes: list[str]) -> list[PictureRun]:
    """One finished main run per (scene, method), lowest seed first, with its previews manifest."""
    chosen: dict[tuple[str, str], dict] = {}
    for rid in res.run_ids(study=MAIN_STUDIES):
        row = res.runs.loc[rid]
        if row.get("status") != "done" or is_null(row.get("run_dir")):
            continue
        key = (str(row["scene"]), str(row["method"]))
        seed = row.get("seed")
        rank = (math.inf if is_null(seed) else float(seed), str(rid))
        if key not in chosen or rank < chosen[key]["rank"]:
            chosen[key] = {"rank": rank, "rid": str(rid), "dir": Path(str(row["run_dir"]))}
    out = []
    for (scene, method), c in sorted(chosen.items()):
        try:
            m = read_manifest(c["dir"])
        except (InputError, FileNotFoundError) as err:
            notes.append(f"Pictures: run {c['rid']} ({method} on {scene}) left out: {err}")
            continue
        if m is None:
            notes.append(f"Pictures: run {c['rid']} ({method} on {scene}) has no saved previews "
                         f"(evaluated before they existed, with eval.previews: 0, or its folder is not at "
                         f"{c['dir']}); run `gsbench eval` on it again to add them.")
            continue
        out.append(PictureRun(c["rid"], method, scene, c["dir"], m))
    return out


# ------------------------------------------------------------------ HTML pieces
def _pct(v: Optional[float]) -> str:
    return "n/a" if v is None or is_null(v) else f"{100.0 * float(v):.1f} %"


def _tile(src: Optional[str], lines: list[str], alt: str) -> str:
    if src is None:
        return '<td class="pic-empty">—</td>'
    cap = "".join(f"<div>{x}</div>" for x in lines)
    return f'<td><img src="{e(src)}" alt="{e(alt)}"><div class="pic-m">{cap}</div></td>'


def _query_lines(q: dict, protocol: str) -> list[str]:
    if q.get("iou") is None:
        return [f"IoU n/a ({e(str(q.get('reason') or 'not scored'))})"]
    lines = [f"IoU {_pct(q['iou'])}"]
    if protocol == "3dovs" and q.get("biou") is not None:
        lines.append(f"BIoU {_pct(q['biou'])}")
    if q.get("localized") is not None:
        lines.append("localized ✓" if q["localized"] else "localized ✗")
    return lines


def _mean_iou(queries: list[dict]) -> Optional[float]:
    v = [q["iou"] for q in queries if q.get("iou") is not None]
    return sum(v) / len(v) if v else None


class _Writer:
    """Writes the PNGs of one report under out_dir/pictures and returns their relative paths."""

    def __init__(self, out_dir: Path):
        self.out_dir = out_dir
        self.root = out_dir / PICTURES_DIR
        self.files: list[Path] = []

    def png(self, run: PictureRun, name: str, rgb: np.ndarray) -> str:
        path = self.root / _slug(run.scene) / f"{_slug(run.method)}-{_slug(run.run_id)[:12]}" / f"{_slug(name)}.png"
        _write_png(path, rgb)
        self.files.append(path)
        return path.relative_to(self.out_dir).as_posix()


def _frame_html(w: _Writer, frame: tuple, entries: list[tuple[PictureRun, dict, dict]]) -> str:
    protocol, view, size = frame
    queries = [q["query"] for q in next((en["queries"] for _, en, _ in entries if en["queries"]), [])]
    ranges = [en["depth_range"] for _, en, _ in entries if en.get("depth_range")]
    lo, hi = (min(r[0] for r in ranges), max(r[1] for r in ranges)) if ranges else (0.0, 1.0)
    sets = sorted({en["frame_set"] for _, en, _ in entries})
    head = (f'<h4>{e(PROTOCOL_TITLE.get(protocol, protocol))} · {e(view)} · {e("/".join(sets))} frame · '
            f"scored at {size[0]}×{size[1]}</h4>")
    cols = "<tr><th></th><th>image</th><th>depth</th>" + "".join(f"<th>{e(q)}</th>" for q in queries) + "</tr>"
    # ground truth: from the first run that has masks for every query (all runs share the scene's GT)
    run0, en0, arr0 = next(((r, en, a) for r, en, a in entries if len(en["queries"]) == len(queries)), entries[0])
    gt_row = ["<tr><th>ground truth</th>", _tile(w.png(run0, f"{en0['key']}_gt", arr0["gt"]), ["GT image"], "GT")]
    gd = arr0["gt_depth"]
    if gd.size:
        src = w.png(run0, f"{en0['key']}_gt_depth", depth_image(gd, np.where(gd > 0, 255, 0), lo, hi))
        gt_row.append(_tile(src, ["GT depth"], "GT depth"))
    else:
        gt_row.append('<td class="pic-empty">no GT depth</td>')
    for k, q in enumerate(queries):
        if k < len(arr0["gt_masks"]) and len(en0["queries"]) == len(queries):
            m = arr0["gt_masks"][k]
            src = w.png(run0, f"{en0['key']}_gt_{k}", overlay(arr0["gt"], m, GT_RGB))
            gt_row.append(_tile(src, [f"area {100.0 * m.mean():.1f} %"], f"GT mask {q}"))
        else:
            gt_row.append('<td class="pic-empty">—</td>')
    rows = [cols, "".join(gt_row) + "</tr>"]
    for run, en, arr in entries:
        miou = _mean_iou(en["queries"])
        label = f"<th>{e(method_label(run.method))}"
        if en["queries"]:
            label += f'<div class="pic-m">frame mIoU {_pct(miou)}</div>'
        row = [f"<tr>{label}</th>",
               _tile(w.png(run, f"{en['key']}_render", arr["render"]), [f"PSNR {en['psnr']:.2f} dB"], "render"),
               _tile(w.png(run, f"{en['key']}_depth", depth_image(arr["depth"], arr["alpha"], lo, hi)), [],
                     "rendered depth")]
        if en.get("semantic_reason") or not en["queries"]:
            row.append(f'<td class="pic-na" colspan="{max(len(queries), 1)}">'
                       f"{e(en.get('semantic_reason') or 'no query')}</td>")
        else:
            for k, q in enumerate(en["queries"]):
                src = w.png(run, f"{en['key']}_pred_{k}", overlay(arr["render"], arr["pred"][k], PRED_RGB))
                row.append(_tile(src, _query_lines(q, protocol), f"predicted mask {q['query']}"))
        rows.append("".join(row) + "</tr>")
    foot = (f'<p class="pic-cap">Depth colours: {e(DEPTH_CMAP)} from {lo:.3g} (near, blue) to {hi:.3g} (far, red), '
            "the 2nd-98th percentile of the opaque pixels over these runs; grey = no surface. Orange = predicted "
            "mask over the render, green = GT mask over the image; metrics are those of this frame at the size it "
            "was scored.</p>")
    return f'<div class="pic-frame">{head}{_table(rows, 2 + len(queries))}{foot}</div>'


def _removal_html(w: _Writer, runs: list[PictureRun], reasons: list[tuple[PictureRun, str]]) -> str:
    views: list[tuple[str, str]] = []
    for run in runs:
        for r in run.manifest["removal"]:
            if (r["query"], r["view"]) not in views:
                views.append((r["query"], r["view"]))
    if not views:
        return ""
    objects = sorted({q for q, _ in views})
    head = f"<h4>Object removal: {e(', '.join(objects))} removed by its text query (held-out views)</h4>"
    cols = ["<tr><th></th>"] + [f'<th colspan="3">{e(v)} · remove “{e(q)}”</th>' for q, v in views] + ["</tr>"]
    sub = ["<tr><th></th>"] + ["<th>before</th><th>after</th><th>GT without it</th>" for _ in views] + ["</tr>"]
    rows = ["".join(cols), "".join(sub)]
    for run in runs:
        by = {(r["query"], r["view"]): r for r in run.manifest["removal"]}
        if not by:
            continue
        row = [f"<tr><th>{e(method_label(run.method))}</th>"]
        for q, v in views:
            r = by.get((q, v))
            if r is None:
                row.append('<td class="pic-na" colspan="3">not saved for this run</td>')
                continue
            try:
                a = read_arrays(run.run_dir, r, REMOVAL_ARRAYS)
            except InputError as err:
                row.append(f'<td class="pic-na" colspan="3">{e(str(err))}</td>')
                continue
            row.append(_tile(w.png(run, f"{r['key']}_before", a["before"]), ["render"], "before removal"))
            ps = "n/a" if r.get("psnr_outside") is None else f"{r['psnr_outside']:.2f} dB"
            row.append(_tile(w.png(run, f"{r['key']}_after", a["after"]),
                             [f"residual {_pct(r['residual'])}", f"PSNR outside {ps}",
                              f"{int(r['n_pruned'])} Gaussians pruned"], "after removal"))
            row.append(_tile(w.png(run, f"{r['key']}_gt_after", overlay(a["gt_after"], a["object"], GT_RGB)),
                             ["object outlined"], "GT without the object"))
        rows.append("".join(row) + "</tr>")
    missing = "".join(f"<li>{e(method_label(r.method))}: {e(why)}</li>" for r, why in reasons)
    foot = ('<p class="pic-cap">Residual = share of the object\'s pixels whose colour after removal differs from the '
            "GT without it by more than 0.1; PSNR outside = PSNR of the other pixels (the metric ids of results.json)."
            "</p>" + (f'<ul class="pic-cap">{missing}</ul>' if missing else ""))
    return f'<div class="pic-frame">{head}{_table(rows, 3 * len(views))}{foot}</div>'


def _provenance(runs: list[PictureRun]) -> str:
    items = []
    for r in runs:
        m = r.manifest
        prov = ", ".join(f"{k}={v}" for k, v in sorted((m.get("providers") or {}).items()) if v)
        items.append(f"<li><strong>{e(method_label(r.method))}</strong>: run <code>{e(r.run_id)}</code>, backend "
                     f"{e(str(m.get('backend')))}, query mode {e(str(m.get('query_mode')))}"
                     + (f", providers {e(prov)}" if prov else "") + "</li>")
    return f'<ul class="pic-cap">{"".join(items)}</ul>'


def pictures_html(res: Results, out_dir: Path, notes: list[str]) -> tuple[str, list[Path]]:
    """The pictures section's HTML and the PNGs it placed under out_dir (a new report folder, so no
    picture of a run that is gone survives); '' when no main run saved previews."""
    runs = picture_runs(res, notes)
    if not runs:
        return "", []
    w = _Writer(out_dir)
    parts = ['<p class="meta">What the evaluation saved for two labelled frames per protocol (held-out frames '
             "first) and for object removal, one run per scene and method (the lowest seed). Tiles are shrunk "
             "for display; the metrics under them were computed at the scored size.</p>"]
    for scene in sorted({r.scene for r in runs}):
        sruns = [r for r in runs if r.scene == scene]
        parts.append(f"<h3>Scene {e(scene)}</h3>" + _provenance(sruns))
        frames: dict[tuple, list] = {}
        for run in sruns:
            for topic, text in sorted((run.manifest.get("notes") or {}).items()):
                notes.append(f"Pictures: {run.method} on {scene}: {topic}: {text}")
            for en in run.manifest["frames"]:
                key = (en["protocol"], en["view"], tuple(en["scored_size"]))
                try:
                    arr = read_arrays(run.run_dir, en, FRAME_ARRAYS)
                except InputError as err:
                    notes.append(f"Pictures: {err}")
                    continue
                frames.setdefault(key, []).append((run, en, arr))
        for key, entries in frames.items():
            parts.append(_frame_html(w, key, entries))
        reasons = [(r, r.manifest["removal_reason"]) for r in sruns if r.manifest.get("removal_reason")]
        parts.append(_removal_html(w, sruns, reasons))
    return "\n".join(parts), w.files
