"""How a metric shows in the paper tables: a :class:`Table` per table, declared by its metric module.

A metric module of the registry (:mod:`epa.metrics.registry`) declares:

- ``KEY``: its setting (``metrics.<KEY>``, where it has one) and its record's key;
- ``STAGE``: ``"metrics"`` (computed by the metrics stage from the aligned matched poses, its record
  under ``KEY`` in ``metrics.json``) or the name of its own stage (its record is that stage's);
- ``enabled(cfg)``; for ``STAGE == "metrics"``: ``AFTER`` (the record it follows in metrics.json,
  None: last), ``compute(ref, est, cfg) -> (record, arrays, notes)`` where ``arrays`` maps a per-case
  table (``ape`` or its own, one of ``ARRAYS`` without ``.csv``) to its columns, and ``notes`` are
  logged as warnings and listed in metrics.json ``notes``;
- ``ARRAYS``: its own per-case files; ``SUMMARY_COLUMNS`` and ``summary(record) -> dict``: its
  ``summary.csv`` columns; ``TABLES``: its paper tables.

Optionally (mode rpg's metric, :mod:`epa.metrics.rpg`, and :mod:`epa.metrics.sim3_check` use them):

- ``INPUTS``: what ``compute`` needs beyond the aligned matched poses, passed as keywords:
  ``unaligned`` (the matched estimate before Step 3), ``transform`` (``05_align/transform.json``),
  ``reference`` (the whole cropped reference), ``estimate_source`` (the estimate's source settings,
  as ``load.json`` records them); each is read only when such a metric is on;
- ``documents(record) -> {file name: text}``: small files of its own, written to
  ``06_metrics/<KEY>/`` (that folder is removed where the metric is off).

A record's ``warning`` (a sentence, or None) is a finding a reader must not miss: besides the log and
metrics.json it goes to the case's flags (its report, ``10_report/report.json``) and summary.csv's
``notes`` column, and a table's ``note`` marks the algorithm.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Table:
    """A paper table (``tables/<name>.tex`` and a block of error_comparison.txt).

    ``per_dataset`` tables have a cell per algorithm and dataset, the mean over its runs of
    ``per_run(record)`` (runs where ``has(record)``), and an Average column; ``missing`` names what
    an algorithm without any such run lacks (its row is marked and left empty). ``per_algorithm``
    tables have one row per algorithm that has the metric: ``per_algorithm(records)`` over every run
    of it, under ``header``."""

    name: str
    title: str
    pair: bool = True  # cells of two numbers (rotation / translation), else one
    per_run: Callable[[dict], tuple] | None = None
    has: Callable[[dict], bool] = lambda record: True
    missing: str | Callable[[list[dict]], str] | None = None  # or of the algorithm's records
    per_algorithm: Callable[[list[dict]], tuple] | None = None
    header: tuple[str, ...] = ()
    # per_dataset: a note after an algorithm's name, its cells kept, of its runs' records (None: none)
    note: Callable[[list[dict]], str | None] | None = None
    after: str | None = None  # the base table it follows; None: after the base tables
    in_text: bool = True  # also in error_comparison.txt
