"""Drift detection: fail segments, success rate, the global gate and the drift-valid metrics, from
the metrics stage's per-pose and per-pair errors (07_drift/)."""

from __future__ import annotations

import logging

import numpy as np

from epa.artifacts.case import CaseData, Columns, Record
from epa.artifacts.stage import Stage, Value
from epa.metrics import accuracy, drift
from epa.metrics.accuracy import null_rotation

log = logging.getLogger(__name__)

NAME = "drift"


def compute(tables: dict, cfg: dict, metrics_record: dict | None = None):
    """The drift record and arrays of the metrics stage's ``tables``; ``metrics_record``, the
    record of the same errors, lends its statistics where every sample is drift-valid."""
    ape, seg, tp = tables["ape"], tables["rpe_segments"], tables["rpe_time"]
    det = drift.detect(
        ape["t"],
        ape["dist_m"],
        ape["trans_m"],
        ape["rot_deg"],
        tp["i"].astype(int),
        tp["j"].astype(int),
        tp["trans_m"],
        cfg["drift"],
    )
    valid, seg_valid, time_valid, notes = drift.valid_metrics(
        det,
        ape["trans_m"],
        ape["rot_deg"],
        seg,
        tp,
        accuracy.recorded_lengths(metrics_record)
        if metrics_record is not None and isinstance(cfg["metrics"]["segments"], str)
        else cfg["metrics"]["segments"],
        time_delta=cfg["metrics"]["time_delta"],
        known=metrics_record,
    )
    fs = det["fail_segments"]
    curve = drift.success_curve(
        ape["t"],
        ape["dist_m"],
        ape["trans_m"],
        tp["i"].astype(int),
        tp["j"].astype(int),
        tp["trans_m"],
        det["thresholds"],
    )
    summary = {
        "thresholds": det["thresholds"],
        "success_rate_distance_pct": det["success_rate_distance_pct"],
        "success_auc_pct": curve.pop("auc_pct"),
        "success_curve": curve,
        "success_rate_time_pct": det["success_rate_time_pct"],
        "global_failed": det["global_failed"],
        "ape_p5_m": det["ape_p5_m"],
        "knee": det["knee"],
        "n_fail_segments": int(len(fs["index_start"])),
        "first_fail_t": float(fs["t_start"][0] - ape["t"][0]) if len(fs["t_start"]) else None,
        # a fail segment that reaches the last pose: the run never recovered from there
        "diverged_at_s": (
            float(fs["t_start"][-1] - ape["t"][0])
            if len(fs["t_start"]) and fs["index_end"][-1] == len(ape["t"]) - 1
            else None
        ),
        "drift_valid": valid,
    }
    if det["global_failed"]:
        summary["status"] = (
            f"globally failed: 5th percentile APE {det['ape_p5_m']:.3g} m >"
            f" {cfg['drift']['global_fail_p5_m']} m"
            if det["ape_p5_m"] is not None
            else "globally failed: no finite APE"
        )
    if len(ape["rot_deg"]) and np.isnan(ape["rot_deg"]).all():  # a position-only estimate
        summary["drift_valid"] = null_rotation(valid)
    if notes:  # why a drift-valid quantity is empty (None); absent when none is
        summary["notes"] = notes
    misfit = thresholds_misfit(summary, metrics_record, cfg["drift"])
    if misfit:
        summary["warning"] = misfit
        log.warning("%s", misfit)
    artifacts = {
        "fail_segments": fs,
        "pose_valid": {"t": ape["t"], "valid": ~det["invalid"]},
        # row k: whether pair k of 06_metrics/rpe_segments.csv (rpe_time.csv) is drift-valid
        "rpe_segments_valid": {"valid": seg_valid},
        "rpe_time_valid": {"valid": time_valid},
    }
    return summary, artifacts


def thresholds_misfit(summary: dict, metrics_record: dict | None, c: dict) -> str | None:
    """A success rate of 100 % beside an ATE of several percent of the path: the thresholds do not
    fit the dataset's scale (an indoor sequence under metre thresholds, an arbitrary scale), so
    the success rate says nothing. None where it fits."""
    if not metrics_record or summary["success_rate_distance_pct"] != 100.0:
        return None
    rmse, length = metrics_record["ate"]["trans_m"]["rmse"], metrics_record["ref_length_m"]
    if rmse is None or not length or 100.0 * rmse / length <= c["max_ate_path_pct"]:
        return None
    fix = (
        "set drift.mode: scale_aware, or the thresholds under overrides.datasets"
        if c["mode"] == "fixed"
        else "set tighter thresholds (drift.scale_rpe_factor, drift.scale_jump_factor)"
    )
    return (
        f"success rate 100 % beside an ATE RMSE of {rmse:.4g} m, {100.0 * rmse / length:.3g} % of"
        f" the {length:.4g} m path (> drift.max_ate_path_pct {c['max_ate_path_pct']:g}): the drift"
        f" thresholds do not fit this dataset's scale; {fix}"
    )


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    tables = {"ape": data.ape, "rpe_segments": data.rpe_segments, "rpe_time": data.rpe_time}
    summary, artifacts = compute(tables, cfg, data.metrics_record)
    data.drift_record, data.fail_segments = summary, artifacts["fail_segments"]
    if write_arrays:
        for name in STAGE.arrays:
            data.folder.write_table(NAME, name, artifacts[name.removesuffix(".csv")])
    data.folder.write_record(NAME, "drift.json", summary)


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("drift", "metrics"),
    records=("drift.json",),
    arrays=("fail_segments.csv", "pose_valid.csv", "rpe_segments_valid.csv", "rpe_time_valid.csv"),
    reads=("ape", "rpe_segments", "rpe_time", "metrics_record"),
    values=(
        Value("drift_record", Record, lambda s: s.f.record(NAME, "drift.json")),
        Value("fail_segments", Columns, lambda s: s.f.table(NAME, "fail_segments.csv")),
    ),
    result="drift_record",
)
