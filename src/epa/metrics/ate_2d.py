"""ATE 2D, ov_eval's ``ResultTrajectory::calculate_ate_2d``: the world-frame yaw error and the planar
position error of each aligned matched pose."""

from __future__ import annotations

import numpy as np

from epa.core import geometry
from epa.core.trajectory import Trajectory, position_only
from epa.metrics.accuracy import stats
from epa.metrics.spec import Metric, Table


def enabled(cfg: dict) -> bool:
    return True


def errors(ref: Trajectory, est: Trajectory, rows=None) -> tuple[np.ndarray, np.ndarray]:
    """The yaw error in degrees, signed, as the z component of the rotation vector of
    R_est R_ref^T (the error in the world frame: ov_eval's JPL quat_2_Rot(q_est)^T quat_2_Rot(q_gt)
    is this world-from-body product), and the planar position error |xy_ref - xy_est| in metres.

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose, the estimate aligned.
    rows : ndarray, optional
        geometry.pair_rows of the same poses made from their quaternions (the metrics stage's):
        D = q_ref conj(q_est) is the conjugate of the yaw's quaternion, its components the same
        products and sums negated (exactly), so the same bits without a product of its own.

    Returns
    -------
    yaw_deg, trans_xy_m : ndarray
    """
    if rows is None:
        return _yaw(ref.q, est.q), geometry.norms(ref.p[:, :2] - est.p[:, :2])
    yaw = np.empty(len(ref))
    for part in geometry.row_blocks(len(ref)):
        yaw[part] = geometry.log_rows(rows[:4, part])[2]
    np.degrees(np.negative(yaw, out=yaw), out=yaw)
    # a zero's sign and a NaN's are what the negation may not give (+0 where q_est conj(q_ref)
    # has -0, and the reverse): those few poses from their own product
    zero = np.flatnonzero(~(np.abs(yaw) > 0))
    if len(zero):
        yaw[zero] = _yaw(ref.q[zero], est.q[zero])
    dx, dy = rows[4] - rows[7], rows[5] - rows[8]  # ref - est: norms' squares summed x then y
    return yaw, np.sqrt(np.add(np.multiply(dx, dx, out=dx), np.multiply(dy, dy, out=dy), out=dx))


def _yaw(q_ref: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """errors' yaw from the quaternions: quat_mul(q_est, quat_conj(q_ref)) and quat_log's z, in
    blocks (the temporaries in cache)."""
    yaw = np.empty(len(q_ref))
    for part in geometry.row_blocks(len(q_ref)):
        conj = geometry.component_rows(q_ref[part])
        conj[:3] *= -1
        error = geometry.mul_rows(geometry.component_rows(q_est[part]), conj)
        yaw[part] = np.degrees(geometry.log_rows(error)[2])
    return yaw


def compute(
    ref: Trajectory, est: Trajectory, cfg: dict, pair_rows=None
) -> tuple[dict, dict, list[str]]:
    yaw, trans_xy = errors(ref, est, pair_rows)
    measured = np.zeros(0) if position_only(ref, est) else yaw  # NaN there: no yaw error at all
    record = {
        "yaw_deg": stats(measured),  # signed: its rmse is ov_eval's
        "trans_xy_m": stats(trans_xy),
    }
    return record, {"ape": {"yaw_deg": yaw, "trans_xy_m": trans_xy}}, []


def _rmse(record: dict, key: str) -> float:
    value = (record.get(key) or {}).get("rmse")
    return np.nan if value is None else float(value)


def per_run(record: dict) -> tuple[float, float]:
    """One run's ATE 2D RMSE: yaw (deg), planar position (m)."""
    return _rmse(record, "yaw_deg"), _rmse(record, "trans_xy_m")


def summary(record: dict) -> dict:
    return {}


_TABLES = (
    Table(
        "ate_2d",
        "FULL TRAJECTORY ATE 2D LATEX TABLE (YAW DEG / XY M)",
        per_run=per_run,
        after="ate",
    ),
)


METRIC = Metric(
    key="ate_2d",
    stage="metrics",
    enabled=enabled,
    summary=summary,
    compute=compute,
    after="ate",  # its record follows the ATE's in metrics.json
    orientation=False,  # its planar error stands for a position-only estimate; its yaw is null
    inputs=("pair_rows",),  # the metrics stage's D rows: its yaw without a product of its own
    arrays=(),  # its per-pose columns (yaw_deg, trans_xy_m) extend ape.csv
    tables=_TABLES,
)
