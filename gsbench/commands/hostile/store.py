"""Hostile inputs: the published results store and the pages generated from it (publish, verify, collect).

The store is an owned folder: links in it are refused, never followed; only the parts the store
wrote are pruned; one writer at a time; a write checks everything first and then changes the store
whole or not at all. Every stored number is a finite number or null before anyone computes with it.
`publish --page` writes only its own page or a new file (the rules: docs/publishing.md; the battery:
gsbench/commands/hostile/__init__.py).
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import json
import os
import shutil
from pathlib import Path
from typing import Callable, Optional

import yaml

from gsbench import grids
from gsbench.cli import main
from gsbench.commands.hostile import Hostile, _base_dir
from gsbench.commands.hostile.output import _checks, _kept, _live_lock, _only
from gsbench.grids.executors import SerialExecutor
from gsbench.grids.store_format import SHARED_DIR
from gsbench.reports.claims_page import GENERATED_MARK, README_BEGIN, README_END

GRID = {"study": "tiny-test",
        "base": {"method": "vanilla", "preset": "cpu-small",
                 "set": {"train.iterations": 2, "train.max_width": 32, "train.eval_every": 0, "eval.previews": 0,
                         "eval.fps_warmup": 0, "eval.fps_repeats": 1}},
        "scenes": [{"preset": "tabletop-small", "views": 8, "resolution": [32, 24]}], "seeds": [0],
        "axes": {"train.lambda_dssim": [0.2, 0.0]}}
NOTES = "# my notes\n"
PNG = b"\x89PNG\r\n\x1a\n my picture"


@functools.lru_cache(maxsize=None)
def _published() -> tuple[Path, Path, Path]:
    """(grid file, runs folder, store): a tiny plan of two finished cells, published (read only)."""
    base = _base_dir() / "store_plan"
    grid_file = base / "tiny.yaml"
    base.mkdir()
    grid_file.write_text(yaml.safe_dump(GRID, sort_keys=False))
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        grids.run_grid(grids.load_grid(grid_file), base / "runs", SerialExecutor(progress=False), log=lambda s: None)
        if main(["publish", str(base / "runs"), "--to", str(base / "store"), "--grids", str(grid_file)]) != 0:
            raise RuntimeError("hostile battery: could not publish the tiny plan")
    return grid_file, base / "runs", base / "store"


def _store(folder: Path) -> Path:
    """A copy of the published tiny store at folder/store."""
    shutil.copytree(_published()[2], folder / "store", symlinks=True)
    return folder / "store"


def _cells(store: Path) -> list[Path]:
    return sorted(p for p in store.glob("*/*.json") if p.parent.name != SHARED_DIR)


def _publish(store: Path) -> list[str]:
    grid_file, runs, _ = _published()
    return ["publish", str(runs), "--to", str(store), "--grids", str(grid_file)]


def _with_metric(folder: Path, value_text: str) -> Path:
    """The store with the first cell's psnr replaced by a JSON value written as given."""
    store = _store(folder)
    cell = _cells(store)[0]
    raw = json.loads(cell.read_text())
    raw["results"]["metrics"]["psnr"] = "@VALUE@"
    cell.write_text(json.dumps(raw, indent=1).replace('"@VALUE@"', value_text))
    return store


# ------------------------------------------------------------------ links and the prune
def _shared_elsewhere(folder: Path) -> Path:
    store = _store(folder)
    shutil.move(str(store / SHARED_DIR), str(folder / "elsewhere"))
    (folder / "elsewhere" / "mine.json").write_text('{"mine": true}')
    (store / SHARED_DIR).symlink_to(folder / "elsewhere", target_is_directory=True)
    _cells(store)[0].unlink()                            # so that the publish has a cell to write, then prunes
    return store


def _prune_link(folder: Path) -> list[str]:
    return _publish(_shared_elsewhere(folder))


def _upgrade_link(folder: Path) -> list[str]:
    return ["publish", "--upgrade", str(_shared_elsewhere(folder)), "--grids", str(_published()[0])]


def _users_parts(folder: Path) -> list[str]:
    """A user's mine.json and NOTES.json in _shared, an unused part the store wrote, and a cell to add."""
    store = _store(folder)
    (store / SHARED_DIR / "mine.json").write_text('{"mine": true}')
    (store / SHARED_DIR / "NOTES.json").write_text("[]")
    (store / SHARED_DIR / "44136fa355b3678a.json").write_text("{}")     # sha256("{}")[:16]: unused, the store's
    _cells(store)[0].unlink()
    return _publish(store)


def _link_grid(folder: Path) -> list[str]:
    store = _store(folder)
    grid = _cells(store)[0].parent
    shutil.move(str(grid), str(folder / "grid_elsewhere"))
    grid.symlink_to(folder / "grid_elsewhere", target_is_directory=True)
    return _publish(store)


