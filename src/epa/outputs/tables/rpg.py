"""Mode rpg's summary tables: what rpg_trajectory_evaluation's ``analyze_trajectories.py`` writes with
``--rmse_table`` and ``--overall_odometry_error``, from each case's rpg statistics (``metrics.json``
``rpg``, ``06_metrics/rpg_relative_errors.csv``).

The runs of an algorithm on a dataset are rpg's trials (in run-name order); a run without a result is
a failed trial, left out as rpg leaves it out. The statistics over trials are rpg's ``MulTrajError``
(:func:`epa.metrics.rpg.multi_trial_statistics`).

- ``rpg_translation_rmse.txt``: ``--rmse_table``. A row per algorithm, a column per dataset (both
  sorted, rpg's default ``sort_names``); a cell is rpg's ``"{:3.3f}, {:3.3f} ({:3.3f} - {:3.3f})"`` of
  the mean, median, min and max over trials of each trial's ATE translation RMSE (m), or its
  ``"{:3.3f}"`` median when every cell has one run (rpg without ``--mul_trials``) or with
  ``tables.rpg_median_only`` (``--rmse_table_median_only``).
- ``rpg_rel_err.txt``: ``--overall_odometry_error``. A row per algorithm: the mean relative translation
  error (%) and rotation error (deg/m) over every pair of every distance, dataset and trial, pooled
  as rpg pools them (per distance across datasets).

Both are rpg's ``results_writer.write_tex_table`` bytes: the header ``'      &      '`` then the columns
joined by ``' & '``, each row ``'<name> &     '`` then its cells, the last one after a space, no ``\\\\``
and no escaping (rpg's text is pasted into a tabular by hand). ``tables/rpg_*.tex`` hold the same cells
in epica's tabular (names escaped, ``tables.style`` rules), marked as the other tables' cells are
(:mod:`epa.outputs.tables.marks`: trials evaluated differently, flagged).

Where rpg stops, these tables say so: a cell without a successful run reads ``-`` (rpg asserts that
every case folder exists and fails on a case without a successful trial), and so does an algorithm
without a single relative-error pair (rpg prints the mean of nothing as 0.000).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from epa.artifacts.case import CaseFolder
from epa.metrics import rpg
from epa.outputs.tables import marks as mark
from epa.outputs.tables.cells import Cell, ok_runs
from epa.outputs.tables.latex import latex_escape, note_rows, restyle, tex_document
from epa.outputs.tables.results import CaseResult

FILES = ("rpg_translation_rmse.txt", "rpg_rel_err.txt")
TABLES = ("rpg_translation_rmse", "rpg_rel_err")
REL_ERR_COLUMNS = ("Translation (\\%)", "Rotation (deg/meter)")  # rpg's labels, LaTeX already
REL_ERR_METRICS = ("rel_trans_perc", "rel_rot_deg_per_m")
MISSING = "-"


def _trials(grid: list[CaseResult], alg: str, ds: str) -> list[CaseResult]:
    return [c for c in ok_runs(grid, alg, ds) if c.metrics.get("rpg")]


def write_tex_table(values: list[list[str]], rows: list[str], cols: list[str]) -> str:
    """rpg's ``results_writer.write_tex_table``, as text (empty without a row or a column)."""
    if not rows or not cols:
        return ""
    out = "      &      " + "".join(c + " & " for c in cols[:-1]) + " " + cols[-1] + "\n"
    for name, row in zip(rows, values):
        out += name + " &     " + "".join(v + " & " for v in row[:-1]) + " " + row[-1] + " \n"
    return out


def _tex(
    title: str, values: list[list[str]], rows: list[str], cols: list[str], style: str, held=None
) -> str:
    """A table of rpg's cells; ``held`` (per row, per cell: its trials) marks the cells whose
    trials were evaluated differently or are flagged (:mod:`epa.outputs.tables.marks`)."""
    held = held or [[[] for _ in row] for row in values]
    cells = [[_held(trials) for trials in row] for row in held]
    header = " & " + " & ".join(r"\textbf{" + c + "}" for c in cols) + r" \\ \hline"
    lines = [header] + [
        latex_escape(name)
        + " & "
        + " & ".join(v + mark.tex(c.marks) for v, c in zip(row, marked))
        + r" \\"
        for name, row, marked in zip(rows, values, cells)
    ]
    ncols = len(cols) + 1
    notes = note_rows(mark.notes(dict(zip(rows, cells))), ncols)
    return restyle(tex_document(title, lines, ncols, notes), style)


