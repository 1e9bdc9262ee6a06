"""Scale that hides a failure: beside a Sim3 alignment's ATE, the scale it fitted and the ATE of an
SE3 fit of the same matched poses, and a warning when the scale may hide what the SE3 ATE shows.

A Sim3 fit absorbs any error that looks like a scale: a run that drifted or collapsed can read a few
centimetres under Sim3 and a metre under SE3 (a published case: 122 cm against 1.6 cm). Active when
``align.method`` is ``sim3`` (``metrics.sim3_check.enabled``, on by default); nothing is added
otherwise. Two checks:

- **scale**, for an algorithm declared metric (``sources.algorithms.<alg>.metric_scale: true``:
  stereo, VIO, LiDAR): ``|ln s| > metrics.sim3_check.max_log_scale`` (0.05, about 5 %);
- **ratio**, unless the algorithm is declared not metric (``metric_scale: false``: monocular, its
  scale arbitrary, the SE3 ATE meaningless): the SE3 ATE RMSE over the Sim3 one above
  ``metrics.sim3_check.max_ate_ratio`` (10).

The SE3 fit is of the estimate at its own scale, the aligned one divided by s (a rigid motion of
the calibrated estimate, so its SE3 fit and ATE are that estimate's), on the same first N matched
poses as the Sim3 fit (``align.first_n``). One Umeyama fit and one ATE: linear in the poses.
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
    return bool(cfg["metrics"]["sim3_check"]["enabled"]) and cfg["align"]["method"] == "sim3"


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


def compute(
    ref: Trajectory, est: Trajectory, cfg: dict, *, transform: dict, estimate_source: dict
) -> tuple[dict, dict, list[str]]:
    c = cfg["metrics"]["sim3_check"]
    fitted = transform
    if fitted.get("method") != "sim3":  # the ov_eval fallback aligns SE3
        why = " (the ov_eval fallback)" if fitted.get("fallback_se3") else ""
        record = {
            "available": False,
            "reason": f"Step 3 fitted {fitted.get('method')}{why}: no scale",
        }
        return record, {}, []
    scale = float(fitted["scale"])
    trans, rot = se3_beside(ref, est, scale, fitted["first_n"])
    se3 = {"trans_m": stats(trans), "rot_deg": stats(rot)}
    sim3_rmse = float(np.sqrt(np.mean(np.sum(np.square(est.p - ref.p), axis=1))))  # the ATE's
    se3_rmse = se3["trans_m"]["rmse"]
    declared = estimate_source.get("metric_scale")
    warnings = findings(scale, se3_rmse, sim3_rmse, declared, c)
    record = {
        "available": True,
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
    """One run's Sim3 scale and SE3 ATE RMSE (m)."""
    return record["scale"], record["ate_se3"]["trans_m"]["rmse"]


def note(records: list[dict]) -> str | None:
    """An algorithm's table note: how many of its runs warn."""
    warned = sum(1 for r in records if r.get("warning"))
    return f"scale warning: {warned} of {len(records)} runs" if warned else None


def summary(record: dict) -> dict:
    return {}


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
    key="sim3_check",  # metrics.sim3_check; only with align.method: sim3
    stage="metrics",
    enabled=enabled,
    summary=summary,  # summary.csv: its warning in the notes column
    settings=("metrics.sim3_check", "align.method"),
    compute=compute,
    after="ate",  # beside the (Sim3) ATE in metrics.json
    inputs=("transform", "estimate_source"),  # Step 3's scale; the metric_scale declaration
    tables=_TABLES,
)
