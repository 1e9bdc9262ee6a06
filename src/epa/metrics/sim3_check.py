"""Scale that hides a failure: beside a Sim3 alignment's ATE, the scale it fitted and the ATE of an
SE3 fit of the same matched poses, and a warning when the scale may hide what the SE3 ATE shows.

A Sim3 fit absorbs any error that looks like a scale: a run that drifted or collapsed can read a few
centimetres under Sim3 and a metre under SE3 (a published case: 122 cm against 1.6 cm). Active when
``align.method`` is ``sim3``. Two checks there:

- **scale**, for an algorithm declared metric (``sources.algorithms.<alg>.metric_scale: true``:
  stereo, VIO, LiDAR): ``|ln s| > metrics.sim3_check.max_log_scale`` (0.05, about 5 %);
- **ratio**, unless the algorithm is declared not metric (``metric_scale: false``: monocular, its
  scale arbitrary, the SE3 ATE meaningless): the SE3 ATE RMSE over the Sim3 one above
  ``metrics.sim3_check.max_ate_ratio`` (10).

The SE3 fit is of the estimate at its own scale, the aligned one divided by s (a rigid motion of
the calibrated estimate, so its SE3 fit and ATE are that estimate's), on the same first N matched
poses as the Sim3 fit (``align.first_n``). One Umeyama fit and one ATE: linear in the poses.

Under an alignment without scale (se3, posyaw, none) the check is the mirror: a Sim3 fit of the
aligned estimate beside its ATE. A scale beyond ``max_log_scale`` whose fit removes more than
``min_error_removed`` of the ATE RMSE, leaving under ``max_residual_path_pct`` of the path, is a
warning (unless the algorithm is declared not metric): an undeclared monocular estimate, whose SE3
numbers mean nothing. (A diverged run's Sim3 fit shrinks it and still leaves metres: drift
detection's finding, not a scale to declare.) One Umeyama fit, positions only.
Every case is checked (``metrics.sim3_check.enabled``, on by default).
"""

from __future__ import annotations

import math

import numpy as np

from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.metrics.accuracy import ape, stats
from epa.metrics.spec import Metric, Table
from epa.steps import align as alignment


def enabled(cfg: dict) -> bool:
    return bool(cfg["metrics"]["sim3_check"]["enabled"])


def se3_beside(ref: Trajectory, est: Trajectory, scale: float, first_n: int) -> tuple:
    """The ATE of an SE3 fit of the same matched poses as a Sim3 fit.

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose, ``est`` aligned by the Sim3 fit of scale ``scale``.
    scale : float
        The Sim3 fit's scale (> 0).
    first_n : int
        The poses the Sim3 fit used (``align.first_n``, -1: all); the SE3 fit uses the same.

    Returns
    -------
    trans_m, rot_deg : ndarray
        Per matched pose, the translation and rotation error after the SE3 fit.
    """
    own = est.p / scale  # R x + t / s: a rigid motion of the estimate
    n = len(ref) if first_n < 0 else min(first_n, len(ref))
    fit = alignment.umeyama(own[:n], ref.p[:n])  # poses the Sim3 fit found determined
    # only positions and quaternions move (no rotation matrices: a third of the cost at 1M poses)
    q = geometry.quat_mul(geometry.rot_to_quat(fit.R), est.q)
    return ape(ref, Trajectory(est.t, own @ fit.R.T + fit.t, q))


def findings(
    scale: float, se3_rmse: float, sim3_rmse: float, metric_scale: bool | None, c: dict
) -> list[str]:
    """The warnings of one case (empty: none), each one sentence with its numbers."""
    out = []
    if metric_scale and abs(math.log(scale)) > c["max_log_scale"]:
        out.append(
            f"Sim3 scale {scale:.4g} for an algorithm declared metric (metric_scale: true):"
            f" |ln s| = {abs(math.log(scale)):.3g} > {c['max_log_scale']:g};"
            f" the SE3 ATE is {se3_rmse:.4g} m against {sim3_rmse:.4g} m under Sim3"
        )
    if metric_scale is not False:
        hidden = se3_rmse > c["max_ate_ratio"] * sim3_rmse  # also when the Sim3 ATE is 0
        if hidden:
            out.append(
                f"the SE3 ATE ({se3_rmse:.4g} m) is more than {c['max_ate_ratio']:g} times the Sim3"
                f" ATE ({sim3_rmse:.4g} m): the Sim3 scale ({scale:.4g}) hides most of the error"
                + (
                    ""
                    if metric_scale
                    else " (declare metric_scale: false if its scale is arbitrary)"
                )
            )
    return out


