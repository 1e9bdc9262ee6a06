"""evo's pose relations: which number an APE or RPE reports for each matched pose or pose pair.

APE compares E = P^-1 Q (estimate P, reference Q), RPE compares E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j),
as evo 1.38 does. From E:

- ``trans_part``: |t(E)| in metres (for the APE, |p_est - p_ref|);
- ``rot_part``: |R(E) - I| (Frobenius, no unit); ``full``: |E - I| of the 4x4 matrix;
- ``angle_deg`` / ``angle_rad``: the rotation angle of R(E);
- ``point_distance``: the APE: |p_est - p_ref|; the RPE: | |p_ref,j - p_ref,i| - |p_est,j - p_est,i| |;
- ``point_distance_error_ratio`` (RPE only): that difference in % of the reference distance (pairs
  whose reference distance is 0 are left out).

Vectorised over all poses or pairs; angles come from quaternions (accurate near 0).
"""

from __future__ import annotations

import numpy as np

from epa import geometry
from epa.errors import EpaError
from epa.metrics import accuracy
from epa.trajectory import Trajectory

RELATIONS = ("full", "trans_part", "rot_part", "angle_deg", "angle_rad", "point_distance",
             "point_distance_error_ratio")
UNIT = {"full": "", "trans_part": "m", "rot_part": "", "angle_deg": "deg", "angle_rad": "rad",
        "point_distance": "m", "point_distance_error_ratio": "%"}
TITLE = {"full": "full transformation", "trans_part": "translation part", "rot_part": "rotation part",
         "angle_rad": "rotation angle in radians", "angle_deg": "rotation angle in degrees",
         "point_distance": "point distance", "point_distance_error_ratio": "point distance error ratio"}


def _check(relation: str, rpe: bool) -> None:
    if relation not in RELATIONS or (relation == "point_distance_error_ratio" and not rpe):
        allowed = RELATIONS if rpe else RELATIONS[:-1]
        raise EpaError(f"unknown pose relation {relation!r}; choose one of {', '.join(allowed)}")


def _from_error_pose(relation: str, q_e: np.ndarray, t_e: np.ndarray) -> np.ndarray:
    """The relation's number of error poses E = (q_e, t_e)."""
    if relation == "trans_part":
        return np.linalg.norm(t_e, axis=-1)
    if relation in ("angle_deg", "angle_rad"):
        angle = geometry.quat_angle(q_e)
        return np.degrees(angle) if relation == "angle_deg" else angle
    rot = np.linalg.norm(geometry.quat_to_rot(q_e) - np.eye(3), axis=(-2, -1))
    if relation == "rot_part":
        return rot
    return np.sqrt(rot ** 2 + np.sum(t_e ** 2, axis=-1))  # full: the last row of E - I is zero


def ape(ref: Trajectory, est: Trajectory, relation: str = "trans_part") -> np.ndarray:
    """Per matched pose: the relation's value of E = P^-1 Q."""
    _check(relation, rpe=False)
    if relation in ("trans_part", "point_distance"):
        return np.linalg.norm(est.p - ref.p, axis=1)
    q_inv = geometry.quat_conj(est.q)
    return _from_error_pose(relation, geometry.quat_mul(q_inv, ref.q), geometry.quat_rotate(q_inv, ref.p - est.p))


def rpe(ref: Trajectory, est: Trajectory, i: np.ndarray, j: np.ndarray, relation: str = "trans_part") -> np.ndarray:
    """Per pair (i, j): the relation's value of E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)."""
    _check(relation, rpe=True)
    if relation in ("point_distance", "point_distance_error_ratio"):
        d_ref = np.linalg.norm(ref.p[j] - ref.p[i], axis=1)
        diff = np.abs(d_ref - np.linalg.norm(est.p[j] - est.p[i], axis=1))
        if relation == "point_distance":
            return diff
        moved = d_ref != 0
        return diff[moved] / d_ref[moved] * 100
    q_ref, t_ref = geometry.relative_motions(ref.q, ref.p, i, j)
    q_est, t_est = geometry.relative_motions(est.q, est.p, i, j)
    q_inv = geometry.quat_conj(q_ref)
    return _from_error_pose(relation, geometry.quat_mul(q_inv, q_est), geometry.quat_rotate(q_inv, t_est - t_ref))


def evo_statistics(errors: np.ndarray) -> dict[str, float]:
    """evo's statistics block, in its order: max, mean, median, min, rmse, sse, std."""
    e = np.asarray(errors, float)
    if e.size == 0:
        raise EpaError("no errors to summarise (no poses or pairs were compared)")
    s = accuracy.stats(e)
    return {"max": s["max"], "mean": s["mean"], "median": s["median"], "min": s["min"], "rmse": s["rmse"],
            "sse": float(np.sum(e * e)), "std": s["std"]}
