"""Table cells and how each is aggregated over runs.

An ATE cell is the mean over runs of each run's RMSE; an RPE / drift-rate / time-RPE cell is the mean
of the errors pooled over runs (and, for the per-algorithm segment tables, over datasets); a
success-rate cell is the mean over runs; the Average column is the mean over the datasets that have a
number; a cell with no successful run prints ``- / -``.
"""

from __future__ import annotations

import numpy as np

from epa.core import runtime
from epa.metrics import drift, statistics


def num(x) -> float:
    return np.nan if x is None else float(x)


def nanmean(values) -> float:
    v = np.array([num(x) for x in values], float)
    v = v[~np.isnan(v)]
    return float(v.mean()) if v.size else np.nan


class Cell:
    """A table cell: missing (None: no successful run), or numbers that may be nan.
    ``pair`` cells hold rot / trans; the others a single number. ``runs`` (runs x numbers) holds
    each run's own value of those numbers, for the spread over runs. ``n``: the runs it holds
    (those with numbers); ``cases``: the cases it was made of and ``marks`` their marks
    (:mod:`epa.outputs.tables.marks`), set by the table that shows it."""

    def __init__(self, values=None, pair: bool = True, runs=None, n: int | None = None):
        self.values, self.pair = values, pair
        self._runs = runs
        self.n = n
        self.cases: list | None = None
        self.marks = ""

    @property
    def runs(self) -> np.ndarray | None:
        """Each run's numbers, made when first asked for: ``runs`` may be a function giving them
        (a table without a spread never asks; pooled cells made them for 600,000 runs at 10,000
        cases)."""
        if callable(self._runs):
            self._runs = self._runs()
        if self._runs is not None and not isinstance(self._runs, np.ndarray):
            self._runs = np.atleast_2d(np.asarray(self._runs, float))
        return self._runs

    def fmt(self, decimals: int, spread: str = "none") -> str:
        if self.values is None:
            return "- / -" if self.pair else "-"
        parts = []
        for k, v in enumerate(self.values):
            if v is None:  # no such number at all (a position-only estimate's rotation)
                parts.append("-")
                continue
            text = "nan" if np.isnan(v) else f"{v:.{decimals}f}"
            if spread != "none" and self.runs is not None and not np.isnan(v):
                pm = statistics.spread(self.runs[:, k], spread)
                text += "" if np.isnan(pm) else f" $\\pm$ {pm:.{decimals}f}"
            parts.append(text)
        n = f" (n={len(self.runs)})" if spread != "none" and self.runs is not None else ""
        return " / ".join(parts) + n

    def spreads(self, kind: str) -> tuple:
        """Each number's spread over the runs as ``fmt`` prints it (``kind``: std / ci); None where
        it prints none (no spread asked, fewer than two runs, a number that is nan or none)."""
        if self.values is None:
            return ()
        out = []
        for k, v in enumerate(self.values):
            pm = np.nan
            if kind != "none" and self.runs is not None and v is not None and not np.isnan(v):
                pm = statistics.spread(self.runs[:, k], kind)
            out.append(None if np.isnan(pm) else float(pm))
        return tuple(out)


def average_cell(cells: list[Cell], pair=True) -> Cell:
    have = [c.values for c in cells if c.values is not None]
    if not have:
        return Cell(None, pair)
    arr = np.array([[num(v) for v in values] for values in have], float)
    none = [all(values[k] is None for values in have) for k in range(arr.shape[1])]
    n = sum(c.n or 0 for c in cells if c.values is not None)  # the runs of its datasets
    return Cell(
        tuple(None if none[k] else nanmean(arr[:, k]) for k in range(arr.shape[1])), pair, n=n
    )


def position_only(c) -> bool:
    """Whether a case's estimate is position-only (its rotation errors are null)."""
    return bool(c.metrics.get("position_only"))


def rotation_marked(cell: Cell, runs) -> Cell:
    """A rotation / translation cell whose runs are all position-only: its rotation is no number
    at all (printed ``-``), never a nan that reads as a failed computation."""
    if runs and cell.values is not None and all(position_only(c) for c in runs):
        cell.values = (None, *cell.values[1:])
    return cell


def ok_runs(grid, alg, ds=None):
    """The runs with a result of ``alg`` (on ``ds``), in grid order. From an index built once per
    grid: scanning the grid for every cell made the tables quadratic (31 s on 1,000 cases)."""
    return list(_index(grid).get((alg, ds), ()))


def cases_of(grid, alg):
    """Every case of ``alg``, with a result or not, in grid order (from the same index)."""
    return list(_index(grid).get((alg, ...), ()))


