"""The TartanAir benchmark's scores, as ``tartanair_tools/evaluation`` computes them
(``tartanair_evaluator.py`` and the modules it calls; docs/protocols.md, section TartanAir).

- Poses are paired **by index**: the two files have one pose per frame, equally many.
- **ATE**: a Horn fit of the *reference onto the estimate* on the poses as given; with ``scale``
  its own scale formula ``s = sum |g_i|^2 / sum e_i . (R g_i)`` (centred positions) multiplies the
  estimate, so the error ``R g_i + t - s e_i`` is in the reference's metres.
- **RPE** and the **KITTI score** are computed after both trajectories are re-based at their first
  pose (``inv(T_0) T_i``) and, with ``scale``, the estimate's positions multiplied by
  ``1 / mean(|de_k| / |dg_k|)`` over the steps where the reference moves more than 0.1 mm.
- RPE: all N^2 ordered pairs when N^2 is below ``max_pairs``, otherwise ``max_pairs`` pairs drawn
  with Python's ``random.randint`` (the script does not seed it; epica seeds ``seed``); the error
  ``inv(inv(E_j) E_i) inv(G_j) G_i``; the means of its translation (m) and angle (**rad**).
- KITTI score: segments of 5, 10, ..., 40 m of reference path starting at **every** pose, the
  devkit's error divided by the length; per length the mean, then the mean over the lengths that
  have a segment: rotation in **deg per m**, translation as a **ratio** (m/m, not %).
"""

from __future__ import annotations

import random

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import kitti
from epa.metrics.spec import Table, protocol

KEY = "tartanair"
KITTI_LENGTHS_M = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0)
STILL_STEP_M = (
    1e-4  # rescale: steps where the reference moves less are left out, as the script does
)


