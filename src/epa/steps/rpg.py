"""rpg_trajectory_evaluation's association and alignment (uzh-rpg, ``analyze_trajectory_single.py``), in
rpg's own arithmetic, quirks included: ``epa rpg`` and ``mode: rpg`` both run these (the errors and
statistics are :mod:`epa.metrics.rpg`; the quirks are listed in :mod:`epa.rpg.protocol` and
docs/protocols-rpg.md).

* association (``associate_timestamps.associate``): every (estimate, groundtruth) pair closer than 0.02 s
  (strictly) is a candidate; candidates are taken greedily by (time difference, estimate index,
  groundtruth index), each pose at most once; sorted by estimate index.
* alignment (``align_utils.alignTrajectory``, gt = s R est + t): ``posyaw`` / ``se3`` with 1 frame on the
  first matched pose's orientation; otherwise Umeyama on the first n positions (-1: all), ``posyaw`` a
  yaw only from the cross-covariance, ``sim3`` with scale; ``none`` the identity. Orientations are
  turned through rpg's 4x4 forms (``quaternion_matrix`` / ``quaternion_from_matrix``).

Quaternions are ``(qx, qy, qz, qw)``. The operations are rpg's, in rpg's order, so the results equal rpg's
bit for bit under the same numpy.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.steps.align import Similarity

EPS = np.finfo(float).eps * 4.0
MAX_DIFF = 0.02
ALIGN_TYPES = ("posyaw", "se3", "sim3", "none")


def associate(
    first, second, offset: float = 0.0, max_difference: float = MAX_DIFF
) -> list[tuple[int, int]]:
    """rpg's ``associate``: greedy one-to-one matching of two stamp lists, closest first; sorted pairs."""
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float) + offset
    order = np.argsort(b, kind="stable")
    bs = b[order]
    lo = np.searchsorted(bs, a - 2.0 * max_difference, "left")
    hi = np.searchsorted(bs, a + 2.0 * max_difference, "right")
    ia = np.repeat(np.arange(len(a)), hi - lo)
    pos = np.concatenate([np.arange(x, y) for x, y in zip(lo, hi)]) if len(a) else np.zeros(0, int)
    ib = order[pos.astype(int)]
    diff = np.abs(a[ia] - b[ib])
    keep = diff < max_difference
    ia, ib, diff = ia[keep], ib[keep], diff[keep]
    used_a = np.zeros(len(a), bool)
    used_b = np.zeros(len(b), bool)
    matches = []
    for k in np.lexsort((ib, ia, diff)):
        x, y = ia[k], ib[k]
        if not used_a[x] and not used_b[y]:
            used_a[x] = used_b[y] = True
            matches.append((int(x), int(y)))
    matches.sort()
    return matches


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """rpg's ``quaternion_matrix`` for each row of an (N, 4) array: (N, 4, 4), normalising; ~0 -> identity."""
    q = np.array(q, dtype=float, copy=True).reshape(-1, 4)
    nq = np.sum(q * q, 1)
    small = nq < EPS
    q = q * np.sqrt(2.0 / np.where(small, 1.0, nq))[:, None]
    o = q[:, :, None] * q[:, None, :]
    m = np.zeros((len(q), 4, 4))
    m[:, 0, 0] = 1.0 - o[:, 1, 1] - o[:, 2, 2]
    m[:, 0, 1] = o[:, 0, 1] - o[:, 2, 3]
    m[:, 0, 2] = o[:, 0, 2] + o[:, 1, 3]
    m[:, 1, 0] = o[:, 0, 1] + o[:, 2, 3]
    m[:, 1, 1] = 1.0 - o[:, 0, 0] - o[:, 2, 2]
    m[:, 1, 2] = o[:, 1, 2] - o[:, 0, 3]
    m[:, 2, 0] = o[:, 0, 2] - o[:, 1, 3]
    m[:, 2, 1] = o[:, 1, 2] + o[:, 0, 3]
    m[:, 2, 2] = 1.0 - o[:, 0, 0] - o[:, 1, 1]
    m[:, 3, 3] = 1.0
    m[small] = np.eye(4)
    return m


def quaternion_from_matrix(m: np.ndarray) -> np.ndarray:
    """rpg's ``quaternion_from_matrix`` for one 4x4 matrix (its M[3, 3] enters)."""
    q = np.empty(4)
    t = np.trace(m)
    if t > m[3, 3]:
        q[3] = t
        q[2] = m[1, 0] - m[0, 1]
        q[1] = m[0, 2] - m[2, 0]
        q[0] = m[2, 1] - m[1, 2]
    else:
        i, j, k = 0, 1, 2
        if m[1, 1] > m[0, 0]:
            i, j, k = 1, 2, 0
        if m[2, 2] > m[i, i]:
            i, j, k = 2, 0, 1
        t = m[i, i] - (m[j, j] + m[k, k]) + m[3, 3]
        q[i] = t
        q[j] = m[i, j] + m[j, i]
        q[k] = m[k, i] + m[i, k]
        q[3] = m[k, j] - m[j, k]
    return q * (0.5 / math.sqrt(t * m[3, 3]))


def rot_z(theta: float) -> np.ndarray:
    """rpg's ``rot_z`` (``rotation_matrix(theta, [0, 0, 1])[:3, :3]``, built the same way)."""
    s, c = math.sin(theta), math.cos(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, c + (1.0 - c)]])


