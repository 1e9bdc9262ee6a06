"""The stage chain: what the stage declarations give.

The stage list is :data:`epa.artifacts.stage.ORDER`; each stage module declares itself
(``STAGE``, :class:`epa.artifacts.stage.Stage`) and everything else is derived here
(:func:`derive`): ``STAGES``, ``NAMES``, ``BY_NAME``, ``CaseData``.

``epa eval`` runs :func:`run_case` (every stage in one process, values passed in memory through one
:class:`~epa.artifacts.case.CaseData`); a workflow job runs one stage for a batch of cases
(:mod:`epa.workflow.jobs`), each stage reading what it needs from the previous stages' artifacts.
Both call the same stage modules, so the command line and the workflow write the same
``metrics.json``.
"""

from __future__ import annotations

import functools
import importlib
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from epa.artifacts import case as case_module
from epa.artifacts import stage as stage_list
from epa.artifacts.case import Case, CaseFolder
from epa.artifacts.stage import Stage, Value
from epa.core.errors import EpaError
from epa.metrics import registry


@dataclass(frozen=True)
class Derived:
    """What the stage declarations give, in the order of :data:`epa.artifacts.stage.ORDER`."""

    stages: tuple[Stage, ...]
    by_name: dict[str, Stage]
    names: tuple[str, ...]
    # name -> its Value; each stage's readable values (its reads, what reading them reads, its own)
    values: dict[str, Value]
    readable: dict[str, frozenset[str]]
    data_class: type[case_module.CaseData]
    # stage -> the value holding its record (the one of type Record it hands on), for those with one
    records: dict[str, str]
    # (stage, record file) of the stages that declare a result: the case's document (metrics.json)
    document: tuple[tuple[str, str], ...]


def _closure(names, values: dict[str, Value]) -> set[str]:
    """``names`` and every value reading them may read (:attr:`~epa.artifacts.stage.Value.needs`)."""
    found: set[str] = set()
    todo = list(names)
    while todo:
        name = todo.pop()
        if name not in found:
            if name not in values:
                raise ValueError(f"no stage hands on a value {name!r}")
            found.add(name)
            todo += values[name].needs
    return found


@functools.lru_cache(maxsize=8)
def derive(stages: tuple[Stage, ...]) -> Derived:
    """Everything the chain derives from the stage declarations (a stage reading a value no earlier
    stage hands on is an error here)."""
    values: dict[str, Value] = {}
    readable: dict[str, frozenset[str]] = {}
    for st in stages:
        for value in st.values:
            values.setdefault(value.name, value)
        try:
            readable[st.name] = frozenset(
                _closure((*st.reads, *(v.name for v in st.values)), values)
            )
        except ValueError as exc:
            raise ValueError(f"stage {st.name}: {exc} before it") from None
    document = tuple((st.name, st.records[0]) for st in stages if st.result is not None)
    return Derived(
        stages=stages,
        by_name={st.name: st for st in stages},
        names=tuple(st.name for st in stages),
        values=values,
        readable=readable,
        data_class=case_module.data_class((v for st in stages for v in st.values), document),
        records={
            st.name: record[0]
            for st in stages
            if (record := [v.name for v in st.values if v.type is case_module.Record])
        },
        document=document,
    )


def declared() -> Derived:
    """The chain of the stage list as it is now (each stage module's ``STAGE``)."""
    # sys.modules first: import_module's own lookups were most of a call, and a workflow job makes
    # a few calls a case
    loaded = sys.modules
    modules = (
        loaded.get(module) or importlib.import_module(module)
        for module in (f"{__package__}.stages.{name}" for name in stage_list.ORDER)
    )
    return derive(tuple(module.STAGE for module in modules))


# Derived from the stage list on each use (module __getattr__ below), so that a stage added to it, as
# tests/test_stage_contract.py adds one, reaches every use.
STAGES: tuple[Stage, ...]  # the declarations, in order
BY_NAME: dict[str, Stage]
NAMES: tuple[str, ...]
CaseData: type[case_module.CaseData]  # with a field for each value a stage hands on
RECORDS: dict[str, str]  # stage -> the CaseData value holding its record
DOCUMENT: tuple[tuple[str, str], ...]  # (stage, record file) of the case's document, metrics.json
_DERIVED = {
    "STAGES": "stages",
    "BY_NAME": "by_name",
    "NAMES": "names",
    "CaseData": "data_class",
    "RECORDS": "records",
    "DOCUMENT": "document",
}


