"""Efficiency: frame-time statistics and EA-Drift from the run's timing file (09_efficiency/).
Without timing the record says ``"available": false``."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from epa.artifacts.case import CaseData, Record
from epa.artifacts.stage import Stage, Value
from epa.core import ranks
from epa.core.errors import EpaError
from epa.metrics import efficiency

log = logging.getLogger(__name__)

NAME = "efficiency"


def compute(t_est, ape: dict, est_length_m: float, timing, dataset: str, cfg: dict):
    """Runtime statistics and EA-Drift of one case (see :mod:`epa.metrics.efficiency`)."""
    c = cfg["efficiency"]
    rate = c["datasets"].get(dataset, c["sensor_rate_hz"])
    note = None
    if rate is None:  # not configured: the timing file's own frame rate
        dt = np.diff(efficiency.in_order(timing[0])[1])
        rate = 1.0 / ranks.median(dt[dt > 0]) if (dt > 0).any() else None
        if rate is None:
            raise EpaError("set efficiency.sensor_rate_hz (the timing file's stamps give no rate)")
        note = f"sensor rate {rate:.3f} Hz from the timing file's stamps (efficiency.sensor_rate_hz not set)"
        log.warning("%s", note)
    summary, table = efficiency.evaluate(
        np.asarray(t_est),
        np.asarray(ape["t"]),
        np.asarray(ape["trans_m"]),
        est_length_m,
        timing,
        rate,
        c["max_diff"],
    )
    if note:
        summary["notes"] = [note]
    if summary.get("n_without_timing"):
        log.warning(
            "%d of %d poses have no timing entry within %s s: left out of EA-Drift",
            summary["n_without_timing"],
            summary["n_poses"],
            c["max_diff"],
        )
    return summary, table


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    load = data.load_record
    if load.get("timing_error"):
        err = load["timing_error"]
        raise EpaError(err["message"], path=err["path"], line=err["line"])
    timing = data.timing
    if timing is None:
        summary, table = {"available": False, "reason": "no timing file for this run"}, {}
    else:
        if data.known("matched") or data.known("calibrated"):
            t_est = data.matched[1].t
        else:  # the matched estimate stamps, without parsing a trajectory
            t_est = data.folder.table("calibrate", "pairs.csv")["t_est"]
        length = data.metrics_record["est_length_m"]
        dataset = Path(load["ref_file"]).stem  # discovery names a dataset by its reference's stem
        summary, table = compute(
            t_est, data.ape, length, (timing["t"], timing["frame_ms"]), dataset, cfg
        )
    data.efficiency_record = summary
    data.folder.write_optional_table(NAME, "frames.csv", table if write_arrays else None)
    data.folder.write_record(NAME, "efficiency.json", summary)


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("efficiency",),
    records=("efficiency.json",),
    arrays=("frames.csv",),
    reads=("load_record", "timing", "matched", "metrics_record", "ape"),
    values=(Value("efficiency_record", Record, lambda s: s.f.record(NAME, "efficiency.json")),),
    result="efficiency_record",
)