def best_yaw(c: np.ndarray) -> float:
    """rpg's ``get_best_yaw``: the theta maximising trace(Rz(theta) C)."""
    return np.pi / 2 - np.arctan2(c[0, 0] + c[1, 1], c[0, 1] - c[1, 0])


def umeyama(model: np.ndarray, data: np.ndarray, known_scale: bool = False, yaw_only: bool = False):
    """rpg's ``align_umeyama``: s, R, t with model = s R data + t."""
    mu_m, mu_d = model.mean(0), data.mean(0)
    mz, dz = model - mu_m, data - mu_d
    n = np.shape(model)[0]
    c = 1.0 / n * np.dot(mz.T, dz)
    sigma2 = 1.0 / n * np.multiply(dz, dz).sum()
    u, d, vt = np.linalg.svd(c)
    v = vt.T
    s_mat = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(v) < 0:
        s_mat[2, 2] = -1
    if yaw_only:
        r = rot_z(best_yaw(np.dot(dz.T, mz)))
    else:
        r = np.dot(u, np.dot(s_mat, v.T))
    s = 1 if known_scale else 1.0 / sigma2 * np.trace(np.dot(np.diag(d), s_mat))
    return s, r, mu_m - s * np.dot(r, mu_d)


def align(p_es, p_gt, q_es, q_gt, method: str, n_aligned: int = -1):
    """rpg's ``alignTrajectory`` (gt = s R est + t): returns (s, R, t). Raises ValueError on a bad n."""
    if method == "none":
        return 1.0, np.eye(3), np.zeros(3)
    if method not in ALIGN_TYPES:
        raise ValueError(f"unknown align_type {method!r} (one of {', '.join(ALIGN_TYPES)})")
    if method == "sim3" and not (n_aligned >= 2 or n_aligned == -1):
        raise ValueError("sim3 uses at least 2 frames (align_num_frames >= 2 or -1)")
    if n_aligned == 1 and method in ("se3", "posyaw"):
        r_gt = quaternion_matrix(q_gt[0])[0, :3, :3]
        r_es = quaternion_matrix(q_es[0])[0, :3, :3]
        r = np.dot(r_gt, r_es.T) if method == "se3" else rot_z(best_yaw(np.dot(r_es, r_gt.T)))
        return 1, r, p_gt[0] - np.dot(r, p_es[0])
    if n_aligned == -1:
        idx = slice(None)
    elif 1 <= n_aligned <= len(p_es):
        idx = slice(0, n_aligned)
    else:
        raise ValueError(
            f"align_num_frames {n_aligned} must be -1 or 1..{len(p_es)} (the matched poses)"
        )
    s, r, t = umeyama(
        p_gt[idx], p_es[idx], known_scale=method != "sim3", yaw_only=method == "posyaw"
    )
    return s, r, np.asarray(t).reshape(3)


def apply_alignment(s, r, t, p_es, q_es):
    """rpg's ``Trajectory.align_trajectory`` loop: p -> s R p + t, q -> q(R R(q)) through its 4x4 forms."""
    p_al = s * np.matmul(r, p_es[:, :, None])[:, :, 0] + t
    rot = np.matmul(r, quaternion_matrix(q_es)[:, :3, :3])
    m = np.zeros((len(q_es), 4, 4))
    m[:, :3, :3] = rot
    m[:, 3, 3] = 1.0
    q_al = np.array([quaternion_from_matrix(x) for x in m]).reshape(-1, 4)
    return p_al, q_al


def fit(ref: Trajectory, est: Trajectory, method: str, first_n: int = -1):
    """rpg's alignment of matched trajectories (row k of ``ref`` matched with row k of ``est``): the
    :class:`~epa.steps.align.Similarity` (ref = s R est + t) and the aligned estimate, whose positions
    and orientations are rpg's bits (its covariance turned as :meth:`Similarity.apply` turns it).

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose.
    method : str
        ``posyaw``, ``se3``, ``sim3`` or ``none`` (rpg's ``align_type``).
    first_n : int
        rpg's ``align_num_frames``: -1 (all) or 1 .. the matched poses (``sim3``: 2 ..).

    Returns
    -------
    (Similarity, Trajectory)
    """
    n = len(ref)
    if method != "none" and not (first_n == -1 or 1 <= first_n <= n):
        raise EpaError(
            f"align.first_n is {first_n}, {n} poses matched: rpg aligns on -1 (all) or 1..{n} poses"
        )
    try:
        s, r, t = align(est.p, ref.p, est.q, ref.q, method, first_n)
    except ValueError as exc:
        raise EpaError(f"align {method} (rpg): {exc}") from None
    p_al, q_al = apply_alignment(s, r, t, est.p, est.q)
    if not (np.isfinite(s) and np.isfinite(r).all() and np.isfinite(t).all()):
        raise EpaError(
            f"align {method} (rpg): the {n if first_n < 0 else first_n} poses it uses do not"
            " determine the alignment (they do not move: the fit is not finite)"
        )
    sim = Similarity(np.asarray(r, float), np.asarray(t, float).reshape(3), float(s))
    return sim, dataclasses.replace(sim.apply(est), p=p_al, q=q_al)
