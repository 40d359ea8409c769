"""`gsbench publish`: the published results store (results/cpu) and the page generated from it.

    gsbench publish RUNS --to results/cpu          add the finished cells of the claims plan in RUNS
    gsbench publish --status [results/cpu]         current / stale cells per grid
    gsbench publish --page docs/claims.md --from results/cpu [results/gpu] --readme README.md [--check]
    gsbench publish --upgrade [results/cpu]        rewrite cells of an older config layout or store format

RUNS is a `gsbench claims --out` folder. A cell whose config is not the plan's, or that another
numerics version computed, is refused; then nothing is written (docs/publishing.md).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from gsbench.errors import InputError, shorten
from gsbench.grids.store import (
    classify,
    format_store_status,
    plan_for,
    plan_of_store,
    publish,
    read_store,
    repo_store,
    store_backend,
)
from gsbench.grids.store_format import STORE_VERSION
from gsbench.grids.store_upgrade import upgrade_store
from gsbench.store import read_text_bounded


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="?", type=Path, default=None, metavar="RUNS",
                        help="a `gsbench claims --out` folder whose finished cells are added (with --to)")
    parser.add_argument("--to", type=Path, default=None, metavar="STORE", help="the store to add them to")
    parser.add_argument("--status", nargs="?", const="", default=None, metavar="STORE",
                        help="list the store's current and stale cells (default: the repository's results/cpu)")
    parser.add_argument("--upgrade", nargs="?", const="", default=None, metavar="STORE",
                        help="rewrite the store's cells written before a method moved config keys, each under "
                             "the run id today's plan gives it, when its upgraded config is the plan's, and "
                             "cells of an older store format (default: the repository's results/cpu)")
    parser.add_argument("--page", type=Path, default=None, metavar="PAGE",
                        help="generate the claims page (figures in PAGE without .md/) from the store")
    parser.add_argument("--from", dest="source", type=Path, nargs="+", default=None, metavar="STORE",
                        help="the store the page is generated from (default: the repository's results/cpu); "
                             "further stores (another backend's, e.g. results/gpu) add an 'Across backends' "
                             "section comparing their verdicts with the first's")
    parser.add_argument("--readme", type=Path, default=None,
                        help="with --page: regenerate the claims block of this README too")
    parser.add_argument("--check", action="store_true",
                        help="with --page: write nothing; exit 1 and print the lines that differ from the files")
    parser.add_argument("--grids", nargs="+", default=None, metavar="GRID",
                        help="the plan: these grids of the claims plan or grid files (default: the whole plan)")
    parser.add_argument("--quick", action="store_true", help="the plan of `gsbench claims --quick`")


def _store(path, option: str) -> Path:
    """The given store, else the repository's results/cpu."""
    if path:
        return Path(path)
    found = repo_store()
    if found is None:
        raise InputError(f"{option}: no store given and no results/cpu in the gsbench checkout")
    return found


def run(args: argparse.Namespace) -> int:
    modes = [m for m, on in (("RUNS", args.runs is not None), ("--status", args.status is not None),
                             ("--page", args.page is not None), ("--upgrade", args.upgrade is not None)) if on]
    if len(modes) != 1:
        raise InputError("give one of RUNS --to STORE, --status [STORE], --upgrade [STORE] or --page PAGE"
                         + (f" (got {', '.join(modes)})" if modes else ""))
    if args.runs is not None and args.to is None:
        raise InputError("RUNS needs --to STORE (the store to add the cells to)")
    grids = plan_for(args.grids, args.quick)
    if args.runs is not None:
        return _publish(args.runs, args.to, grids)
    if args.status is not None:
        return _status(_store(args.status, "--status"), grids)
    if args.upgrade is not None:
        return _upgrade(_store(args.upgrade, "--upgrade"), grids)
    sources = args.source or [None]
    return _page(args, _store(sources[0], "--from"), grids, sources[1:])


def _publish(runs: Path, store: Path, grids: list) -> int:
    rep = publish(runs, store, grids)
    if rep.refused:
        for run_dir, why in rep.refused:
            print(f"refused: {shorten(run_dir)}: {shorten(why, 400)}")
        raise InputError(f"{shorten(runs)}: {len(rep.refused)} cells refused (listed above); nothing was published")
    for p in rep.written + rep.replaced:
        print(f"published: {p}")
    print(f"gsbench publish: {len(rep.written)} cells added, {len(rep.replaced)} replaced (older numerics version), "
          f"{len(rep.unchanged)} already published, {rep.not_finished} not finished")
    return 0


def _upgrade(store: Path, grids: list) -> int:
    rep = upgrade_store(store, grids)
    if rep.refused:
        for path, why in rep.refused:
            print(f"refused: {shorten(path)}: {shorten(why, 400)}")
        raise InputError(f"{shorten(store)}: {len(rep.refused)} cells refused (listed above); nothing was rewritten")
    for grid, old, new in rep.upgraded:
        print(f"upgraded: {grid}/{old} -> {grid}/{new}")
    print(f"{len(rep.upgraded)} cells upgraded, {rep.current} already in today's layout"
          + (f"; {len(rep.reformatted)} rewritten in store format {STORE_VERSION} (same content)"
             if rep.reformatted else ""))
    return 0


def _status(store: Path, grids: list) -> int:
    cells = read_store(store)
    grids = plan_of_store(grids, cells, store)         # another backend's store: the plan on its backend
    current, stale = classify(cells, grids)
    print(format_store_status(cells, current, stale, grids))
    return 0


def _page(args: argparse.Namespace, store: Path, grids: list, others: list[Path]) -> int:
    from gsbench.reports.claims_page import (  # lazy: start-up
        MAX_PAGE_BYTES,
        README_BEGIN,
        build_page,
        check_page,
        figure_folder,
        readme_with_block,
        shown_figures,
        write_page,
    )
    if args.check and not args.page.is_file():
        raise InputError(f"{shorten(args.page)}: page not found (generate it without --check first)")
    readme = read_text_bounded(args.readme, MAX_PAGE_BYTES, "README") if args.readme is not None else None
    if not args.check:                 # refused before the long part: a page or README gsbench would not write
        shown_figures(args.page)
        if readme is not None:
            readme_with_block(readme, README_BEGIN, shorten(args.readme))
    current, stale = classify(read_store(store), grids)
    other_cells = []
    for p in others:            # another backend's store, against the plan on its backend
        cells = read_store(p)
        other_cells.append((str(p), store_backend(cells, p), classify(cells, plan_of_store(grids, cells, p))[0]))
    page = build_page(current, stale, grids, figure_folder(args.page).name, other_cells)
    if not args.check:
        for p in write_page(page, args.page, args.readme):
            print(f"wrote {p}")
        return 0
    folder = figure_folder(args.page)
    names = [p.name for p in folder.glob("dose_*.png")] if folder.is_dir() else []
    diff = check_page(page, read_text_bounded(args.page, MAX_PAGE_BYTES, "page"), readme, names)
    for line in diff:
        print(line)
    if diff:
        print(f"gsbench publish: {args.page} differs from the store {store}; regenerate it with `gsbench publish "
              f"--page {args.page} --from {store}" + (f" --readme {args.readme}`" if args.readme else "`"))
        return 1
    print(f"gsbench publish: {args.page} matches the store {store}")
    return 0
