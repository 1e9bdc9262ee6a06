"""The stage chain, defined once: the stage modules in the order they run.

``epa eval`` runs :func:`run_case` (every stage in one process, values passed in memory through one
:class:`~epa.artifacts.case.CaseData`); a workflow job runs one stage for a batch of cases
(:mod:`epa.workflow.jobs`), each stage reading what it needs from the previous stages' artifacts.
Both call the same stage modules, so the command line and the workflow write the same
``metrics.json``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from epa.artifacts.case import Case, CaseData, CaseFolder
from epa.core.errors import EpaError
from epa.metrics import registry
from epa.workflow.stages import (
    align,
    calibrate,
    consistency,
    crop,
    drift,
    efficiency,
    load,
    metrics,
    report,
    sync,
)

STAGES = (load, crop, sync, calibrate, align, metrics, drift, consistency, efficiency, report)
BY_NAME = {stage.NAME: stage for stage in STAGES}
NAMES = tuple(BY_NAME)
# run_case keeps every stage's values in memory; these trajectories are let go once the last stage
# that reads them has run (a million poses with covariance: about 0.7 GB less at the peak).
LAST_READER = {"loaded": "crop", "sync_matched": "calibrate", "calibrated": "metrics"}


def artifacts(stage) -> tuple[str, ...]:
    return stage.RECORDS + stage.ARRAYS


def sections_for(stage: str) -> tuple[str, ...]:
    """The config sections one stage reads: its ``SETTINGS``, then those its registered metrics
    declare (:attr:`epa.metrics.spec.Metric.settings`)."""
    return tuple(dict.fromkeys(BY_NAME[stage].SETTINGS + registry.sections(stage)))


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
    k = NAMES.index(stage)
    return NAMES[k - 1] if k else None


def write_failure(folder: CaseFolder, stage: str, reason: str, *, arrays: bool = True) -> None:
    """Failure markers in each of a stage's artifacts (only its records where arrays are not written)."""
    st = BY_NAME[stage]
    folder.write_failure(stage, artifacts(st) if arrays else st.RECORDS, reason)


def run_stage(stage: str, data: CaseData, cfg: dict, *, write_arrays: bool = True) -> None:
    """One stage for one case. Raises EpaError for a user mistake; any other exception is a bug."""
    BY_NAME[stage].run(data, settings_for(stage, cfg), write_arrays)


def run_case(
    ref_path,
    est_path,
    out_dir,
    cfg: dict,
    *,
    write_arrays: bool = False,
    on_stage: Callable[[str], None] | None = None,
    ref_source: dict | None = None,
    est_source: dict | None = None,
) -> dict:
    """Every stage for one case in this process (``epa eval``); returns each record that tells the
    case: metrics, drift, consistency, efficiency. A user mistake raises EpaError after the failed
    stage's markers are written."""
    data = run_case_data(
        ref_path,
        est_path,
        out_dir,
        cfg,
        write_arrays=write_arrays,
        on_stage=on_stage,
        ref_source=ref_source,
        est_source=est_source,
    )
    return {
        "metrics": data.metrics_record,
        "drift": data.drift_record,
        "consistency": data.consistency_record,
        "efficiency": data.efficiency_record,
    }


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
) -> CaseData:
    """:func:`run_case`, returning the whole :class:`CaseData` (every stage's record and, in memory,
    the per-pose errors): what the Python API (:func:`epa.evaluate`) hands on."""
    case = Case("", "", "", Path(ref_path), Path(est_path), ref_source, est_source)
    data = CaseData(CaseFolder(out_dir, case))
    for st in STAGES:
        if on_stage is not None:
            on_stage(st.NAME)
        try:
            run_stage(st.NAME, data, cfg, write_arrays=write_arrays)
            data.forget(*(name for name, last in LAST_READER.items() if last == st.NAME))
        except EpaError as exc:
            write_failure(data.folder, st.NAME, f"{st.NAME}: {exc.one_line()}", arrays=write_arrays)
            if exc.path is None:  # a stage's finding about the case: name the estimate it is about
                raise EpaError(f"{st.NAME}: {exc.message}", path=str(est_path)) from None
            raise
    return data


def clear_arrays(folder: CaseFolder) -> None:
    """Remove array artifacts a previous run left (``epa eval`` without them must not leave stale ones)."""
    for st in STAGES:
        for name in st.ARRAYS:
            folder.remove(st.NAME, name)