# ------------------------------------------------------------------ one writer, all or nothing
def _locked(folder: Path) -> list[str]:
    store = _store(folder)
    _live_lock(folder / ".store.writer.lock", "gsbench publish (the other one)")
    _cells(store)[0].unlink()
    return _publish(store)


def _corrupt_other(folder: Path) -> list[str]:
    store = _store(folder)
    _cells(store)[0].unlink()
    (store / "other-grid").mkdir()
    (store / "other-grid" / "0000000000000ccc.json").write_text('{"store_version": 2, "gri')
    return _publish(store)


def _stray_tmp(folder: Path) -> list[str]:
    store = _store(folder)
    cell = _cells(store)[0]
    (cell.parent / f".{cell.name}.x8k2_9ab.tmp").write_text('{"half a cell": ')
    cell.unlink()
    return _publish(store)


def _store_is_a_file(folder: Path) -> list[str]:
    (folder / "store").write_text("not a folder")
    return _publish(folder / "store")


# ------------------------------------------------------------------ numbers
def _huge_check(folder: Path) -> list[str]:
    store = _with_metric(folder, "9" * 401)
    (folder / "claims.md").write_text(f"{GENERATED_MARK} docs/claims.md` -->\n")
    return ["publish", "--page", str(folder / "claims.md"), "--from", str(store), "--grids", str(_published()[0]),
            "--check"]


def _huge_verify(folder: Path) -> list[str]:
    return ["verify", str(_with_metric(folder, "9" * 401)), "--cells", "1"]


def _text_verify(folder: Path) -> list[str]:
    return ["verify", str(_with_metric(folder, '"24.1 dB"')), "--cells", "1"]


def _nan_status(folder: Path) -> list[str]:
    return ["publish", "--status", str(_with_metric(folder, "NaN")), "--grids", str(_published()[0])]


def _huge_collect(folder: Path) -> list[str]:
    run = folder / "runs" / "r1"
    run.mkdir(parents=True)
    (run / "results.json").write_text('{"run_id": "r1", "method": "vanilla", "scene": "s", "metrics": {"psnr": '
                                      + "9" * 401 + "}}")
    return ["collect", str(folder / "runs")]


def _text_in_run(folder: Path) -> list[str]:
    """A run of the plan whose results.json holds a text metric, published into a store lacking its cell."""
    grid_file, runs, _ = _published()
    shutil.copytree(runs, folder / "runs")
    run = sorted(p.parent for p in (folder / "runs").glob("*/results.json"))[0]
    res = json.loads((run / "results.json").read_text())
    res["metrics"]["psnr"] = "24.1 dB"
    (run / "results.json").write_text(json.dumps(res))
    store = _store(folder)
    (store / "tiny" / f"{run.name}.json").unlink()
    return ["publish", str(folder / "runs"), "--to", str(store), "--grids", str(grid_file)]


def _newer_results(folder: Path) -> list[str]:
    store = _store(folder)
    cell = _cells(store)[0]
    raw = json.loads(cell.read_text())
    raw["results"]["results_version"] = 999
    cell.write_text(json.dumps(raw))
    return ["publish", "--status", str(store), "--grids", str(_published()[0])]


def _deep_part(folder: Path) -> list[str]:
    store = _store(folder)
    text = "[" * 100_000 + "]" * 100_000 + "\n"
    h = hashlib.sha256(text.encode()).hexdigest()[:16]
    (store / SHARED_DIR / f"{h}.json").write_text(text)
    cell = _cells(store)[0]
    raw = json.loads(cell.read_text())
    raw["config"]["train"] = {"$shared": h}
    cell.write_text(json.dumps(raw))
    return ["publish", "--status", str(store), "--grids", str(_published()[0])]


def _long_path(folder: Path) -> list[str]:
    deep = folder.joinpath(*(["d" * 120] * 4))
    deep.mkdir(parents=True)
    store = _store(deep)
    _cells(store)[0].write_text('{"store_version": 2, "gri')
    return ["publish", "--status", str(store), "--grids", str(_published()[0])]


# ------------------------------------------------------------------ pages
def _page_notes(folder: Path) -> list[str]:
    (folder / "notes.md").write_text(NOTES)
    (folder / "notes").mkdir()
    (folder / "notes" / "dose_x.png").write_bytes(PNG)
    return ["publish", "--page", str(folder / "notes.md"), "--from", str(_store(folder)), "--grids",
            str(_published()[0])]


def _page_readme(folder: Path) -> list[str]:
    (folder / "README.md").write_text(f"# project\n{README_BEGIN}\n{README_END}\n")
    return ["publish", "--page", str(folder / "README.md"), "--from", str(_store(folder)), "--grids",
            str(_published()[0])]


def _readme_no_markers(folder: Path) -> list[str]:
    (folder / "README.md").write_text(NOTES)
    return ["publish", "--page", str(folder / "claims.md"), "--readme", str(folder / "README.md"), "--from",
            str(_store(folder)), "--grids", str(_published()[0])]


