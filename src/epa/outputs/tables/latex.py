"""The paper tables: one LaTeX tabular per table (``tables/<name>.tex``), built from the base tables
and the registered metrics' (:mod:`epa.metrics.registry`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from epa.metrics import accuracy
from epa.metrics.accuracy import segment_key, time_rpe_key, time_rpe_name
from epa.outputs.tables import marks as mark
from epa.outputs.tables.cells import (
    Cell,
    ate_cell,
    average_cell,
    cases_of,
    drift_rate_cell,
    mean_over_runs,
    mean_pair_cell,
    ok_runs,
    rotation_marked,
    success_auc_cell,
    success_cell,
)
from epa.outputs.tables.results import CaseResult, segments_by_dataset

_LATEX_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
}


def latex_escape(text: str) -> str:
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in str(text))


def _latex_rows(
    header: list[str], rows: list[tuple[str, list[Cell]]], decimals: int, spread: str = "none"
) -> list[str]:
    lines = [
        " & " + " & ".join(r"\textbf{" + latex_escape(h) + "}" for h in header) + r" \\ \hline"
    ]
    for name, cells in rows:
        lines.append(
            latex_escape(name)
            + " & "
            + " & ".join(c.fmt(decimals, spread) + mark.tex(c.marks) for c in cells)
            + r" \\"
        )
    return lines


class Built(NamedTuple):
    """A table as built: its file name, title, LaTeX rows (header first), number of columns, and
    for its CSV the cells themselves (``body``: algorithm, row name, cells), the column labels,
    what its columns are (``kind``: per_dataset, per_segment, per_algorithm) and the footnotes of
    its marks ((letter, text))."""

    name: str
    title: str
    rows: list[str]
    ncols: int
    body: list[tuple[str, str, list[Cell]]]
    columns: list[str]
    kind: str
    notes: list[tuple[str, str]]

    def note_rows(self) -> list[str]:
        return note_rows(self.notes, self.ncols)


def note_rows(notes: list[tuple[str, str]], ncols: int) -> list[str]:
    """Footnotes ((letter, text)) as LaTeX rows spanning a table of ``ncols`` columns."""
    return [
        rf"\multicolumn{{{ncols}}}{{l}}{{\footnotesize "
        + (mark.tex(k) + " " if k else "")
        + latex_escape(t)
        + r"} \\"
        for k, t in notes
    ]


def _built(name, title, header, body, layout, kind, decimals=None) -> Built:
    """A table of ``body`` rows (algorithm, row name, cells) under ``header``."""
    dec = layout.decimals if decimals is None else decimals
    rows = [(label, cells) for _, label, cells in body]
    return Built(
        name,
        title,
        _latex_rows(header, rows, dec, layout.spread),
        len(header) + 1,
        body,
        list(header),
        kind,
        mark.notes({alg: cells for alg, _, cells in body}),
    )


def _marked(cell: Cell, cases) -> Cell:
    """``cell`` with the cases it was made of (unless its maker named them) and their marks."""
    if cell.cases is None:
        cell.cases = list(cases)
    cell.marks = mark.of_cases(cell.cases) if cell.values is not None else ""
    return cell


SPREAD_TITLE = {
    "none": "",
    "std": " [± SAMPLE STD OVER RUNS, n = RUNS]",
    "ci": " [± HALF-WIDTH OF THE 95% CI OF THE MEAN OVER RUNS, STUDENT T, n = RUNS]",
}


def build_tables(
    grid: list[CaseResult],
    segments,
    decimals: int = 3,
    metrics=(),
    spread: str = "none",
    text: bool = False,
    *,
    time_delta: float,
) -> list[Built]:
    """Every table (:class:`Built`: file name, title, latex row lines, number of columns, cells),
    in report order: the base tables, each registered metric's (``metrics``: the enabled ones)
    after the base table it names or at the end. With ``spread`` (std / ci) each cell with runs
    also shows its spread over them and their number. ``text``: only the tables
    error_comparison.txt shows. ``time_delta``: ``metrics.time_delta``, which names the time RPE's
    tables."""
    layout = _Layout.of(grid, decimals, spread)
    out = _base_tables(layout, segments, time_delta)
    # a Table.after names a base table as BASE_TABLES spells it: the time RPE's as rpe_time
    named = dict(zip(accuracy.BASE_TABLES, accuracy.base_tables(time_delta)))
    for metric in metrics:
        for spec in metric.tables:
            if text and not spec.in_text:
                continue
            table = _metric_table(layout, metric, spec)
            at = next(
                (k + 1 for k, t in enumerate(out) if t[0] == named.get(spec.after, spec.after)),
                len(out),
            )
            out.insert(at, table)
    return out


def _unmarked(alg: str) -> str | None:
    return None


@dataclass(frozen=True)
class _Layout:
    """What every table of one grid shares: its cases, a row per algorithm, a column per dataset
    (and their Average), the decimals and the spread its cells show."""

    grid: list[CaseResult]
    algs: list[str]
    datasets: list[str]
    decimals: int
    spread: str

    @classmethod
    def of(cls, grid: list[CaseResult], decimals: int, spread: str) -> _Layout:
        algs = sorted({c.algorithm for c in grid})
        return cls(grid, algs, sorted({c.dataset for c in grid}), decimals, spread)

    def rows_per_dataset(self, cell_of, pair=True, marked=_unmarked):
        """A row per algorithm (algorithm, row name, cells): a cell per dataset and their Average;
        an algorithm ``marked`` (by what it lacks) is named so, its cells empty, never faked. Each
        cell carries the marks of the cases it holds (the Average: those of its datasets' cells)."""
        rows = []
        for a in self.algs:
            missing = marked(a)
            cells = []
            for d in self.datasets:
                if missing:
                    cells.append(Cell(None, pair))
                    continue
                runs = ok_runs(self.grid, a, d)
                cells.append(_marked(cell_of(runs), runs))
            held = [c for cell in cells if cell.values is not None for c in cell.cases or ()]
            average = _marked(average_cell(cells, pair), held)
            rows.append((a, f"{a} ({missing})" if missing else a, cells + [average]))
        return rows

    def per_dataset(self, name: str, title: str, rows, decimals: int | None = None) -> Built:
        """A table of ``rows_per_dataset`` rows."""
        header = self.datasets + ["Average"]
        return _built(
            name, title + SPREAD_TITLE[self.spread], header, rows, self, "per_dataset", decimals
        )


def _per_segment(layout: _Layout, segments, name: str, title: str, fn):
    """A table with a row per algorithm and a column per segment length."""
    seg_labels = [f"{segment_key(s)}m" for s in segments]
    # these pool an algorithm's datasets: the spread is over every run of every dataset
    rows = []
    for a in layout.algs:
        runs = ok_runs(layout.grid, a)
        marks = mark.of_cases(runs)  # every cell of the row holds the same runs
        cells = [fn(runs, s) for s in segments]
        for cell in cells:
            cell.cases, cell.marks = runs, marks if cell.values is not None else ""
        rows.append((a, a, cells))
    built = _built(
        name,
        title + SPREAD_TITLE[layout.spread].replace("RUNS]", "RUNS OF ALL DATASETS]"),
        seg_labels,
        rows,
        layout,
        "per_segment",
    )
    lengths = lengths_note(layout.grid)
    return built._replace(notes=built.notes + [("", lengths)]) if lengths else built


def lengths_note(grid: list[CaseResult]) -> str | None:
    """Where datasets were evaluated at different segment lengths (overrides, ``segments: auto``):
    each dataset's, for a table whose columns are lengths. None where they share one list."""
    by_dataset = segments_by_dataset(grid)
    if len({tuple(v) for v in by_dataset.values()}) <= 1:
        return None
    return "segment lengths per dataset: " + "; ".join(
        f"{ds} {', '.join(segment_key(s) for s in lengths)} m"
        for ds, lengths in sorted(by_dataset.items())
    )


def _base_tables(layout: _Layout, segments, time_delta: float) -> list[Built]:
    """The tables every report has, those of :data:`epa.metrics.accuracy.BASE_TABLES` in its order:
    ATE and RPE of the full trajectories, then success rates and those of their drift-valid parts."""

    def per_dataset(name, title, fn, pair=True, dec=None):
        return layout.per_dataset(name, title, layout.rows_per_dataset(fn, pair), dec)

    def build(name: str) -> Built:
        base = name.removeprefix("valid_")
        valid = base != name
        tag = "DRIFT-VALID ONLY" if valid else "FULL TRAJECTORY"
        prefix = "valid_" if valid else ""
        if base == "success_rate":
            return per_dataset(
                "success_rate",
                "DRIFT-VALID SUCCESS RATE LATEX TABLE (% PATH LENGTH)",
                success_cell,
                pair=False,
                dec=2,
            )
        if base == "success_auc":
            return per_dataset(
                "success_auc",
                "SUCCESS RATE AREA LATEX TABLE (% PATH, MEAN OVER DRIFT THRESHOLDS x0.1-x10)",
                success_auc_cell,
                pair=False,
                dec=2,
            )
        if base == "ate":
            return per_dataset(
                prefix + "ate",
                f"{tag} ATE LATEX TABLE (ROT DEG / TRANS M)",
                lambda r: ate_cell(r, valid),
            )
        if base == "rpe_distance":
            return _per_segment(
                layout,
                segments,
                prefix + "rpe_distance",
                f"{tag} DISTANCE RPE LATEX TABLE (ROT DEG / TRANS M)",
                lambda r, s: mean_pair_cell(r, "segments", valid, s),
            )
        if base == "drift_rate":
            return _per_segment(
                layout,
                segments,
                prefix + "drift_rate",
                f"{tag} DISTANCE DRIFT RATE LATEX TABLE (% TRANS / DIST)",
                lambda r, s: drift_rate_cell(r, valid, s),
            )
        if base == accuracy.TIME_RPE:
            return per_dataset(
                prefix + time_rpe_key(time_delta),
                f"{tag} {time_rpe_name(time_delta).upper()} TIME RPE LATEX TABLE (ROT DEG / TRANS M)",
                lambda r: mean_pair_cell(r, "time", valid),
            )
        raise ValueError(f"base table {name!r}: no table of that name to build")

    return [build(name) for name in accuracy.BASE_TABLES]


def _metric_table(layout: _Layout, metric, spec):
    """A registered metric's table (:class:`epa.metrics.spec.Table`)."""
    grid = layout.grid

    def has(alg):
        return any(spec.has(c.record_of(metric)) for c in cases_of(grid, alg))

    if spec.per_algorithm is not None:  # one row per algorithm with the metric, over all its runs
        rows = []
        for a in layout.algs:
            held = [c for c in cases_of(grid, a) if spec.has(c.record_of(metric))]
            if held:
                values = spec.per_algorithm([c.record_of(metric) for c in held])
                cells = [Cell((v,), pair=False, n=len(held)) for v in values]
                rows.append((a, a, [_marked(cell, [c for c in held if c.ok]) for cell in cells]))
        return _built(spec.name, spec.title, list(spec.header), rows, layout, "per_algorithm", None)

    def cell_of(runs):
        runs = [c for c in runs if spec.has(c.record_of(metric))]
        cell = mean_over_runs(runs, lambda c: spec.per_run(c.record_of(metric)))
        cell.pair, cell.cases = spec.pair, runs
        return rotation_marked(cell, runs) if spec.pair else cell

    def marked(alg):
        if not spec.missing or has(alg):
            return None
        if callable(spec.missing):
            return spec.missing([c.record_of(metric) for c in cases_of(grid, alg)])
        return spec.missing

    rows = layout.rows_per_dataset(cell_of, spec.pair, marked)
    if spec.note is not None:
        rows = [(alg, _noted(name, alg, grid, metric, spec), cells) for alg, name, cells in rows]
    return layout.per_dataset(spec.name, spec.title, rows)


def _noted(name: str, alg: str, grid, metric, spec) -> str:
    """An algorithm's row name with its table note (of its successful runs that have the metric)."""
    records = [c.record_of(metric) for c in ok_runs(grid, alg) if spec.has(c.record_of(metric))]
    text = spec.note(records) if records else None
    return f"{name} ({text})" if text else name


def tex_document(title: str, rows: list[str], ncols: int, notes: list[str] | None = None) -> str:
    """A table that \\input's into a paper: a tabular with the report's rows, titled in a comment,
    and its ``notes`` (the footnotes of its marks) as rows spanning it under a rule."""
    spec = "l" + "c" * (ncols - 1)
    under = [r"\hline", *notes] if notes else []
    return "\n".join(
        [f"% {title}", r"\begin{tabular}{" + spec + "}", *rows, *under, r"\end{tabular}", ""]
    )


TABLE_STYLES = ("hline", "booktabs")


def restyle(tex: str, style: str = "hline") -> str:
    """A table in another style of rules: ``hline`` as written; ``booktabs`` puts \\toprule over the
    header, \\midrule under it (for its \\hline) and \\bottomrule under the last row."""
    if style == "hline":
        return tex
    if style != "booktabs":
        raise ValueError(f"tables.style: {style!r} is not one of {TABLE_STYLES}")
    out: list[str] = []
    ruled = False  # the bottom rule goes over the footnotes, where a table has them
    lines = tex.split("\n")
    for k, line in enumerate(lines):
        if line == r"\hline" and k + 1 < len(lines) and lines[k + 1].startswith(r"\multicolumn"):
            out.append(r"\bottomrule")
            ruled = True
            continue
        if line.startswith(r"\end{tabular}") and not ruled:
            out.append(r"\bottomrule")
        out.append(line.replace(r" \hline", r" \midrule"))
        if line.startswith(r"\begin{tabular}"):
            out.append(r"\toprule")
    return "\n".join(out)