def sim3_beside(
    ref: Trajectory, est: Trajectory, first_n: int, rows: np.ndarray | None = None
) -> tuple[float, float]:
    """The scale and ATE RMSE (m) of a Sim3 fit of matched positions aligned without scale.

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose, ``est`` as Step 3 aligned it (se3, posyaw or none).
    first_n : int
        The poses Step 3 fitted on (``align.first_n``, -1: all); the Sim3 fit uses the same (every
        pose where Step 3 used fewer than 3).
    rows : ndarray, optional
        :func:`epa.core.geometry.pair_rows` of the pair (its position rows are read).

    Returns
    -------
    scale, rmse : float
        The fitted scale s (est -> ref) and the position RMSE after the fit.
    """
    # Step 3 on 1 or 2 poses (mode rpg) determines no Sim3: the estimate's scale on every pose
    n = len(ref) if first_n < 3 else min(first_n, len(ref))
    if n == len(ref):  # fitted on every pose: on component rows, in blocks
        ref_rows = rows[4:7] if rows is not None else np.ascontiguousarray(ref.p.T)
        est_rows = rows[7:10] if rows is not None else np.ascontiguousarray(est.p.T)
        return alignment.sim3_fit_rmse(est_rows, ref_rows)
    fit = alignment.umeyama(est.p[:n], ref.p[:n], with_scale=True)
    moved = fit.s * (est.p @ fit.R.T) + fit.t
    return float(fit.s), float(np.sqrt(np.mean(np.sum(np.square(moved - ref.p), axis=1))))


def unscaled_findings(
    scale: float,
    fitted_rmse: float,
    sim3_rmse: float,
    metric_scale: bool | None,
    c: dict,
    path_m: float,
) -> list[str]:
    """The warning of a case aligned without scale whose Sim3 fit finds one far from 1 that removes
    most of its error, leaving little (under ``max_residual_path_pct`` of the ``path_m`` metres of
    matched reference path): the recipe does not fit the estimate. Empty: none. A fit that still
    leaves much is a run that failed, whatever its scale: drift detection's finding, not this one."""
    if metric_scale is False or not fitted_rmse > 0:
        return []
    removed = 1.0 - sim3_rmse / fitted_rmse
    if abs(math.log(scale)) <= c["max_log_scale"] or removed <= c["min_error_removed"]:
        return []
    if not path_m > 0 or 100.0 * sim3_rmse / path_m > c["max_residual_path_pct"]:
        return []
    what = (
        "for an algorithm declared metric (metric_scale: true): its scale is wrong"
        if metric_scale
        else "if its scale is arbitrary (monocular), declare"
        " sources.algorithms.<algorithm>.metric_scale: false to evaluate it with Sim3"
    )
    return [
        f"a Sim3 fit finds scale {scale:.4g} (|ln s| = {abs(math.log(scale)):.3g} >"
        f" {c['max_log_scale']:g}) and removes {100 * removed:.0f} % of the ATE"
        f" ({fitted_rmse:.4g} m -> {sim3_rmse:.4g} m): {what}"
    ]


def estimate_scale(transform: dict, calibrate_record: dict | None) -> dict | None:
    """The scale a case was evaluated with (reference metres per estimate unit), where anything
    fitted one: Step 2's (applied by the plan) times Step 3's Sim3 scale, with Step 2's standard
    deviation carried through Step 3's factor (Step 3's own has none). None: no scale fitted."""
    plan = (calibrate_record or {}).get("plan") or {}
    ext = (calibrate_record or {}).get("extrinsic") or {}
    step2 = ext.get("scale") if plan.get("apply_extrinsic") else None
    step3 = transform.get("scale") if transform.get("method") == "sim3" else None
    if step2 is None and step3 is None:
        return None
    s3 = 1.0 if step3 is None else float(step3)
    std = ext.get("scale_std") if step2 is not None else None
    return {
        "value": (1.0 if step2 is None else float(step2)) * s3,
        "std": None if std is None else float(std) * s3,
        "fitted_by": "+".join(
            name for name, v in (("step2", step2), ("step3", step3)) if v is not None
        ),
    }


