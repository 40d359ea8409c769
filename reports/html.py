"""The static index.html: every table (as HTML), every plot (PNG by relative path), notes on what
is absent, and a provenance section (providers, backends, protocols, metric implementations,
machines, versions) so a reader knows what produced the numbers.
"""
from __future__ import annotations

import html
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from string import Template

import pandas as pd

from gsbench.reports.data import Results, is_null
from gsbench.reports.table import Table
from gsbench.store import write_text_atomic

e = html.escape


@dataclass
class Section:
    id: str
    title: str
    tables: list[Table] = field(default_factory=list)
    figures: list[tuple[str, str]] = field(default_factory=list)  # (relative path, caption)
    notes: list[str] = field(default_factory=list)
    blocks: list[str] = field(default_factory=list)  # ready HTML (the pictures), placed after the figures


def _template() -> Template:
    text = resources.files("gsbench.reports").joinpath("templates/index.html").read_text(encoding="utf-8")
    return Template(text)


def _counts_table(df: pd.DataFrame, cols: list[str], caption: str) -> str:
    """Distinct combinations of `cols` over runs, with the number of runs."""
    cols = [c for c in cols if c in df.columns]
    if not cols:
        return f"<p>{e(caption)}: not recorded.</p>"
    runs = df.drop_duplicates("run_id")[cols].astype(object)
    runs = runs.where(runs.notna(), "—")
    counts = runs.astype(str).value_counts(dropna=False).reset_index()
    counts.columns = list(cols) + ["runs"]
    head = "".join(f"<th>{e(c)}</th>" for c in counts.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{e(str(v))}</td>" for v in row) + "</tr>" for row in counts.itertuples(index=False)
    )
    return (f'<div class="tablewrap"><table class="prov"><caption>{e(caption)}</caption><thead><tr>{head}</tr></thead>'
            f'<tbody>{body}</tbody></table></div>')


def _impl_table(df: pd.DataFrame) -> str:
    rows = df[df["metric"].notna() & df["value"].notna()]  # only ids that produced a number
    rows = (
        rows[rows["source"].astype(object).where(rows["source"].notna(), "") == "metrics"] if "source" in rows else rows
    )
    impl: dict[str, set[str]] = {}
    for m, i in zip(rows["metric"], rows["metric_impl"]):
        impl.setdefault(str(m), set()).add("—" if is_null(i) else str(i))
    body = "".join(f"<tr><td>{e(m)}</td><td>{e(', '.join(sorted(v)))}</td></tr>" for m, v in sorted(impl.items()))
    return (
        '<div class="tablewrap"><table class="prov"><caption>'
        "Metric implementations (metric_impl ids recorded in results.json; "
        "a metric with several ids was computed by different implementations)</caption>"
        f"<thead><tr><th>metric</th><th>metric_impl</th></tr></thead><tbody>{body}</tbody></table></div>"
    )


def provenance_html(res: Results, writer_version: str) -> str:
    df = res.df
    prov = [c for c in df.columns if c.startswith("provider.")]
    mach = [c for c in df.columns if c.startswith(("machine.", "env."))]
    parts = [
        "<p>Every number above comes from the results.json files listed in the collected table; "
        "numbers from different evaluation protocols are not comparable and are never averaged together.</p>",
        _counts_table(df, prov, "Prior providers (depth, masks, features) per run"),
        _counts_table(df, ["backend"], "Render backends"),
        _counts_table(
            df,
            ["protocol", "protocols"],
            "Evaluation protocols (primary protocol of the run, and every protocol it was evaluated under)",
        ),
        _impl_table(df),
        _counts_table(
            df,
            mach,
            "Machines and versions that produced the results (results.json `machine`; env.* from the run's env.json)",
        )
        if mach
        else "<p>Machine: not recorded in results.json.</p>",
        f'<p class="meta">Report written by gsbench {e(writer_version)}.</p>',
    ]
    return "\n".join(parts)


