"""A small table model and its three renderings (Markdown, LaTeX, HTML).

Why a model: the same table goes to three formats, and bold marks / "n/a (reason)" / mean +- std
must be decided once. Bold = the best displayed value among the compared alternatives; it is
written as **x** in Markdown, \\textbf{x} in LaTeX and <strong> in HTML (nothing else is bold:
section rows are italic).
"""
from __future__ import annotations

import html
import math
from dataclasses import dataclass, field

NO_RUN = "–"  # no run exists for this cell (as the paper's "--")
CHECK = "✓"


@dataclass
class Cell:
    """One value in display units: mean (+- sample std and the number of seeds when n > 1), or n/a
    with a reason."""
    mean: float | None = None
    std: float | None = None
    n: int = 0               # runs (seeds) with a value
    total: int = 0           # runs in the cell
    reason: str | None = None
    decimals: int = 2
    check: bool | None = None  # a check-mark cell (loss subsets); None = numeric cell
    text: str | None = None    # literal text (e.g. a row label inside the grid)
    bold: bool = False

    def rounded(self) -> float | None:
        if self.mean is None or not math.isfinite(self.mean):
            return None
        return round(self.mean, self.decimals)

    def plain(self, pm: str = "±") -> str:
        if self.check is not None:
            return CHECK if self.check else ""
        if self.text is not None:
            return self.text
        if self.mean is None or not math.isfinite(self.mean):
            return f"n/a ({self.reason})" if self.reason else NO_RUN
        s = f"{self.mean:.{self.decimals}f}"
        if self.n > 1 and self.std is not None and math.isfinite(self.std):
            s += f" {pm} {self.std:.{self.decimals}f}"
        if self.total > self.n:
            s += f" (n={self.n}/{self.total})"
        elif self.n > 1:  # several seeds: say how many the mean and std are over
            s += f" (n={self.n})"
        return s


@dataclass
class Column:
    metric: str              # metric key (bold groups compare columns with the same metric)
    label: str               # plain header
    latex: str               # LaTeX header
    better: str | None = None
    group: str | None = None  # upper header (method or scene), None = no upper header
    group_latex: str | None = None

    def header(self) -> str:
        arrow = {"higher": " ↑", "lower": " ↓"}.get(self.better or "", "")
        return self.label + arrow

    def header_latex(self) -> str:
        arrow = {"higher": "$\\uparrow$", "lower": "$\\downarrow$"}.get(self.better or "", "")
        return self.latex + arrow


@dataclass
class Row:
    labels: list[str]
    cells: list[Cell]
    section: str | None = None
    label_checks: list[bool] | None = None  # label columns rendered as check marks


