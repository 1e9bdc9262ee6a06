"""evo's pose relations: which number an APE or RPE reports for each matched pose or pose pair.

APE compares E = P^-1 Q (estimate P, reference Q), RPE compares E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j),
as evo 1.38 does. From E:

- ``trans_part``: |t(E)| in metres (for the APE, |p_est - p_ref|);
- ``rot_part``: |R(E) - I| (Frobenius, no unit); ``full``: |E - I| of the 4x4 matrix;
- ``angle_deg`` / ``angle_rad``: the rotation angle of R(E);
- ``point_distance``: the APE: |p_est - p_ref|; the RPE: | |p_ref,j - p_ref,i| - |p_est,j - p_est,i| |;
- ``point_distance_error_ratio`` (RPE only): that difference in % of the reference distance (pairs
  whose reference distance is 0 are left out).

Vectorised over all poses or pairs; angles come from quaternions (accurate near 0). Translation
and angle are the library's ATE and RPE formulas; only rot_part and full need E itself.
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


def _angle(relation: str, rad: np.ndarray) -> np.ndarray:
    return np.degrees(rad) if relation == "angle_deg" else rad


def _matrix_relation(relation: str, q_e: np.ndarray, t_e: np.ndarray) -> np.ndarray:
    """rot_part or full of error poses E = (q_e, t_e): the entries of R(E) (and t(E)) against identity."""
    rot = np.linalg.norm(geometry.quat_to_rot(q_e) - np.eye(3), axis=(-2, -1))
    return rot if relation == "rot_part" else np.sqrt(rot ** 2 + np.sum(t_e ** 2, axis=-1))  # full: last row is 0


def ape(ref: Trajectory, est: Trajectory, relation: str = "trans_part") -> np.ndarray:
    """Per matched pose: the relation's value of E = P^-1 Q. Translation and angle are the ATE's
    (accuracy.ape): |t(E)| = |p_est - p_ref| and angle(E) = angle(Q P^T)."""
    _check(relation, rpe=False)
    if relation in ("trans_part", "point_distance", "angle_deg", "angle_rad"):
        trans, rot_deg = accuracy.ape(ref, est)
        return trans if relation in ("trans_part", "point_distance") else _angle(relation, np.radians(rot_deg))
    q_inv = geometry.quat_conj(est.q)
    return _matrix_relation(relation, geometry.quat_mul(q_inv, ref.q), geometry.quat_rotate(q_inv, ref.p - est.p))


def rpe(ref: Trajectory, est: Trajectory, i: np.ndarray, j: np.ndarray, relation: str = "trans_part") -> np.ndarray:
    """Per pair (i, j): the relation's value of E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j). Translation and
    angle are the RPE's (geometry.relative_errors)."""
    _check(relation, rpe=True)
    if relation in ("point_distance", "point_distance_error_ratio"):
        d_ref = np.linalg.norm(ref.p[j] - ref.p[i], axis=1)
        diff = np.abs(d_ref - np.linalg.norm(est.p[j] - est.p[i], axis=1))
        if relation == "point_distance":
            return diff
        moved = d_ref != 0
        return diff[moved] / d_ref[moved] * 100
    if relation in ("trans_part", "angle_deg", "angle_rad"):
        rot_deg, trans = geometry.relative_errors(geometry.pose_discrepancy(ref.q, est.q), ref.p, est.p, i, j)
        return trans if relation == "trans_part" else _angle(relation, np.radians(rot_deg))
    q_ref, t_ref = geometry.relative_motions(ref.q, ref.p, i, j)
    q_est, t_est = geometry.relative_motions(est.q, est.p, i, j)
    q_inv = geometry.quat_conj(q_ref)
    return _matrix_relation(relation, geometry.quat_mul(q_inv, q_est), geometry.quat_rotate(q_inv, t_est - t_ref))


def evo_statistics(errors: np.ndarray) -> dict[str, float]:
    """evo's statistics block, in its order: max, mean, median, min, rmse, sse, std."""
    e = np.asarray(errors, float)
    if e.size == 0:
        raise EpaError("no errors to summarise (no poses or pairs were compared)")
    s = accuracy.stats(e)
    return {"max": s["max"], "mean": s["mean"], "median": s["median"], "min": s["min"], "rmse": s["rmse"],
            "sse": float(np.sum(e * e)), "std": s["std"]}
