"""The tables' cells as numbers: ``tables/<name>.csv`` beside each .tex (a row per cell) and
``cells.csv``, one tidy file of every cell of every table and of each algorithm and dataset's
cases (how many have a result, fell back, are flagged; the mean Sim3 scale).

A value is written with 17 significant digits, empty where the table prints ``-`` or ``nan``;
``spread`` is the table's (``tables.spread``: std or ci; empty with ``none`` or under two runs); ``n``
the runs a cell holds (its Average: the runs of its datasets' cells); ``marks`` its letters
(:mod:`epa.outputs.tables.marks`).
"""

from __future__ import annotations

import csv
import io
import re

import numpy as np

from epa.outputs.tables import marks as mark
from epa.outputs.tables.cells import cases_of, ok_runs
from epa.outputs.tables.latex import Built

CELLS_COLUMNS = ("algorithm", "dataset", "metric", "statistic", "value", "spread", "n", "marks")
# the dataset of a cell that pools every dataset of its algorithm (per segment length, per algorithm)
ALL = "all"


def quantities(table: Built) -> list[str]:
    """The names of a cell's numbers: for a pair table, the two of its title's units
    (``ROT DEG / TRANS M`` -> rot_deg, trans_m); else ``value``."""
    pair = any(c.pair for _, _, cells in table.body for c in cells)
    if not pair:
        return ["value"]
    unit = re.search(r"\(([^()]*)\)", table.title)
    parts = unit.group(1).split(" / ") if unit else []
    if len(parts) != 2:
        return ["value_1", "value_2"]
    return [_name(p) for p in parts]


def _name(text: str) -> str:
    """A column name from a unit label: its words before a comma, at most four, in lower case."""
    words = text.split(",")[0].split()[:4]
    return "_".join(w.lower() for w in words) or "value"


def _number(x) -> str:
    if x is None:
        return ""
    x = float(x)
    return "" if not np.isfinite(x) else format(x, ".17g")


def _cells(table: Built, spread: str):
    """(algorithm, row name, column label, quantity names, values, spreads, n, marks) per cell."""
    names = quantities(table)
    for alg, label, cells in table.body:
        for column, cell in zip(table.columns, cells):
            values = cell.values if cell.values is not None else (None,) * len(names)
            spreads = cell.spreads(spread) if cell.values is not None else (None,) * len(names)
            yield alg, label, column, names, values, spreads, cell.n, cell.marks


def table_csv(table: Built, spread: str) -> str:
    """``tables/<name>.csv``: a row per cell of the .tex, its numbers, their spreads, n, marks and
    the row's note (what the .tex says after the algorithm's name)."""
    names = quantities(table)
    cols = ["algorithm", "column", *names, *(f"{q}_spread" for q in names), "n", "marks", "note"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for alg, label, column, _, values, spreads, n, marks in _cells(table, spread):
        note = label[len(alg) + 2 : -1] if label != alg else ""
        w.writerow(
            [
                alg,
                column,
                *map(_number, values),
                *map(_number, spreads),
                "" if n is None else n,
                marks,
                note,
            ]
        )
    return buf.getvalue()


def cell_rows(tables: list[Built], spread: str, grid) -> list[list]:
    """cells.csv's rows: every cell of every table, then each algorithm and dataset's cases."""
    rows = []
    for table in tables:
        for alg, _, column, names, values, spreads, n, marks in _cells(table, spread):
            for q, v, s in zip(names, values, spreads):
                if table.kind == "per_dataset":
                    dataset, statistic = column, q
                elif table.kind == "per_segment":
                    dataset, statistic = ALL, f"{q}_{column}"
                else:
                    dataset, statistic = ALL, column
                rows.append([alg, dataset, table.name, statistic, v, s, n, marks])
    rows += case_rows(grid)
    return rows


def case_rows(grid) -> list[list]:
    """Per algorithm and dataset (metric ``cases``): the cases with a result, those that fell back
    to the ov_eval way, those flagged; (metric ``alignment``) the mean Sim3 scale of those
    Sim3-aligned, with its sample std."""
    rows = []
    for alg in sorted({c.algorithm for c in grid}):
        for ds in sorted({c.dataset for c in cases_of(grid, alg)}):
            runs = ok_runs(grid, alg, ds)
            marks = mark.of_cases(runs)
            evals = [mark.evaluation(c) for c in runs]
            n = len(runs)
            rows.append([alg, ds, "cases", "with_result", n, None, n, marks])
            rows.append(
                [alg, ds, "cases", "fallback", sum(e.fallback for e in evals), None, n, marks]
            )
            flagged = sum(bool(e.warnings) for e in evals)
            rows.append([alg, ds, "cases", "flagged", flagged, None, n, marks])
            scales = [e.scale for e in evals if e.scale is not None]
            if scales:
                std = float(np.std(scales, ddof=1)) if len(scales) > 1 else None
                rows.append(
                    [
                        alg,
                        ds,
                        "alignment",
                        "sim3_scale",
                        float(np.mean(scales)),
                        std,
                        len(scales),
                        marks,
                    ]
                )
    return rows


def cells_csv(rows: list[list]) -> str:
    """cells.csv's text."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CELLS_COLUMNS)
    for alg, ds, metric, statistic, value, spread, n, marks in rows:
        value = value if isinstance(value, int) else _number(value)
        w.writerow(
            [alg, ds, metric, statistic, value, _number(spread), "" if n is None else n, marks]
        )
    return buf.getvalue()