# ------------------------------------------------------------------ checks
def _cells_now(n: int) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        got = len(_cells(folder / "store")) if (folder / "store").is_dir() else 0
        return None if got == n else f"the store holds {got} cells, expected {n}"
    return check


def _missing(rel: str) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        return f"{rel} was written" if os.path.lexists(folder / rel) else None
    return check


def _parts_kept(folder: Path, code: int, err: str) -> Optional[str]:
    shared = folder / "store" / SHARED_DIR
    names = set(os.listdir(shared))
    if not {"mine.json", "NOTES.json"} <= names:
        return f"a user's file in {SHARED_DIR} was deleted: {sorted(names)}"
    return f"the unused part was kept: {sorted(names)}" if "44136fa355b3678a.json" in names else None


def _elsewhere_kept(folder: Path, code: int, err: str) -> Optional[str]:
    got = sorted(os.listdir(folder / "elsewhere"))
    return None if "mine.json" in got and len(got) > 1 else f"the folder _shared links to holds {got}"


def _grid_kept(folder: Path, code: int, err: str) -> Optional[str]:
    n = len(list((folder / "grid_elsewhere").glob("*.json")))
    return None if n == 2 else f"the folder the grid folder links to holds {n} cells, expected 2"


def _alone(folder: Path, code: int, err: str) -> Optional[str]:
    """Nothing left beside the store: no scratch folder, no lock."""
    left = sorted(set(os.listdir(folder)) - {"store"})
    return f"left beside the store: {left}" if left else None


def _no_tmp(folder: Path, code: int, err: str) -> Optional[str]:
    left = [p.name for p in (folder / "store").rglob("*.tmp")]
    return f"stray temporaries left: {left}" if left else None


_NOT_WRITTEN = "nothing was written"
CASES: list[Hostile] = [
    Hostile("store", "publish prunes through a _shared that links elsewhere", _prune_link,
            (f"{SHARED_DIR}: a symbolic link", _NOT_WRITTEN), check=_checks(_elsewhere_kept, _cells_now(1))),
    Hostile("store", "publish --upgrade through a _shared that links elsewhere", _upgrade_link,
            (f"{SHARED_DIR}: a symbolic link",), check=_elsewhere_kept),
    Hostile("store", "publish keeps a user's mine.json and NOTES.json in _shared", _users_parts, exit_code=0,
            check=_checks(_parts_kept, _cells_now(2), _alone)),
    Hostile("store", "publish into a store whose grid folder is a link", _link_grid, ("a symbolic link",),
            check=_grid_kept),
    Hostile("store", "publish while another publish holds the store", _locked,
            ("another process is writing this results store", "pid 1"),
            check=_checks(_cells_now(1), _only(".", {".store.writer.lock", "store"}))),
    Hostile("store", "publish with a corrupt unrelated cell in the store", _corrupt_other,
            ("0000000000000ccc.json", "corrupt or truncated JSON", _NOT_WRITTEN), check=_cells_now(2)),
    Hostile("store", "publish after a killed one left a temporary in the store", _stray_tmp, exit_code=0,
            check=_checks(_no_tmp, _cells_now(2), _alone)),
    Hostile("store", "publish --to a file", _store_is_a_file, ("exists and is not a folder",),
            check=_kept("store", "not a folder")),
    Hostile("store", "a 401-digit integer metric: publish --page --check", _huge_check,
            ("results.metrics.psnr", "integer of 401 digits")),
    Hostile("store", "a 401-digit integer metric: verify", _huge_verify, ("integer of 401 digits",)),
    Hostile("store", "a text metric: verify", _text_verify, ("results.metrics.psnr", "got a str")),
    Hostile("store", "a text metric in a run: publish", _text_in_run, ("1 cells refused", "nothing was published"),
            check=_cells_now(1)),
    Hostile("store", "a NaN metric: publish --status", _nan_status, ("results.metrics.psnr", "not finite")),
    Hostile("store", "a 401-digit integer metric in a run: collect", _huge_collect,
            ("results.json", "integer of 401 digits")),
    Hostile("store", "results version 999 in a published cell", _newer_results, ("results version 999",)),
    Hostile("store", "a shared part 100,000 levels deep named by its hash", _deep_part,
            ("nested deeper than",)),
    Hostile("store", "a store at a path of 500 characters with a corrupt cell", _long_path,
            ("corrupt or truncated JSON",)),
    Hostile("store", "publish --page over a user's notes, pictures beside it", _page_notes,
            ("notes.md: not a page gsbench generated", _NOT_WRITTEN),
            check=_checks(_kept("notes.md", NOTES), _kept("notes/dose_x.png", PNG))),
    Hostile("store", "publish --page README.md (a typo)", _page_readme, ("README.md: not a page gsbench generated",),
            check=_kept("README.md", f"# project\n{README_BEGIN}\n{README_END}\n")),
    Hostile("store", "publish --readme without its claims markers", _readme_no_markers,
            (README_BEGIN, _NOT_WRITTEN), check=_checks(_missing("claims.md"), _kept("README.md", NOTES))),
]
