"""summary.csv (a row per case) and success_curves.csv."""

from __future__ import annotations

import csv
import io as _io

import numpy as np

from epa.metrics import registry
from epa.metrics.accuracy import segment_key, time_rpe_key, time_rpe_name
from epa.metrics.drift import CURVE_FACTORS
from epa.outputs.tables.cells import num, ok_runs, position_only, stat
from epa.outputs.tables.results import CaseResult

POSITION_ONLY_NOTE = "position-only estimate: its rotation columns are nan (no orientation)"

BASE_COLUMNS = [
    "algorithm",
    "dataset",
    "run",
    "status",
    "eval_source",
    "n_matched",
    "ate_trans_rmse_m",
    "ate_rot_rmse_deg",
    "time_rpe_1s_trans_mean_m",  # named after metrics.time_delta: time_rpe_columns
    "time_rpe_1s_rot_mean_deg",
    "time_offset_s",
    "time_offset_std_s",
    "step1_status",
    "extrinsic_rot_deg",
    "extrinsic_trans_m",
    "extrinsic_rot_std_deg",
    "extrinsic_trans_std_m",
    "step2_status",
    "success_rate_distance_pct",
    "success_auc_pct",
    "success_rate_time_pct",
    "global_failed",
    "knee_threshold_m",
    "fail_segments",
    "diverged_at_s",
]


def time_rpe_columns(time_delta: float) -> tuple[str, str]:
    """summary.csv's time-RPE columns (mean translation, mean rotation) under ``metrics.time_delta``."""
    name = time_rpe_name(time_delta)
    return f"time_rpe_{name}_trans_mean_m", f"time_rpe_{name}_rot_mean_deg"


def columns(segments, time_delta: float, metrics=None) -> list[str]:
    """summary.csv's columns: the base ones, each registered metric's (a scoring protocol's only
    when it is among ``metrics``, the enabled ones; None: every metric), notes, then per segment
    length."""
    renamed = dict(zip(time_rpe_columns(1.0), time_rpe_columns(time_delta)))
    base = [renamed.get(c, c) for c in BASE_COLUMNS]
    metric_cols = [
        col
        for metric in registry.REGISTRY
        if not metric.protocol or metrics is None or metric in metrics
        for col in metric.summary_columns
    ]
    seg_cols = []
    for s in segments:
        L = segment_key(s)
        seg_cols += [f"rpe_{L}m_trans_mean_m", f"rpe_{L}m_rot_mean_deg", f"drift_rate_{L}m_pct"]
    return base + metric_cols + ["notes"] + seg_cols


def _largest(values):
    """The largest per-axis deviation; None when an axis has none (unobservable) or none exist."""
    return None if not values or any(v is None for v in values) else max(values)


def _confidence(m: dict) -> dict:
    """summary.csv's Step 1 / Step 2 confidence columns from a case's metrics.json."""
    step1, calib = m.get("sync", {}).get("step1", {}), m.get("calibrate", {})
    ext = calib.get("extrinsic") or {}
    return {
        "time_offset_std_s": step1.get("std"),
        "step1_status": step1.get("status"),
        "extrinsic_rot_std_deg": _largest(ext.get("rotation_std_deg")),
        "extrinsic_trans_std_m": _largest(ext.get("translation_std_m")),
        "step2_status": calib.get("step2_status"),
    }