def _index(grid) -> dict:
    kept = _INDEX.get(id(grid))
    if kept is None or kept[0] is not grid or kept[1] != len(grid):
        index: dict = {}
        for c in grid:
            index.setdefault((c.algorithm, ...), []).append(c)  # no dataset name is ...
            if c.ok:
                index.setdefault((c.algorithm, None), []).append(c)
                index.setdefault((c.algorithm, c.dataset), []).append(c)
        _INDEX.clear()  # one grid at a time; holding it keeps its id from being reused
        kept = _INDEX[id(grid)] = (grid, len(grid), index)
    return kept[2]


_INDEX: dict[int, tuple] = runtime.register("outputs.tables.cells.index", {})


def run_ate(c, valid: bool = False) -> tuple[float, float]:
    """One run's ATE RMSE: rotation (deg), translation (m)."""
    src = c.drift["drift_valid"]["ate"] if valid else c.metrics["ate"]
    return src["rot_deg"]["rmse"], src["trans_m"]["rmse"]


def mean_over_runs(runs, of) -> Cell:
    """The cell of a per-run pair: its mean over the runs (ov_eval's ATE cells)."""
    if not runs:
        return Cell(None)
    per_run = [tuple(num(x) for x in of(c)) for c in runs]
    return Cell(tuple(nanmean(v) for v in zip(*per_run)), runs=per_run, n=len(per_run))


def ate_cell(runs, valid: bool) -> Cell:
    return rotation_marked(mean_over_runs(runs, lambda c: run_ate(c, valid)), runs)


def _per_run(runs, table: str, valid: bool, length=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each run's (rot, trans) errors of the pairs a pooled cell takes from it: the same values in
    the same order whether a length's pairs are a run of rows (``length_runs``) or masked."""
    out = []
    for c in runs:
        t = getattr(c, table)
        keep = t["valid"] > 0 if valid else None
        if length is None:
            rot, trans = t.get("rot_deg", _NONE), t.get("trans_m", _NONE)
        else:  # as the drift stage takes them
            trans, rot, keep = drift.of_length(t, keep, t.get("length_runs"), float(length))
        out.append((rot, trans) if keep is None else (rot[keep], trans[keep]))
    return out


_NONE = np.zeros(0)


def pooled(runs, table: str, valid: bool, length=None):
    per_run = _per_run(runs, table, valid, length)
    return tuple(
        np.concatenate([r[k] for r in per_run]) if per_run else np.zeros(0) for k in (0, 1)
    )


def _pooled_cell(runs, table, valid, length, of, width: int) -> Cell:
    """A cell pooling the pairs of all runs, ``of(rot, trans)`` giving its ``width`` numbers; its
    spread is over each run's own ``of`` (runs without pairs left out)."""
    per_run = _per_run(runs, table, valid, length)
    rot, trans = (np.concatenate([r[k] for r in per_run]) for k in (0, 1))
    if _all_nan_valid(runs, valid) or rot.size == 0:
        return Cell((np.nan,) * width, n=0)
    # each run's own numbers taken again if a spread asks for them: kept, the selections of every
    # cell of a table would stay in memory until it is written
    return Cell(
        of(rot, trans),
        runs=lambda: [of(r, t) for r, t in _per_run(runs, table, valid, length) if r.size],
        n=sum(1 for r, _ in per_run if r.size),  # the runs its spread is over
    )


def mean_pair_cell(runs, table, valid, length=None) -> Cell:
    if not runs:
        return Cell(None)
    cell = _pooled_cell(
        runs, table, valid, length, lambda rot, trans: (float(rot.mean()), float(trans.mean())), 2
    )
    return rotation_marked(cell, runs)


def drift_rate_cell(runs, valid, length) -> Cell:
    if not runs:
        return Cell(None, pair=False)
    cell = _pooled_cell(
        runs,
        "segments",
        valid,
        length,
        lambda _, trans: (float(np.mean(trans / float(length)) * 100),),
        1,
    )
    cell.pair = False
    return cell


def _all_nan_valid(runs, valid):
    return valid and all(
        c.drift["global_failed"] or not (num(c.drift["success_rate_distance_pct"]) > 0)
        for c in runs
    )


def _single_over_runs(runs, of) -> Cell:
    """The cell of a per-run number: its mean over the runs."""
    cell = mean_over_runs(runs, lambda c: (of(c),))
    cell.pair = False
    return cell


def success_cell(runs) -> Cell:
    return _single_over_runs(runs, lambda c: c.drift["success_rate_distance_pct"])


def success_auc_cell(runs) -> Cell:
    return _single_over_runs(runs, lambda c: c.drift.get("success_auc_pct"))


def stat(d: dict, *keys):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return np.nan
        d = d[k]
    return num(d)
