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
and angle are the library's ATE and RPE formulas; rot_part and full need E itself, as matrices.
KITTI's printed rotation blocks are orthonormal only to ~1e-7; evo computes on them as printed, so
when a trajectory carries them (``r_printed``, ``Trajectory.r_as_printed``) every relation is evo's matrix
arithmetic: that is what matches evo to 1e-6 on the smallest RPE statistics.
"""

from __future__ import annotations

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import accuracy

RELATIONS = (
    "full",
    "trans_part",
    "rot_part",
    "angle_deg",
    "angle_rad",
    "point_distance",
    "point_distance_error_ratio",
)
UNIT = {
    "full": "",
    "trans_part": "m",
    "rot_part": "",
    "angle_deg": "deg",
    "angle_rad": "rad",
    "point_distance": "m",
    "point_distance_error_ratio": "%",
}
TITLE = {
    "full": "full transformation",
    "trans_part": "translation part",
    "rot_part": "rotation part",
    "angle_rad": "rotation angle in radians",
    "angle_deg": "rotation angle in degrees",
    "point_distance": "point distance",
    "point_distance_error_ratio": "point distance error ratio",
}


def _check(relation: str, rpe: bool) -> None:
    if relation not in RELATIONS or (relation == "point_distance_error_ratio" and not rpe):
        allowed = RELATIONS if rpe else RELATIONS[:-1]
        raise EpaError(f"unknown pose relation {relation!r}; choose one of {', '.join(allowed)}")


def _angle(relation: str, rad: np.ndarray) -> np.ndarray:
    return np.degrees(rad) if relation == "angle_deg" else rad


def _printed(*trajs: Trajectory) -> bool:
    return any(t.r_printed is not None for t in trajs)


def _between(
    r_a: np.ndarray, p_a: np.ndarray, r_b: np.ndarray, p_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A^-1 B as (rotations, translations), A^-1 taken as evo's se3_inverse takes it, [R^T, -R^T p]:
    evo's arithmetic exactly, also on KITTI's printed, not quite orthonormal, rotation blocks (the
    matrix twin of geometry.relative_motions, which works on quaternions)."""
    r_t = np.swapaxes(r_a, -1, -2)
    return r_t @ r_b, np.einsum("nij,nj->ni", r_t, p_b - p_a)


def _ape_error_poses(ref: Trajectory, est: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """E = P^-1 Q."""
    return _between(est.r_as_printed, est.p, ref.r_as_printed, ref.p)


def _rpe_error_poses(ref: Trajectory, est: Trajectory, i, j) -> tuple[np.ndarray, np.ndarray]:
    """E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)."""
    r_ref, r_est = ref.r_as_printed, est.r_as_printed
    motion_ref = _between(r_ref[i], ref.p[i], r_ref[j], ref.p[j])
    motion_est = _between(r_est[i], est.p[i], r_est[j], est.p[j])
    return _between(*motion_ref, *motion_est)


def _of_error_poses(relation: str, r_e: np.ndarray, t_e: np.ndarray) -> np.ndarray:
    """The relation's value of error poses E = (r_e, t_e). The angle is that of E's nearest rotation,
    as scipy's from_matrix (evo's so3_log_angle) takes it."""
    if relation == "trans_part":
        return np.linalg.norm(t_e, axis=-1)
    if relation in ("angle_deg", "angle_rad"):
        return _angle(relation, geometry.rotation_angle(geometry.nearest_rotation(r_e)))
    rot = np.linalg.norm(r_e - np.eye(3), axis=(-2, -1))
    # full: last row is 0
    return rot if relation == "rot_part" else np.sqrt(rot**2 + np.sum(t_e**2, axis=-1))


def ape(ref: Trajectory, est: Trajectory, relation: str = "trans_part") -> np.ndarray:
    """Per matched pose: the relation's value of E = P^-1 Q. Translation and angle are the ATE's
    (accuracy.ape): |t(E)| = |p_est - p_ref| and angle(E) = angle(Q P^T), except on printed rotation
    blocks, where the angle is evo's (of the matrix product)."""
    _check(relation, rpe=False)
    if relation in ("trans_part", "point_distance") or (
        relation.startswith("angle") and not _printed(ref, est)
    ):
        trans, rot_deg = accuracy.ape(ref, est)
        return (
            trans
            if relation in ("trans_part", "point_distance")
            else _angle(relation, np.radians(rot_deg))
        )
    return _of_error_poses(relation, *_ape_error_poses(ref, est))


def rpe(
    ref: Trajectory, est: Trajectory, i: np.ndarray, j: np.ndarray, relation: str = "trans_part"
) -> np.ndarray:
    """Per pair (i, j): the relation's value of E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j). Translation and
    angle are the RPE's (geometry.relative_errors), except on printed rotation blocks (evo's matrix
    arithmetic, _rpe_error_poses)."""
    _check(relation, rpe=True)
    if relation in ("point_distance", "point_distance_error_ratio"):
        d_ref = np.linalg.norm(ref.p[j] - ref.p[i], axis=1)
        diff = np.abs(d_ref - np.linalg.norm(est.p[j] - est.p[i], axis=1))
        if relation == "point_distance":
            return diff
        moved = d_ref != 0
        return diff[moved] / d_ref[moved] * 100
    if relation in ("trans_part", "angle_deg", "angle_rad") and not _printed(ref, est):
        rot_deg, trans = geometry.relative_errors(
            geometry.pose_discrepancy(ref.q, est.q), ref.p, est.p, i, j
        )
        return trans if relation == "trans_part" else _angle(relation, np.radians(rot_deg))
    return _of_error_poses(relation, *_rpe_error_poses(ref, est, i, j))


def evo_statistics(errors: np.ndarray) -> dict[str, float]:
    """evo's statistics block, in its order: max, mean, median, min, rmse, sse, std."""
    e = np.asarray(errors, float)
    if e.size == 0:
        raise EpaError("no errors to summarise (no poses or pairs were compared)")
    s = accuracy.stats(e)
    return {
        "max": s["max"],
        "mean": s["mean"],
        "median": s["median"],
        "min": s["min"],
        "rmse": s["rmse"],
        "sse": float(np.sum(e * e)),
        "std": s["std"],
    }
