"""Consistency: NEES and ±3σ of the estimate's own covariance, in its own frames (08_consistency/).
Without covariance the record says ``"available": false``."""

from __future__ import annotations

import logging

from epa.artifacts.case import CaseData, Columns, Record
from epa.artifacts.stage import Stage, Value
from epa.core.trajectory import position_only
from epa.metrics import consistency
from epa.steps.align import Similarity
from epa.steps.calibrate import Extrinsic

log = logging.getLogger(__name__)

NAME = "consistency"


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    # the estimate as read: its covariance is in its own frames
    ref, est = data.matched
    calib = data.calibrate_record
    extrinsic = (
        Extrinsic.from_dict(calib["extrinsic"]) if calib["plan"]["apply_extrinsic"] else None
    )
    which = position_only(ref, est)
    if est.cov_rot is not None and which:
        reason = f"{which}: the NEES needs the rotation errors"
        summary: dict = {"available": False, "reason": reason}
        table: dict = {}
    else:
        summary, table = consistency.evaluate(
            ref, est, Similarity.from_dict(data.transform), extrinsic
        )
    if summary.get("available") is False and summary.get("reason"):
        log.info("consistency: %s", summary["reason"])
    data.consistency_record, data.nees = summary, table
    data.folder.write_optional_table(NAME, "nees.csv", table if write_arrays else None)
    data.folder.write_record(NAME, "consistency.json", summary)


def _nees(data: CaseData) -> Columns:
    """08_consistency/nees.csv, or {} without covariance"""
    return data.f.table(NAME, "nees.csv") if data.f.has(NAME, "nees.csv") else {}


STAGE = Stage(
    name=NAME,
    run=run,
    records=("consistency.json",),
    arrays=("nees.csv",),
    reads=("matched", "calibrate_record", "transform"),
    values=(
        Value("consistency_record", Record, lambda s: s.f.record(NAME, "consistency.json")),
        Value("nees", Columns, _nees),
    ),
    result="consistency_record",
)
