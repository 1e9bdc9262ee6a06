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


def errors(ref: Trajectory, est: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """The yaw error in degrees, signed, as the z component of the rotation vector of
    R_est R_ref^T (the error in the world frame: ov_eval's JPL quat_2_Rot(q_est)^T quat_2_Rot(q_gt)
    is this world-from-body product), and the planar position error |xy_ref - xy_est| in metres.

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose, the estimate aligned.

    Returns
    -------
    yaw_deg, trans_xy_m : ndarray
    """
    yaw = np.empty(len(ref))
    # quat_mul(est.q, quat_conj(ref.q)) and quat_log's z, in blocks: the temporaries in cache
    for part in geometry.row_blocks(len(ref)):
        conj = geometry.component_rows(ref.q[part])
        conj[:3] *= -1
        error = geometry.mul_rows(geometry.component_rows(est.q[part]), conj)
        yaw[part] = np.degrees(geometry.log_rows(error)[2])
    return yaw, geometry.norms(ref.p[:, :2] - est.p[:, :2])


def compute(ref: Trajectory, est: Trajectory, cfg: dict) -> tuple[dict, dict, list[str]]:
    yaw, trans_xy = errors(ref, est)
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
    arrays=(),  # its per-pose columns (yaw_deg, trans_xy_m) extend ape.csv
    tables=_TABLES,
)
