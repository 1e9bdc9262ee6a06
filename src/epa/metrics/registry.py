"""The metrics a case is scored by beyond ATE, RPE and drift: one module each, listed here once. The
metrics stage, the per-case arrays, the paper tables and ``summary.csv`` iterate this list of their
declarations (:class:`epa.metrics.spec.Metric`, each module's ``METRIC``), checked by
:func:`validate` when this module loads. Its order is the order of their columns and tables; in
metrics.json a record follows its ``after``, wherever that metric is in the list."""

from __future__ import annotations

import importlib
from collections.abc import Sequence

from epa.metrics import accuracy
from epa.metrics.spec import Metric

# The registered metrics' modules (epa.metrics.<name>, each declaring METRIC), named once, in the
# order of their columns and tables.
MODULES = (
    "ate_2d",
    "consistency",
    "efficiency",
    "kitti",
    "per_axis",
    "rpg",
    "sim3_check",
    "tum",
    "tartanair",
    "hilti",
    "eth3d",
)


def validate(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """The metrics as given, once their declarations agree with each other; raises TypeError or
    ValueError naming the metric and its field: a duplicate key, array, summary column or table; an
    ``after`` that is neither a key of the base record nor another metric of the metrics stage, or a
    cycle of them; a table following an unknown table.

    Parameters
    ----------
    metrics : sequence of Metric

    Returns
    -------
    tuple of Metric
    """
    seen: dict[str, set] = {
        "key": set(),
        "arrays": set(),
        "summary_columns": set(),
        "tables": set(),
    }
    for m in metrics:
        if not isinstance(m, Metric):
            raise TypeError(f"the registry lists {m!r}, not a Metric")
        for field, names in (
            ("key", (m.key,)),
            ("arrays", m.arrays),
            ("summary_columns", m.summary_columns),
            ("tables", tuple(t.name for t in m.tables)),
        ):
            dup = [n for n in names if n in seen[field]] or [n for n in names if names.count(n) > 1]
            if dup:
                raise ValueError(f"metric {m.key!r}: {field} {dup} registered twice")
            seen[field].update(names)
    in_stage = {m.key: m for m in metrics if m.stage == "metrics"}
    for m in in_stage.values():
        if m.after is not None and m.after not in accuracy.RECORD_KEYS and m.after not in in_stage:
            raise ValueError(
                f"metric {m.key!r}: after {m.after!r} is neither a key of the metrics record"
                f" {accuracy.RECORD_KEYS} nor a registered metric of the metrics stage"
            )
        chain, at = [m.key], m.after
        while at in in_stage:
            if at in chain:
                raise ValueError(
                    f"metric {m.key!r}: after makes a cycle: {' -> '.join(chain + [at])}"
                )
            chain.append(at)
            at = in_stage[at].after
    tables = set(accuracy.BASE_TABLES) | seen["tables"]
    for m in metrics:
        for t in m.tables:
            if t.after is not None and t.after not in tables:
                raise ValueError(
                    f"metric {m.key!r}: table {t.name!r} follows {t.after!r}, which is no table"
                )
    return tuple(metrics)


def anchor(metric: Metric, record: dict, metrics: Sequence[Metric] | None = None) -> str | None:
    """The key of ``record`` that ``metric``'s record follows: its ``after``, or where that metric is
    off (its record absent) that metric's own anchor, and so on; None: last."""
    by_key = {m.key: m for m in (REGISTRY if metrics is None else metrics)}
    at = metric.after
    while at is not None and at not in record:
        at = by_key[at].after if at in by_key else _time_rpe_as_named(at, record)
    return at


def _time_rpe_as_named(at: str, record: dict) -> str | None:
    """RECORD_KEYS names the time RPE ``rpe_time`` (accuracy.TIME_RPE): for that anchor, the
    record's own time-RPE key (``rpe_time_1s`` at metrics.time_delta 1); None for any other."""
    found = accuracy.time_rpe_in(record) if at == accuracy.TIME_RPE else None
    return None if found is None else "rpe_time_" + found[0]


def placement(metrics: Sequence[Metric] | None = None) -> tuple[Metric, ...]:
    """The metrics of the metrics stage in the order their records are placed: each after the
    metric it follows, otherwise in registry order."""
    stage = [m for m in (REGISTRY if metrics is None else metrics) if m.stage == "metrics"]
    keys = {m.key for m in stage}
    out: list[Metric] = []

    def place(m: Metric) -> None:
        if m in out:
            return
        if m.after in keys:
            place(next(a for a in stage if a.key == m.after))
        out.append(m)

    for m in stage:
        place(m)
    return tuple(out)


REGISTRY = validate(
    tuple(importlib.import_module(f"{__package__}.{name}").METRIC for name in MODULES)
)


def computed_in(stage: str) -> tuple[Metric, ...]:
    """The registered metrics a stage computes."""
    return tuple(m for m in REGISTRY if m.stage == stage)


def sections(stage: str | None = None) -> tuple[str, ...]:
    """The config sections the registered metrics read (those a stage computes; None: all), in
    registry order."""
    metrics = REGISTRY if stage is None else computed_in(stage)
    return tuple(dict.fromkeys(s for m in metrics for s in m.sections))


def protocols() -> tuple[str, ...]:
    """The keys of the registered scoring protocols (``epa eval --protocol``)."""
    return tuple(m.key for m in REGISTRY if m.protocol)