def __getattr__(name: str):
    if name in _DERIVED:
        return getattr(declared(), _DERIVED[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def sections_for(stage: str) -> tuple[str, ...]:
    """The config sections one stage reads: its declared ``settings``, then those its registered metrics
    declare (:attr:`epa.metrics.spec.Metric.settings`)."""
    return tuple(dict.fromkeys(declared().by_name[stage].settings + registry.sections(stage)))


def settings_for(stage: str, cfg: dict) -> dict:
    """The part of a resolved config one stage reads (what the workflow puts in the rule's params)."""
    return {k: cfg[k] for k in sections_for(stage) if k in cfg}  # folders: only on a grid


# what the tables read besides the registered metrics' settings (error_comparison.txt, summary.csv,
# provenance of the sources)
TABLES_SETTINGS = ("tables", "metrics", "mode", "load", "sources")


def tables_settings(cfg: dict) -> dict:
    """The part of a resolved config the tables rule reads (``scripts/tables.py``): the tables', then
    every registered metric's sections (a section absent from ``cfg``: None)."""
    return {k: cfg.get(k) for k in dict.fromkeys(TABLES_SETTINGS + registry.sections())}


def previous(stage: str) -> str | None:
    names = declared().names
    k = names.index(stage)
    return names[k - 1] if k else None


def write_failure(folder: CaseFolder, stage: str, reason: str, *, arrays: bool = True) -> None:
    """Failure markers in each of a stage's artifacts (only its records where arrays are not written)."""
    st = declared().by_name[stage]
    folder.write_failure(stage, st.artifacts if arrays else st.records, reason)


def reads_under(stage: str, cfg: dict) -> frozenset[str]:
    """The values ``stage`` reads under the settings ``cfg`` (its ``reads_for``, else its reads)."""
    st = declared().by_name[stage]
    if st.reads_for is None:
        return frozenset(st.reads)
    reads = frozenset(st.reads_for(settings_for(stage, cfg)))
    if not reads <= set(st.reads):
        raise ValueError(
            f"stage {stage}: reads_for gives {sorted(reads - set(st.reads))}, not read"
        )
    return reads


def unread(data: case_module.CaseData, later: set[str]) -> list[str]:
    """The values in memory that no later stage reads (``later``: the values they read), nor any
    value they read that is not in memory and would be read again from them (its ``needs``): what
    run_case lets go. A value in memory is never read again, so what it was read from is not kept
    for it (a million poses: the cropped trajectories go after Step 2, not after the last stage)."""
    values = declared().values
    needed: set[str] = set()
    todo = list(later)
    while todo:
        name = todo.pop()
        if name not in needed:
            needed.add(name)
            if not data.known(name):
                todo += values[name].needs
    return [name for name in values if data.known(name) and name not in needed]


def run_stage(
    stage: str,
    data: case_module.CaseData,
    cfg: dict,
    *,
    write_arrays: bool = True,
    gone: frozenset[str] = frozenset(),
) -> None:
    """One stage for one case. Raises EpaError for a user mistake; any other exception is a bug
    (reading a value the stage does not declare it reads is one, and so is reading a value of
    ``gone``, which run_case let go)."""
    chain = declared()
    data.readable(chain.readable[stage] - gone)
    try:
        chain.by_name[stage].run(data, settings_for(stage, cfg), write_arrays)
    finally:
        data.readable(None)


def run_case(ref_path, est_path, out_dir, cfg: dict, **options) -> dict:
    """Every stage for one case in this process (``epa eval``); returns each stage's ``result``
    (the records that tell the case: metrics, drift, consistency, efficiency), by stage name. A user
    mistake raises EpaError after the failed stage's markers are written. ``options``: those of
    :func:`run_case_data`."""
    data = run_case_data(ref_path, est_path, out_dir, cfg, **options)
    return {st.name: getattr(data, st.result) for st in declared().stages if st.result is not None}


def run_case_data(
    ref_path,
    est_path,
    out_dir,
    cfg: dict,
    *,
    write_arrays: bool = False,
    on_stage: Callable[[str], None] | None = None,
    ref_source: dict | None = None,
    est_source: dict | None = None,
    keep: tuple[str, ...] = (),
    settings_record: dict | None = None,
) -> case_module.CaseData:
    """:func:`run_case`, returning the whole :class:`CaseData`. Every value stays in memory until
    no stage from there on reads it under ``cfg`` (:func:`reads_under`, :func:`unread`: a million
    poses with covariance, a few hundred MB less at the peak); each stage's ``result`` and the
    values named in ``keep`` stay (what the Python API, :func:`epa.evaluate`, hands on: every
    record and the per-pose errors, which are not on disk without ``write_arrays``).
    ``settings_record``: what the case's own settings changed (load.json ``settings``)."""
    chain = declared()
    case = Case("", "", "", Path(ref_path), Path(est_path), ref_source, est_source, settings_record)
    data = chain.data_class(CaseFolder(out_dir, case))
    kept = {st.result for st in chain.stages} | set(keep)
    reads = [reads_under(st.name, cfg) for st in chain.stages]
    gone: set[str] = set()
    for k, st in enumerate(chain.stages):
        if on_stage is not None:
            on_stage(st.name)
        # what a killed `epa eval --out` into this folder left, as a workflow job removes it
        data.folder.remove_temporaries(st.name, st.artifacts)
        try:
            run_stage(st.name, data, cfg, write_arrays=write_arrays, gone=frozenset(gone))
            # what no later stage reads under these settings goes (a value set again is back)
            let_go = [v for v in unread(data, set().union(*reads[k + 1 :])) if v not in kept]
            data.forget(*let_go)
            gone = {v for v in gone if not data.known(v)} | set(let_go)
        except EpaError as exc:
            write_failure(data.folder, st.name, f"{st.name}: {exc.one_line()}", arrays=write_arrays)
            if exc.path is None:  # a stage's finding about the case: name the estimate it is about
                raise EpaError(f"{st.name}: {exc.message}", path=str(est_path)) from None
            raise
    return data


def clear_arrays(folder: CaseFolder) -> None:
    """Remove array artifacts a previous run left (``epa eval`` without them must not leave stale ones)."""
    for st in declared().stages:
        for name in st.arrays:
            folder.remove(st.name, name)