def _held(trials: list[CaseResult]) -> Cell:
    cell = Cell(() if trials else None)
    cell.cases, cell.marks = trials, mark.of_cases(trials)
    return cell


def rmse_table(grid: list[CaseResult], median_only: bool = False):
    """(cells, algorithms, datasets, whether the cells are the median only) of rpg's translation RMSE
    table."""
    algs = sorted({c.algorithm for c in grid})
    datasets = sorted({c.dataset for c in grid})
    # rpg's n_trials is its --mul_trials: here the most runs any algorithm has on a dataset
    n_trials = max(Counter((c.algorithm, c.dataset) for c in grid).values(), default=0)
    median_only = median_only or n_trials == 1
    values = []
    for alg in algs:
        row = []
        for ds in datasets:
            trials = _trials(grid, alg, ds)
            if not trials:
                row.append(MISSING)
                continue
            st = rpg.trial_rmse_statistics([c.metrics["rpg"]["absolute"] for c in trials])
            st = st["rmse_trans"]  # finite: positions are
            if median_only:
                row.append("{:3.3f}".format(st["median"]))
            else:
                row.append(
                    "{:3.3f}, {:3.3f} ({:3.3f} - {:3.3f})".format(
                        st["mean"], st["median"], st["min"], st["max"]
                    )
                )
        values.append(row)
    return values, algs, datasets, median_only


def _trial_errors(results_dir, c: CaseResult) -> dict:
    """One trial as multi_trial_statistics takes it, from the case's record and relative errors."""
    record = c.metrics["rpg"]
    table = CaseFolder.of(results_dir, c.case).table("metrics", "rpg_relative_errors.csv")
    dist = np.asarray(table.get("distance_m", []), float)
    rel = {
        d: {m: np.asarray(table[col], float)[dist == d] for m, col in rpg.REL_COLUMNS.items()}
        for d in record["distances_m"]
    }
    return {"abs_stats": record["absolute"], "distances": record["distances_m"], "rel": rel}


def rel_err_table(grid: list[CaseResult], results_dir):
    """(cells, algorithms, columns) of rpg's overall relative-error table."""
    algs = sorted({c.algorithm for c in grid})
    datasets = sorted({c.dataset for c in grid})
    values = []
    for alg in algs:
        pooled: dict = {m: {} for m in REL_ERR_METRICS}  # rpg: {metric: {distance: values}}
        for ds in datasets:
            trials = _trials(grid, alg, ds)
            if not trials:
                continue
            mt = rpg.multi_trial_statistics([_trial_errors(results_dir, c) for c in trials])
            for m in REL_ERR_METRICS:
                for d, e in mt["rel"].items():
                    pooled[m].setdefault(d, []).extend(e[m].tolist())
        row = []
        for m in REL_ERR_METRICS:
            errors = [x for v in pooled[m].values() for x in v]
            row.append("{:.3f}".format(rpg.statistics(errors)["mean"]) if errors else MISSING)
        values.append(row)
    return values, algs, list(REL_ERR_COLUMNS)


def write_rpg_tables(grid: list[CaseResult], results_dir, cfg: dict, write) -> None:
    """``results_dir``/rpg_translation_rmse.txt, rpg_rel_err.txt and tables/rpg_*.tex, each through
    ``write(path, text)``."""
    results_dir = Path(results_dir)
    style = cfg["tables"].get("style", "hline")
    values, rows, cols, median = rmse_table(grid, cfg["tables"].get("rpg_median_only", False))
    write(results_dir / "rpg_translation_rmse.txt", write_tex_table(values, rows, cols))
    title = "RPG TRANSLATION RMSE LATEX TABLE (ATE M; " + (
        "MEDIAN OVER RUNS)" if median else "OVER RUNS: MEAN, MEDIAN (MIN - MAX))"
    )
    tex_cols = [latex_escape(c) for c in cols]
    held = [[_trials(grid, a, d) for d in cols] for a in rows]
    write(
        results_dir / "tables/rpg_translation_rmse.tex",
        _tex(title, values, rows, tex_cols, style, held),
    )
    values, rows, cols = rel_err_table(grid, results_dir)
    write(results_dir / "rpg_rel_err.txt", write_tex_table(values, rows, cols))
    title = "RPG RELATIVE ERROR LATEX TABLE (MEAN OVER EVERY PAIR, DISTANCE, DATASET AND RUN)"
    every = {a: [c for c in ok_runs(grid, a) if c.metrics.get("rpg")] for a in rows}
    held = [[every[a] for _ in cols] for a in rows]
    write(results_dir / "tables/rpg_rel_err.tex", _tex(title, values, rows, cols, style, held))