def summary_rows(
    grid: list[CaseResult], segments, time_delta: float, metrics=None
) -> tuple[list[str], list[dict]]:
    time_key, (time_trans, time_rot) = time_rpe_key(time_delta), time_rpe_columns(time_delta)
    rows = []
    for c in grid:
        m, d = c.metrics, c.drift
        row = {"algorithm": c.algorithm, "dataset": c.dataset, "run": c.run, "status": c.status}
        if c.ok:
            row.update(
                eval_source=m.get("eval_source"),
                n_matched=m.get("n_matched"),
                ate_trans_rmse_m=stat(m, "ate", "trans_m", "rmse"),
                ate_rot_rmse_deg=stat(m, "ate", "rot_deg", "rmse"),
                **{
                    time_trans: stat(m, time_key, "trans_m", "mean"),
                    time_rot: stat(m, time_key, "rot_deg", "mean"),
                },
                time_offset_s=m.get("time_offset_s"),
                extrinsic_rot_deg=m.get("extrinsic_rot_deg"),
                extrinsic_trans_m=m.get("extrinsic_trans_m"),
                **_confidence(m),
                success_rate_distance_pct=num(d.get("success_rate_distance_pct")),
                success_rate_time_pct=num(d.get("success_rate_time_pct")),
                global_failed=d.get("global_failed"),
                knee_threshold_m=stat(d, "knee", "threshold_m"),
                fail_segments=d.get("n_fail_segments"),
                diverged_at_s=d.get("diverged_at_s"),
            )
            for metric in registry.REGISTRY:
                row.update(metric.summary(c.record_of(metric)))
            # a stage after drift that failed (a broken timing file) leaves the accuracy standing
            failed = [r["failed"] for r in c.records.values() if r.get("failed")]
            warned = [w for w in (c.record_of(m).get("warning") for m in registry.REGISTRY) if w]
            if d.get("warning"):  # drift's thresholds do not fit the dataset
                warned.insert(0, d["warning"])
            # a position-only estimate's rotation columns are nan for want of an orientation
            only = [POSITION_ONLY_NOTE] if position_only(c) else []
            row["notes"] = "; ".join(failed + warned + only) or None
            for s in segments:
                L = segment_key(s)
                if L not in (m.get("rpe_distance") or {}):  # a length of other datasets: empty
                    continue
                row[f"rpe_{L}m_trans_mean_m"] = stat(m, "rpe_distance", L, "trans_m", "mean")
                row[f"rpe_{L}m_rot_mean_deg"] = stat(m, "rpe_distance", L, "rot_deg", "mean")
                row[f"drift_rate_{L}m_pct"] = stat(m, "drift_rate_pct", L)
        rows.append(row)
    return columns(segments, time_delta, metrics), rows


def records_csv(cols: list[str], rows: list[dict]) -> str:
    """CSV of dict rows: missing values empty, floats to 9 significant digits."""
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n", restval="")
    w.writeheader()
    for r in rows:
        w.writerow(
            {
                k: (
                    "" if r.get(k) is None else (f"{r[k]:.9g}" if isinstance(r[k], float) else r[k])
                )
                for k in cols
            }
        )
    return buf.getvalue()


def summary_csv(grid, segments, time_delta: float, metrics=None) -> str:
    return records_csv(*summary_rows(grid, segments, time_delta, metrics))


SUCCESS_CURVE_COLUMNS = [
    "algorithm",
    "dataset",
    "runs",
    "factor",
    "success_rate_distance_pct",
    "auc_pct",
]


def success_curves(grid: list[CaseResult]) -> list[dict]:
    """results/success_curves.csv rows: per algorithm and dataset, the distance success rate (% path,
    mean over the successful runs) with every drift threshold multiplied by each factor, and the area."""

    rows = []
    for alg in sorted({c.algorithm for c in grid}):
        for ds in sorted({c.dataset for c in grid}):
            curves = [
                c.drift["success_curve"]["success_rate_distance_pct"]
                for c in ok_runs(grid, alg, ds)
                if c.drift.get("success_curve")
            ]
            if curves:
                mean = np.nanmean(np.array(curves, float), axis=0)
                rows += [
                    {
                        "algorithm": alg,
                        "dataset": ds,
                        "runs": len(curves),
                        "factor": float(f),
                        "success_rate_distance_pct": float(v),
                        "auc_pct": float(np.mean(mean)),
                    }
                    for f, v in zip(CURVE_FACTORS, mean)
                ]
    return rows