def runs_html(res: Results) -> str:
    df = res.runs
    study = df["study"].map(lambda s: "(standalone)" if is_null(s) else str(s))
    counts = pd.crosstab(study, df["status"].map(str))
    head = "<th>study</th>" + "".join(f"<th>{e(c)}</th>" for c in counts.columns)
    body = "".join(f"<tr><td>{e(i)}</td>" + "".join(f"<td class=\"num\">{int(v)}</td>" for v in row) + "</tr>"
                   for i, row in zip(counts.index, counts.values))
    out = [
        f'<table class="prov"><caption>Runs by study and status</caption><thead><tr>{head}</tr></thead>'
        f"<tbody>{body}</tbody></table>"
    ]
    bad = df[df["status"] != "done"]
    if len(bad):
        items = "".join(
            f"<li><code>{e(str(r['run_dir']))}</code>: {e(str(r['status']))}</li>" for _, r in bad.iterrows()
        )
        out.append(f"<p>Runs not finished (their values show as n/a):</p><ul>{items}</ul>")
    if "dropped" in df.columns:
        dropped = [(r["run_dir"], r["dropped"]) for _, r in df.iterrows()
                   if not is_null(r["dropped"]) and str(r["dropped"]).strip()]
        if dropped:
            items = "".join(f"<li><code>{e(str(d))}</code>: {e(str(t))}</li>" for d, t in dropped)
            out.append("<p>Settings the resolver dropped (the run trained without them; grid rows that became "
                       f"the same configuration are merged in the tables):</p><ul>{items}</ul>")
        else:
            out.append("<p>The resolver dropped no setting in any run.</p>")
    else:
        out.append("<p>Dropped settings: not recorded in the collected table (no 'dropped' column).</p>")
    return "\n".join(out)


def write_index(path: Path, title: str, source: str, generated: str, sections: list[Section],
                notes: list[str], res: Results, links: list[tuple[str, str]], writer_version: str) -> Path:

    body = [f"<h1>{e(title)}</h1>",
            f'<p class="meta">Source: <code>{e(source)}</code> · {len(res.runs)} runs · generated {e(generated)}</p>']
    body.append(
        "<nav><h2>Contents</h2><ul>"
        + "".join(f'<li><a href="#{e(s.id)}">{e(s.title)}</a></li>' for s in sections)
        + '<li><a href="#notes">Notes</a></li><li><a href="#provenance">Provenance</a></li></ul></nav>'
    )
    body.append(
        '<p class="meta">Tables: best value per compared group in <strong>bold</strong>; '
        "“n/a (reason)” = could not be computed; “–” = no run; mean ± sample std (n = seeds) when a cell has several "
        "seeds. Difference tables: row minus the study's reference row [95 % interval] (n); * = the interval "
        "excludes zero. "
        "Downloads: " + " · ".join(f'<a href="{e(h)}">{e(t)}</a>' for h, t in links) + "</p>"
    )
    for s in sections:
        body.append(f'<section id="{e(s.id)}"><h2>{e(s.title)}</h2>')
        for t in s.tables:
            body.append(f"<h3>{e(t.title)}</h3>")
            body.append(f'<div class="tablewrap">{t.to_html()}</div>')
        for src, cap in s.figures:
            body.append(f'<figure><img src="{e(src)}" alt="{e(cap)}"><figcaption>{e(cap)}</figcaption></figure>')
        body += s.blocks
        for n in s.notes:
            body.append(f'<p class="note">{e(n)}</p>')
        body.append("</section>")
    body.append('<section id="notes"><h2>Notes</h2>')
    body.append("<ul>" + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ul>" if notes else "<p>None.</p>")
    body.append(runs_html(res))
    body.append("</section>")
    body.append(f'<section id="provenance"><h2>Provenance</h2>{provenance_html(res, writer_version)}</section>')
    page = _template().safe_substitute(title=e(title), body="\n".join(body))
    write_text_atomic(path, page)
    return path