@dataclass
class Table:
    id: str
    title: str
    caption: str
    label_headers: list[str]
    columns: list[Column]
    rows: list[Row] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    label_is_check: bool = False  # the label columns are check marks (loss subsets)
    label_headers_latex: list[str] | None = None  # LaTeX source of the label headers (else escaped)
    section: str | None = None  # report section (HTML) when not implied by the id

    # ---------------------------------------------------------------- bold marks
    def bold_best_per_column(self) -> None:
        """Best value of every column, compared among the rows of one section."""
        sections: dict[str | None, list[int]] = {}
        for i, r in enumerate(self.rows):
            sections.setdefault(r.section, []).append(i)
        for j, col in enumerate(self.columns):
            for idx in sections.values():
                _mark([self.rows[i].cells[j] for i in idx], col.better)

    def bold_best_per_row(self) -> None:
        """Best value among the columns of one row that hold the same metric (methods as columns)."""
        by_metric: dict[str, list[int]] = {}
        for j, col in enumerate(self.columns):
            by_metric.setdefault(col.metric, []).append(j)
        for r in self.rows:
            for js in by_metric.values():
                _mark([r.cells[j] for j in js], self.columns[js[0]].better)

    # ---------------------------------------------------------------- renderers
    def _has_groups(self) -> bool:
        return any(c.group for c in self.columns)

    def _group_spans(self) -> list[tuple[str | None, int, str | None]]:
        spans: list[list] = []
        for c in self.columns:
            if spans and spans[-1][0] == c.group:
                spans[-1][1] += 1
            else:
                spans.append([c.group, 1, c.group_latex])
        return [tuple(s) for s in spans]  # type: ignore[misc]

    def to_markdown(self) -> str:
        heads = list(self.label_headers)
        for c in self.columns:
            heads.append(f"{c.group} · {c.header()}" if c.group else c.header())
        lines = [f"### {self.title}", "", _md_escape(self.caption), ""]
        lines.append("| " + " | ".join(_md_escape(h) for h in heads) + " |")
        lines.append("|" + "|".join([":--"] * len(self.label_headers) + ["--:"] * len(self.columns)) + "|")
        current = object()
        for r in self.rows:
            if r.section != current and r.section is not None:
                lines.append("| " + " | ".join([f"*{_md_escape(r.section)}*"] + [""] * (len(heads) - 1)) + " |")
            current = r.section
            labels = (
                [(CHECK if v else "") for v in r.label_checks]
                if r.label_checks is not None
                else [_md_escape(x) for x in r.labels]
            )
            cells = []
            for c in r.cells:
                s = _md_escape(c.plain())
                cells.append(f"**{s}**" if c.bold else s)
            lines.append("| " + " | ".join(labels + cells) + " |")
        for n in self.notes:
            lines.append("")
            lines.append(f"> {_md_escape(n)}")
        return "\n".join(lines) + "\n"

    def to_latex(self) -> str:
        nl = len(self.label_headers)
        spans = self._group_spans()
        colspec = "c" * nl if self.label_is_check else "l" * nl
        for _g, k, _ in spans:
            colspec += "|" + "c" * k
        ncols = nl + len(self.columns)
        out = ["\\begin{table}[ht]", "\\centering",
               f"\\caption{{{_tex(self.caption)}}}", f"\\label{{tab:{self.id}}}",
               "\\resizebox{\\linewidth}{!}{%",
               f"\\begin{{tabular}}{{{colspec}}}", "\\toprule"]
        if self._has_groups():
            parts = [""] * nl
            for i, (g, k, gl) in enumerate(spans):
                sep = "|" if i < len(spans) - 1 else ""
                parts.append(f"\\multicolumn{{{k}}}{{c{sep}}}{{\\textit{{{gl if gl else _tex(g or '')}}}}}")
            out.append(" & ".join(parts) + " \\\\")
        heads = list(self.label_headers_latex) if self.label_headers_latex else [_tex(h) for h in self.label_headers]
        heads += [c.header_latex() for c in self.columns]
        out.append(" & ".join(heads) + " \\\\")
        out.append("\\midrule")
        current = object()
        for r in self.rows:
            if r.section != current and r.section is not None:
                out.append(f"\\multicolumn{{{ncols}}}{{l}}{{\\textit{{{_tex(r.section)}}}}} \\\\")
            current = r.section
            labels = (
                [("\\checkmark" if v else "") for v in r.label_checks]
                if r.label_checks is not None
                else [_tex(x) for x in r.labels]
            )
            cells = []
            for c in r.cells:
                if c.check is not None:
                    s = "\\checkmark" if c.check else ""
                else:
                    s = _tex(c.plain(pm="\x00"))
                    s = s.replace("\x00", "$\\pm$")
                cells.append(f"\\textbf{{{s}}}" if c.bold else s)
            out.append(" & ".join(labels + cells) + " \\\\")
        out += ["\\bottomrule", "\\end{tabular}", "}", "\\end{table}"]
        for n in self.notes:
            out.insert(0, f"% note: {n}")
        return "\n".join(out) + "\n"

    def to_html(self) -> str:
        e = html.escape
        nl = len(self.label_headers)
        out = [f'<table class="results" id="tab-{e(self.id)}">', f"<caption>{e(self.caption)}</caption>", "<thead>"]
        if self._has_groups():
            out.append("<tr>" + "".join("<th></th>" for _ in range(nl)) + "".join(
                f'<th colspan="{k}" class="group">{e(g or "")}</th>' for g, k, _ in self._group_spans()) + "</tr>")
        out.append("<tr>" + "".join(f"<th>{e(h)}</th>" for h in self.label_headers)
                   + "".join(f"<th>{e(c.header())}</th>" for c in self.columns) + "</tr>")
        out.append("</thead><tbody>")
        current = object()
        for r in self.rows:
            if r.section != current and r.section is not None:
                out.append(
                    f'<tr class="section"><td colspan="{nl + len(self.columns)}"><em>{e(r.section)}</em></td></tr>'
                )
            current = r.section
            labels = [(CHECK if v else "") for v in r.label_checks] if r.label_checks is not None else list(r.labels)
            tds = "".join(f'<td class="label">{e(x)}</td>' for x in labels)
            for c in r.cells:
                s = e(c.plain())
                cls = "na" if (c.check is None and c.text is None and c.rounded() is None) else "num"
                tds += f'<td class="{cls}">' + (f"<strong>{s}</strong>" if c.bold else s) + "</td>"
            out.append(f"<tr>{tds}</tr>")
        out.append("</tbody></table>")
        for n in self.notes:
            out.append(f'<p class="note">{e(n)}</p>')
        return "\n".join(out) + "\n"


def _mark(cells: list[Cell], better: str | None) -> None:
    """Bold the best rounded value (ties all bold); nothing when fewer than two values compete or
    when all of them are equal (a bold mark would then carry no information)."""
    if better not in ("higher", "lower"):
        return
    vals = [(c, c.rounded()) for c in cells if c.check is None and c.text is None and c.rounded() is not None]
    if len(vals) < 2 or len({v for _, v in vals}) == 1:
        return
    best = max(v for _, v in vals) if better == "higher" else min(v for _, v in vals)
    for c, v in vals:
        if v == best:
            c.bold = True


def _md_escape(s: str) -> str:
    return str(s).replace("|", "\\|").replace("*", "\\*")


_TEX = {"\\": "\\textbackslash{}", "&": "\\&", "%": "\\%", "$": "\\$", "#": "\\#", "_": "\\_",
        "{": "\\{", "}": "\\}", "~": "\\textasciitilde{}", "^": "\\textasciicircum{}",
        "±": "$\\pm$", "–": "--", "✓": "\\checkmark", "↑": "$\\uparrow$", "↓": "$\\downarrow$",
        "·": "$\\cdot$", "λ": "$\\lambda$"}


def _tex(s: str) -> str:
    return "".join(_TEX.get(ch, ch) for ch in str(s))