def rebased(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Rotations and positions of ``inv(T_0) T_i`` (trajectory_transform.shift0)."""
    r = traj.r
    r0t = r[0].T
    return r0t @ r, (traj.p - traj.p[0]) @ r0t.T


def speed_scale(p_ref: np.ndarray, p_est: np.ndarray) -> float:
    """``1 / mean(|de_k| / |dg_k|)`` over the steps where the reference moves (trajectory_transform.rescale).

    Parameters
    ----------
    p_ref, p_est : ndarray (N, 3)
        Positions paired by index.

    Returns
    -------
    float
        The factor the script multiplies the estimate's positions by.
    """
    step_ref = np.linalg.norm(np.diff(p_ref, axis=0), axis=1)
    step_est = np.linalg.norm(np.diff(p_est, axis=0), axis=1)
    moving = step_ref > STILL_STEP_M
    if not moving.any():
        raise EpaError(
            f"metrics.{KEY}.scale: the reference never moves more than {STILL_STEP_M} m between"
            " two poses, so the TartanAir scale is undefined"
        )
    ratio = float(np.mean(step_est[moving] / step_ref[moving]))
    if ratio == 0.0:
        raise EpaError(f"metrics.{KEY}.scale: the estimate never moves, so its scale is undefined")
    return 1.0 / ratio


def ate(p_ref: np.ndarray, p_est: np.ndarray, with_scale: bool) -> tuple[float, float]:
    """TartanAir's ATE (evaluate_ate_scale.align): RMSE (m) and its scale.

    Parameters
    ----------
    p_ref, p_est : ndarray (N, 3)
        Positions paired by index, as given (not re-based).
    with_scale : bool
        Fit the scale (the monocular track).

    Returns
    -------
    rmse_m, scale : float
    """
    g = p_ref - p_ref.mean(axis=0)
    e = p_est - p_est.mean(axis=0)
    u, _, vt = np.linalg.svd(e.T @ g)  # the transpose of the script's sum of outer(g_i, e_i)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    rot = u @ sign @ vt  # maps the reference onto the estimate
    turned = g @ rot.T
    scale = float(np.sum(g * g) / np.sum(e * turned)) if with_scale else 1.0
    error = turned - scale * e  # R g_i + t - s e_i, t cancelling the means
    return float(np.sqrt(np.mean(np.sum(error * error, axis=1)))), scale


def rpe_pairs(n: int, max_pairs: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i, j) evaluate_rpe.evaluate_trajectory takes: all ordered pairs, or ``max_pairs``
    drawn by ``random.randint`` from a generator seeded with ``seed`` (i then j, pair by pair)."""
    if max_pairs == 0 or n < np.sqrt(max_pairs):
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        return i.ravel(), j.ravel()
    draw = random.Random(seed).randint
    # call by call, as the script: its draws bit for bit (10000 pairs: 0.04 s, whatever N)
    ij = np.array([draw(0, n - 1) for _ in range(2 * max_pairs)], dtype=np.int64)
    return ij[0::2], ij[1::2]


def rpe(r_ref, p_ref, r_est, p_est, i: np.ndarray, j: np.ndarray) -> tuple[float, float]:
    """Mean translation (m) and angle (rad) of ``inv(inv(E_j) E_i) inv(G_j) G_i`` over the pairs.

    Parameters
    ----------
    r_ref, r_est : ndarray (N, 3, 3)
    p_ref, p_est : ndarray (N, 3)
        Re-based (and rescaled) poses.
    i, j : ndarray of int

    Returns
    -------
    trans_m, rot_rad : float
    """

    def motion(r, p):  # inv(T_j) T_i
        rjt = np.swapaxes(r[j], 1, 2)
        return rjt @ r[i], np.einsum("nab,nb->na", rjt, p[i] - p[j])

    r_g, t_g = motion(r_ref, p_ref)
    r_e, t_e = motion(r_est, p_est)
    r_et = np.swapaxes(r_e, 1, 2)
    r_err = r_et @ r_g
    t_err = np.einsum("nab,nb->na", r_et, t_g - t_e)
    cos = (np.trace(r_err, axis1=1, axis2=2) - 1) / 2
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    return float(np.mean(np.linalg.norm(t_err, axis=1))), float(np.mean(angle))


def kitti_score(ref: Trajectory, est: Trajectory) -> tuple[float | None, float | None, int]:
    """TartanAir's KITTI score (evaluate_kitti.evaluate): rotation (deg/m) and translation (m/m),
    the mean over the segment lengths of each length's mean, with the number of segments."""
    first, last, lengths = kitti.segments(geometry.path_distances(ref.p), KITTI_LENGTHS_M, step=1)
    rot_rad, trans_m = kitti.segment_errors(ref, est, first, last)
    rot, trans = [], []
    for length in KITTI_LENGTHS_M:
        at = lengths == length
        if at.any():
            rot.append(np.mean(rot_rad[at] / length) * 180 / np.pi)
            trans.append(np.mean(trans_m[at] / length))
    if not rot:
        return None, None, 0
    return float(np.mean(rot)), float(np.mean(trans)), int(len(first))


def paired(
    cfg: dict, reference: Trajectory, estimate: Trajectory, ref: Trajectory, unaligned
) -> tuple[Trajectory, Trajectory]:
    """The two trajectories the protocol compares, pose k with pose k."""
    settings = cfg["metrics"][KEY]
    if settings["pairs"] == "matched":  # epica's Step 1 pairs, the estimate before Step 3
        return ref, unaligned
    if len(reference) != len(estimate):
        raise EpaError(
            f"metrics.{KEY}: TartanAir pairs poses by index, but the reference has"
            f" {len(reference)} poses and the estimate {len(estimate)} (give one pose per frame"
            f" in both, or set metrics.{KEY}.pairs: matched)"
        )
    return reference, estimate


def evaluate(ref: Trajectory, est: Trajectory, *, scale: bool, max_pairs: int, seed: int) -> dict:
    """TartanAir's three scores of two trajectories paired by index (see the module's docstring)."""
    if len(ref) < 2:
        raise EpaError(f"metrics.{KEY}: TartanAir needs at least 2 poses, got {len(ref)}")
    ate_m, ate_scale = ate(ref.p, est.p, scale)
    r_ref, p_ref = rebased(ref)
    r_est, p_est = rebased(est)
    s = speed_scale(p_ref, p_est) if scale else 1.0
    p_est = p_est * s
    i, j = rpe_pairs(len(ref), max_pairs, seed)
    rpe_trans, rpe_rot = rpe(r_ref, p_ref, r_est, p_est, i, j)
    base_ref = Trajectory.from_rp(ref.t, r_ref, p_ref)
    base_est = Trajectory.from_rp(est.t, r_est, p_est)
    k_rot, k_trans, n_segments = kitti_score(base_ref, base_est)
    return {
        "n_poses": len(ref),
        "scale": scale,
        "ate_m": ate_m,
        "ate_scale": ate_scale,
        "rescale": s,
        "rpe_n_pairs": int(len(i)),
        "rpe_trans_m": rpe_trans,
        "rpe_rot_rad": rpe_rot,
        "kitti_n_segments": n_segments,
        "kitti_rot_deg_per_m": k_rot,
        "kitti_trans": k_trans,
    }


def compute(
    ref: Trajectory,
    est: Trajectory,
    cfg: dict,
    *,
    reference: Trajectory,
    estimate: Trajectory,
    unaligned: Trajectory,
) -> tuple[dict, dict, list[str]]:
    """The TartanAir record of a case (its settings: ``metrics.tartanair``).

    Parameters
    ----------
    ref, est : Trajectory
        The matched reference and the aligned matched estimate (``pairs: matched`` uses ``ref``).
    reference, estimate : Trajectory
        The whole cropped trajectories (``pairs: index``, the benchmark's pairing).
    unaligned : Trajectory
        The matched estimate before Step 3 (``pairs: matched``).

    Returns
    -------
    (record, arrays, notes)
    """
    settings = cfg["metrics"][KEY]
    a, b = paired(cfg, reference, estimate, ref, unaligned)
    record = {"pairs": settings["pairs"], "seed": settings["seed"]}
    record |= evaluate(
        a, b, scale=settings["scale"], max_pairs=settings["max_pairs"], seed=settings["seed"]
    )
    notes = []
    if record["kitti_n_segments"] == 0:
        notes.append(
            f"{KEY}: no 5 m segment fits in the {a.length():.3f} m reference: its KITTI score is"
            " empty"
        )
    return record, {}, notes


def summary(record: dict) -> dict:
    """Empty unless metrics.tartanair is on."""
    return {
        "tartanair_ate_m": record.get("ate_m"),
        "tartanair_rpe_rot_rad": record.get("rpe_rot_rad"),
        "tartanair_rpe_trans_m": record.get("rpe_trans_m"),
        "tartanair_kitti_rot_deg_per_m": record.get("kitti_rot_deg_per_m"),
        "tartanair_kitti_trans": record.get("kitti_trans"),
    }


METRIC = protocol(
    KEY,  # metrics.tartanair: off by default; `epa eval --protocol tartanair`
    summary=summary,
    compute=compute,
    inputs=("reference", "estimate", "unaligned"),
    summary_columns=(
        "tartanair_ate_m",
        "tartanair_rpe_rot_rad",
        "tartanair_rpe_trans_m",
        "tartanair_kitti_rot_deg_per_m",
        "tartanair_kitti_trans",
    ),
    tables=(
        Table(KEY, "TARTANAIR ATE (M)", pair=False, per_run=lambda r: (r["ate_m"],)),
        Table(
            f"{KEY}_kitti",
            "TARTANAIR KITTI SCORE (ROT DEG/M / TRANS M/M, 5-40 M SEGMENTS)",
            per_run=lambda r: (r["kitti_rot_deg_per_m"], r["kitti_trans"]),
            has=lambda r: bool(r.get("kitti_n_segments")),
        ),
    ),
)
