"""Per-axis errors (evo's long-standing request, its issue #554): the ATE and the distance RPE split
into x, y, z (m) and roll, pitch, yaw (deg). ``metrics.per_axis: true``; off by default.

- ATE: the world-frame position error est - ref of each aligned matched pose, and the orientation
  error E = R_ref^T R_est (the body-frame error) as Z-Y-X Euler angles: yaw about z, pitch about y,
  roll about x, each in (-180, 180]. Signed, so a bias shows as a mean.
- RPE: for every distance-RPE pair (i, j) of each segment length (the RPE's own pairs), the
  relative motions A = Q_i^-1 Q_j (reference) and B = P_i^-1 P_j (estimate): the translation error
  t_B - t_A in the frame of pose i (its norm is the RPE's translation error) and R_A^T R_B as Euler
  angles (its angle is the RPE's rotation error).
"""

from __future__ import annotations

import numpy as np

from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.metrics.accuracy import segment_key, segment_pairs, stats
from epa.metrics.spec import Metric, Table

AXES = ("x", "y", "z", "roll", "pitch", "yaw")
UNITS = ("m", "m", "m", "deg", "deg", "deg")


def enabled(cfg: dict) -> bool:
    return bool(cfg["metrics"]["per_axis"])


def euler_zyx_deg(r: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (deg) of rotation matrices (..., 3, 3), R = Rz(yaw) Ry(pitch) Rx(roll).

    Parameters
    ----------
    r : ndarray (..., 3, 3)

    Returns
    -------
    ndarray (..., 3)
        roll, pitch, yaw in degrees.
    """
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    pitch = np.arcsin(np.clip(-r[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    return np.degrees(np.stack([roll, pitch, yaw], axis=-1))


def ate_errors(ref: Trajectory, est: Trajectory) -> np.ndarray:
    """(N, 6): x, y, z (m) and roll, pitch, yaw (deg) of each aligned matched pose's error.

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose, the estimate aligned.

    Returns
    -------
    ndarray (N, 6)
    """
    rot = np.einsum("nba,nbc->nac", ref.r, est.r)  # R_ref^T R_est
    return np.column_stack([est.p - ref.p, euler_zyx_deg(rot)])


def rpe_errors(ref: Trajectory, est: Trajectory, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """(M, 6): per-axis relative errors of the pairs (i, j), in the frame of pose i."""
    q_a, t_a = geometry.relative_motions(ref.q, ref.p, i, j)
    q_b, t_b = geometry.relative_motions(est.q, est.p, i, j)
    rot = geometry.quat_to_rot(geometry.quat_mul(geometry.quat_conj(q_a), q_b))
    return np.column_stack([t_b - t_a, euler_zyx_deg(rot)])


def _stats(errors: np.ndarray) -> dict:
    return {f"{a}_{u}": stats(errors[:, k]) for k, (a, u) in enumerate(zip(AXES, UNITS))}


def compute(ref: Trajectory, est: Trajectory, cfg: dict) -> tuple[dict, dict, list[str]]:
    ate = ate_errors(ref, est)
    dist = geometry.path_distances(ref.p)
    rpe = {}
    for length in cfg["metrics"]["segments"]:
        i, j = segment_pairs(dist, float(length), cfg["metrics"]["segment_tol"])
        rpe[segment_key(length)] = _stats(rpe_errors(ref, est, i, j))
    columns = {f"err_{a}_{u}": ate[:, k] for k, (a, u) in enumerate(zip(AXES, UNITS))}
    return {"ate": _stats(ate), "rpe_distance": rpe}, {"ape": columns}, []


def per_algorithm(records: list[dict]) -> tuple[float, ...]:
    """The ATE RMSE of each axis, averaged over the algorithm's runs."""
    return tuple(
        float(np.mean([r["ate"][f"{a}_{u}"]["rmse"] for r in records])) for a, u in zip(AXES, UNITS)
    )


def summary(record: dict) -> dict:
    return {}


_TABLES = (
    Table(
        "ate_per_axis",
        "PER-AXIS ATE LATEX TABLE (RMSE: X Y Z M, ROLL PITCH YAW DEG, MEAN OVER RUNS)",
        pair=False,
        has=lambda r: bool(r.get("ate")),
        per_algorithm=per_algorithm,
        header=("x (m)", "y (m)", "z (m)", "roll", "pitch", "yaw"),
    ),
)


METRIC = Metric(
    key="per_axis",  # metrics.per_axis: off by default
    stage="metrics",
    enabled=enabled,
    summary=summary,
    settings=("metrics.per_axis", "metrics.segments", "metrics.segment_tol"),
    compute=compute,
    after="ate_2d",  # its record follows ATE 2D's in metrics.json
    arrays=(),  # its per-pose columns (err_x_m ... err_yaw_deg) extend ape.csv
    tables=_TABLES,
)