def compute(
    ref: Trajectory,
    est: Trajectory,
    cfg: dict,
    *,
    transform: dict,
    estimate_source: dict,
    calibrate_record: dict | None = None,
    accuracy: dict | None = None,
    pair_rows: np.ndarray | None = None,
) -> tuple[dict, dict, list[str]]:
    c = cfg["metrics"]["sim3_check"]
    fitted = transform
    declared = estimate_source.get("metric_scale")
    if fitted.get("method") != "sim3":  # the recipe fitted no scale: does the estimate need one?
        # the case's own ATE, as its tables print it
        fitted_rmse = (
            float(accuracy["ate"]["trans_m"]["rmse"])
            if accuracy is not None
            else float(np.sqrt(np.mean(np.sum(np.square(est.p - ref.p), axis=1))))
        )
        # the estimate's extent per axis, on pair_rows' position rows where given: numpy reduces
        # the (N, 3) positions' columns 100x slower than contiguous rows (11 ms at 100,000 poses)
        positions = pair_rows[7:10] if pair_rows is not None else est.p.T
        if len(ref) < 3 or not np.ptp(positions, axis=1).any():
            reason = "fewer than 3 matched poses" if len(ref) < 3 else "the estimate does not move"
            return {"available": False, "reason": f"no Sim3 fit: {reason}"}, {}, []
        scale, sim3_rmse = sim3_beside(ref, est, fitted["first_n"], pair_rows)
        path = float(accuracy["ref_length_m"]) if accuracy is not None else ref.length()
        warnings = unscaled_findings(scale, fitted_rmse, sim3_rmse, declared, c, path)
        record = {
            "available": True,
            "fitted": fitted.get("method"),
            "evaluated_scale": estimate_scale(fitted, calibrate_record),
            "scale": scale,
            "log_scale": math.log(scale),
            "metric_scale": declared,
            "ate_rmse_m": fitted_rmse,
            "ate_sim3_rmse_m": sim3_rmse,
            "error_removed": 1.0 - sim3_rmse / fitted_rmse if fitted_rmse > 0 else None,
            "thresholds": {
                "max_log_scale": c["max_log_scale"],
                "min_error_removed": c["min_error_removed"],
                "max_residual_path_pct": c["max_residual_path_pct"],
            },
            "warning": "; ".join(warnings) or None,
        }
        return record, {}, warnings
    scale = float(fitted["scale"])
    trans, rot = se3_beside(ref, est, scale, fitted["first_n"])
    se3 = {"trans_m": stats(trans), "rot_deg": stats(rot)}
    sim3_rmse = float(np.sqrt(np.mean(np.sum(np.square(est.p - ref.p), axis=1))))  # the ATE's
    se3_rmse = se3["trans_m"]["rmse"]
    warnings = findings(scale, se3_rmse, sim3_rmse, declared, c)
    record = {
        "available": True,
        "fitted": "sim3",
        "evaluated_scale": estimate_scale(fitted, calibrate_record),
        "scale": scale,
        "log_scale": math.log(scale),
        "metric_scale": declared,
        "ate_se3": se3,
        # a Sim3 ATE of 0 leaves the ratio undefined (never inf): the SE3 ATE says the rest
        "ate_ratio": se3_rmse / sim3_rmse if sim3_rmse > 0 else None,
        "thresholds": {"max_log_scale": c["max_log_scale"], "max_ate_ratio": c["max_ate_ratio"]},
        "warning": "; ".join(warnings) or None,
    }
    return record, {}, warnings


def _has(record: dict) -> bool:
    return bool(record.get("available"))


def per_run(record: dict) -> tuple[float, float]:
    """One run's Sim3 scale and SE3 ATE RMSE (m): under Sim3 the SE3 fit's beside it, else the
    case's own ATE (its alignment has no scale)."""
    if "ate_se3" in record:
        return record["scale"], record["ate_se3"]["trans_m"]["rmse"]
    return record["scale"], record["ate_rmse_m"]


def note(records: list[dict]) -> str | None:
    """An algorithm's table note: how many of its runs warn."""
    warned = sum(1 for r in records if r.get("warning"))
    return f"scale warning: {warned} of {len(records)} runs" if warned else None


def summary(record: dict) -> dict:
    """summary.csv: the alignment Step 3 fitted and the scale the case was evaluated with."""
    scale = record.get("evaluated_scale") or {}
    return {
        "alignment": record.get("fitted"),
        "scale": scale.get("value"),
        "scale_std": scale.get("std"),
    }


_TABLES = (
    Table(
        "sim3_check",
        "SIM3 SCALE LATEX TABLE (SCALE / SE3 ATE RMSE M BESIDE THE SIM3 ATE, MEAN OVER RUNS)",
        per_run=per_run,
        has=_has,
        note=note,
        after="ate",
    ),
)


METRIC = Metric(
    key="sim3_check",  # metrics.sim3_check; every case
    stage="metrics",
    enabled=enabled,
    summary=summary,  # summary.csv: its warning in the notes column
    settings=("metrics.sim3_check",),
    compute=compute,
    after="ate",  # beside the (Sim3) ATE in metrics.json
    # Step 3's scale; the metric_scale declaration; Step 2's scale
    inputs=("transform", "estimate_source", "calibrate_record", "accuracy", "pair_rows"),
    summary_columns=("alignment", "scale", "scale_std"),
    tables=_TABLES,
)
