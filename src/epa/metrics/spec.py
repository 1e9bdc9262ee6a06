"""The metric contract, in code: a :class:`Metric` per metric module (its ``METRIC``), a
:class:`Table` per paper table it declares. The registry (:mod:`epa.metrics.registry`) checks the
declarations when it loads: a wrong field, an unknown anchor or table fails at import.

A record's ``warning`` (a sentence, or None) is a finding a reader must not miss: besides the log and
metrics.json it goes to the case's flags (its report, ``10_report/report.json``) and summary.csv's
``notes`` column, and a table's ``note`` marks the algorithm.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

INPUTS = (
    "unaligned",
    "transform",
    "reference",
    "estimate_source",
    "estimate",
    "image_stamps",
    "printed_quaternions",
    "pair_rows",
    "calibrate_record",
    "accuracy",
)


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


def _strings(value, field: str, key: str) -> None:
    if not isinstance(value, tuple) or not all(isinstance(v, str) and v for v in value):
        raise TypeError(f"metric {key!r}: {field} must be a tuple of names, not {value!r}")


@dataclass(frozen=True)
class Metric:
    """What a metric module declares (its ``METRIC``); checked when it is built and when the
    registry loads.

    - ``key``: its record's key (and its setting ``metrics.<key>``, where it has one);
    - ``stage``: ``"metrics"`` (computed by the metrics stage from the aligned matched poses, its
      record under ``key`` in ``metrics.json``) or the name of its own stage (its record is that
      stage's);
    - ``enabled(cfg)``; ``summary(record) -> dict``: its ``summary.csv`` columns, named by
      ``summary_columns``;
    - ``settings``: the config keys it reads, dotted (``"metrics.per_axis"``, ``"align"``); the
      stage's and the tables rule's config subsets include their sections, so reading one is never
      a ``KeyError``;
    - for ``stage == "metrics"``: ``compute(ref, est, cfg, **inputs) -> (record, arrays, notes)``
      where ``arrays`` maps a per-case table (``ape`` or its own, one of ``arrays`` without
      ``.csv``) to its columns and ``notes`` are logged as warnings and listed in metrics.json
      ``notes``; ``after``: the record it follows in metrics.json (a key of the base record or of
      another metric of the stage; None: last);
    - ``inputs``: what ``compute`` needs beyond the aligned matched poses, passed as keywords (one
      of the metrics stage's ``INPUTS``, checked when that stage loads: the matched estimate before
      Step 3, ``05_align/transform.json``, the whole cropped reference, the estimate's source
      settings as ``load.json`` records them, the whole cropped estimate, the image stamps of
      metrics.eth3d.image_stamps or None, the reference's and the estimate's files read again with
      their quaternions as printed, each None where its source prints none,
      :func:`epa.core.geometry.pair_rows` of the aligned matched poses, None where a side is
      position-only, ``04_calibrate/calibrate.json``, the accuracy record the metrics stage
      computed: ``ref_length_m``, ``ate``, ...); each is read only when such a metric is on;
    - ``protocol``: one of the field's published scoring protocols (TUM RGB-D, TartanAir, ...),
      turned on by ``epa eval --protocol <key>`` or ``metrics.<key>.enabled``;
    - ``arrays``: its own per-case files; ``tables``: its paper tables;
    - ``documents(record) -> {file name: text}``: small files of its own, written to
      ``06_metrics/<key>/`` (that folder is removed where the metric is off);
    - ``orientation``: whether ``compute`` needs the estimate's orientation (the default); for a
      position-only estimate (``t x y z``) such a metric's record is None, with a note saying why.
    """

    key: str
    stage: str
    enabled: Callable[[dict], bool]
    summary: Callable[[dict], dict]
    settings: tuple[str, ...] = ()
    compute: Callable[..., tuple[dict, dict, list[str]]] | None = None
    after: str | None = None
    inputs: tuple[str, ...] = ()
    arrays: tuple[str, ...] = ()
    summary_columns: tuple[str, ...] = ()
    tables: tuple[Table, ...] = ()
    documents: Callable[[dict], dict[str, str]] | None = None
    protocol: bool = False
    # it needs the estimate's orientation: a position-only case's record is None, with a note
    orientation: bool = True

    def __post_init__(self):
        if not isinstance(self.key, str) or not self.key:
            raise TypeError(f"a metric's key must be a non-empty string, not {self.key!r}")
        key = self.key
        if not isinstance(self.stage, str) or not self.stage:
            raise TypeError(f"metric {key!r}: stage must be a stage name, not {self.stage!r}")
        for field in ("enabled", "summary"):
            if not callable(getattr(self, field)):
                raise TypeError(f"metric {key!r}: {field} must be callable")
        for field in ("settings", "inputs", "arrays", "summary_columns"):
            _strings(getattr(self, field), field, key)
        if any("" in s.split(".") for s in self.settings):
            raise ValueError(
                f"metric {key!r}: settings {self.settings!r}: a dotted config key each"
            )
        if not isinstance(self.tables, tuple) or not all(isinstance(t, Table) for t in self.tables):
            raise TypeError(f"metric {key!r}: tables must be a tuple of Table")
        if self.documents is not None and not callable(self.documents):
            raise TypeError(f"metric {key!r}: documents must be callable or None")
        if self.stage == "metrics":
            if not callable(self.compute):
                raise TypeError(f"metric {key!r}: a metric of the metrics stage needs compute")
            if self.after is not None and (not isinstance(self.after, str) or not self.after):
                raise TypeError(f"metric {key!r}: after must be a record key or None")
        elif self.compute is not None or self.after is not None or self.inputs or self.documents:
            raise ValueError(
                f"metric {key!r}: compute, after, inputs and documents belong to metrics of the"
                f" metrics stage, not of stage {self.stage!r}"
            )

    @property
    def sections(self) -> tuple[str, ...]:
        """The config sections its settings are in, in order."""
        return tuple(dict.fromkeys(s.split(".")[0] for s in self.settings))


def protocol(key: str, **fields) -> Metric:
    """A scoring protocol's declaration: a metric of the metrics stage whose settings are the
    section ``metrics.<key>``, on where its ``enabled`` is true (what ``epa eval --protocol <key>``
    sets); ``fields``: the rest of its :class:`Metric`."""
    return Metric(
        key=key,
        stage="metrics",
        enabled=lambda cfg: bool(cfg["metrics"][key]["enabled"]),
        settings=(f"metrics.{key}",),
        protocol=True,
        **fields,
    )
