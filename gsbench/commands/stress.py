"""`gsbench stress`: the numerical stress battery (see the gsbench/stress package)."""
from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

from tqdm import tqdm

from gsbench.outdir import OwnedFolder, refuse_foreign
from gsbench.store import write_text_atomic


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for stress.csv and stress.md: new, empty or an earlier one (default: print only)")
    parser.add_argument("--component", action="append", default=None,
                        help="only components whose name starts with this (repeatable), e.g. render:cpu, loss, metrics")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")


def format_table(rows: list[dict]) -> str:
    cols = ["component", "case", "max_abs", "max_rel", "finite_out", "finite_grad", "pass", "note"]

    def fmt(v):
        if v is None:
            return "-"
        if isinstance(v, bool):
            return "yes" if v else "NO"
        if isinstance(v, float):
            return f"{v:.2e}"
        return str(v)

    body = [[fmt(r[c]) if c != "pass" else ("pass" if r[c] else "FAIL") for c in cols] for r in rows]
    widths = [max(len(c), *(len(b[i]) for b in body)) if body else len(c) for i, c in enumerate(cols)]
    lines = ["| " + " | ".join(c.ljust(w) for c, w in zip(cols, widths)) + " |",
             "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += ["| " + " | ".join(v.ljust(w) for v, w in zip(b, widths)) + " |" for b in body]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from gsbench.commands.hostile import hostile_cases  # lazy: start-up (cli loads all commands)
    from gsbench.stress import all_cases, run_case  # lazy: start-up (cli loads all commands)

    cases, skipped = all_cases(args.component)
    hostile = hostile_cases()
    if args.component:
        hostile = [c for c in hostile if any(c.component.startswith(p) for p in args.component)]
    cases += hostile
    if args.list:
        for c in cases:
            print(f"{c.component}\t{c.name}")
        return 0
    if args.out is not None:      # a folder of someone else's is refused before the battery runs
        refuse_foreign(args.out, "gsbench stress", force_hint=False)
    results = [run_case(c) for c in tqdm(cases, desc="stress", unit="case", file=sys.stderr)]
    rows = [r.row() for r in results + skipped]
    print(format_table(rows))
    n_fail = sum(not r["pass"] for r in rows)
    print(f"\n{len(rows) - n_fail} passed, {n_fail} failed")
    if args.out is not None:
        buf = io.StringIO()
        pd.DataFrame(rows).to_csv(buf, index=False)
        with OwnedFolder(args.out, "gsbench stress", force_hint=False, what="stress folder") as folder:
            assert folder.staging is not None
            write_text_atomic(folder.staging / "stress.csv", buf.getvalue())
            write_text_atomic(folder.staging / "stress.md", format_table(rows) + "\n")
            folder.commit()
        print(f"wrote {args.out / 'stress.csv'}")
    return 1 if n_fail else 0
