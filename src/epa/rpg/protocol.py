"""The arithmetic of uzh-rpg's rpg_trajectory_evaluation (``analyze_trajectory_single.py``), quirks included.

Every function names the rpg function it reproduces. Quaternions are ``(qx, qy, qz, qw)`` as in rpg's files
and its ``transformations.py``. Nothing here reads or writes files (that is :mod:`epa.rpg.command`).

The quirks kept on purpose (each is rpg's behaviour, not an oversight here):

* association (``associate_timestamps.associate``): every (estimate, groundtruth) pair closer than 0.02 s
  (strictly) is a candidate; candidates are taken greedily by (time difference, estimate index,
  groundtruth index), each pose at most once. The offset is added to the groundtruth stamp
  (``abs(a - (b + offset))``); rpg always passes 0.
* ``posyaw`` / ``se3`` with ``align_num_frames == 1`` align on the first matched pose only: ``se3`` takes
  ``R_gt0 R_es0^T``, ``posyaw`` the best yaw of ``R_es0 R_gt0^T``; the translation maps the first position.
  Otherwise Umeyama on the first n matched positions (-1: all); ``posyaw`` keeps only a yaw, chosen from
  the cross-covariance ``data^T model`` (no 1/n), scale 1. ``sim3`` needs n >= 2 or -1.
* the yaw rotation is built as rpg's ``rotation_matrix(theta, [0, 0, 1])``: its (2, 2) entry is
  ``cos + (1 - cos)``, not exactly 1.
* the absolute ``scale`` error is ``|(|p_es_aligned| / |p_gt|) - 1| * 100`` per pose: ``np.diff(p, 0)`` in
  rpg is the positions themselves, so it is a ratio of distances from the origin, not of motions.
* the absolute rotation error uses rpg's ``logmap_so3``, whose small-angle branch (trace > 3 - 1e-7) uses
  ``0.5 - (tr - 3)^2 / 12``.
* relative-error distances are 10..50 % of the length of the whole (time-window filtered) raw groundtruth,
  truncated (not rounded) to two decimals; the pairs use the accumulated length of the *matched*
  groundtruth positions.
* pair selection (``compute_comparison_indices_length``): for each start index, the first index at or
  after it whose accumulated distance is closest to start + d, if closer than 0.2 d (strictly); starts
  without such an end are skipped, yet the k-th kept pair then starts at index k (rpg enumerates the list
  of end indices), not at the start index that found it. Fewer than 2 pairs: no samples.
* relative errors use the *unaligned* estimate; only the Sim3 scale (1 for the other alignments) multiplies
  the estimate's relative translation. The error ``inv(T_gt1_gt2) * T_es1_es2`` is conjugated by the
  estimate's end orientation; yaw and gravity (pitch/roll norm) are its 'rzyx' Euler angles in degrees,
  ``rot`` its angle (arccos of the clipped trace), ``trans_perc = |t| / d * 100``,
  ``rot_deg_per_m = rot / d``.
* statistics (``results_writer.compute_statistics``): population std, and integer zeros with
  ``num_samples: 0`` for an empty vector.

The operations are rpg's, in rpg's order (the same squared norms, matrix products, inverses and
conversions, vectorised only where numpy gives the same bits), so the statistics equal rpg's bit for bit
under the same numpy: the arccos of a small rotation angle amplifies a last-bit difference ~1e6 times.
"""

from __future__ import annotations

import math

import numpy as np

EPS = np.finfo(float).eps * 4.0
MAX_DIFF = 0.02
BOXPLOT_PERCENTAGES = (0.1, 0.2, 0.3, 0.4, 0.5)
ALIGN_TYPES = ("posyaw", "se3", "sim3", "none")
STAT_KEYS = ("rmse", "mean", "median", "std", "min", "max", "num_samples")
REL_METRICS = (
    "rel_trans",
    "rel_trans_perc",
    "rel_yaw",
    "rel_rot",
    "rel_gravity",
    "rel_rot_deg_per_m",
)
REL_LABELS = ("trans", "trans_perc", "yaw", "rot", "gravity", "rot_deg_per_m")


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


def distance_from_start(p: np.ndarray) -> np.ndarray:
    """rpg's ``get_distance_from_start``: accumulated path length, starting at 0."""
    d = np.diff(p[:, 0:3], axis=0)
    return np.concatenate(([0], np.cumsum(np.sqrt(np.sum(d * d, 1)))))


def truncate(number: float, decimals: int = 0) -> float:
    """rpg's ``Trajectory.truncate``."""
    if decimals == 0:
        return math.trunc(number)
    factor = 10.0**decimals
    return math.trunc(number * factor) / factor


def boxplot_distances(traj_length: float, percentages=BOXPLOT_PERCENTAGES) -> list[float]:
    """rpg's ``compute_boxplot_distances``: each percentage of the groundtruth length, truncated to 2
    decimals."""
    return [truncate(pct * traj_length, 2) for pct in percentages]


def comparison_indices(distances: np.ndarray, dist: float, max_dist_diff: float) -> list[int]:
    """rpg's ``compute_comparison_indices_length``: the end index of each start that has one (module doc).

    rpg scans i >= start for the first minimum of |distances[i] - (d_start + dist)| below max_dist_diff;
    distances never decrease, so that minimum is found by bisection (first index of the value just below or
    just at/above the target; ties go to the lower value, as rpg's strict comparison keeps the first)."""
    distances = np.asarray(distances, dtype=float)
    n = len(distances)
    if n == 0:
        return []
    target = distances + dist
    above = np.searchsorted(distances, target, "left")  # first index with value >= target
    start = np.arange(n)
    above = np.maximum(above, start)
    below = above - 1  # the last value < target (when >= start)
    err_above = np.where(above < n, np.abs(distances[np.minimum(above, n - 1)] - target), np.inf)
    has_below = below >= start
    below_val = distances[np.maximum(below, 0)]
    err_below = np.where(has_below, np.abs(below_val - target), np.inf)
    below_first = np.maximum(np.searchsorted(distances, below_val, "left"), start)
    best = np.where(err_below <= err_above, below_first, above)
    err = np.minimum(err_below, err_above)
    return [int(b) for b, e in zip(best, err) if e < max_dist_diff]


def euler_rzyx(m: np.ndarray) -> np.ndarray:
    """rpg's ``euler_from_matrix(m, 'rzyx')`` for (N, >=3, >=3): (N, 3) yaw, pitch, roll."""
    m = m[:, :3, :3]
    cy = np.sqrt(m[:, 0, 0] * m[:, 0, 0] + m[:, 1, 0] * m[:, 1, 0])
    ok = cy > EPS
    yaw = np.where(ok, np.arctan2(m[:, 1, 0], m[:, 0, 0]), 0.0)
    pitch = np.arctan2(-m[:, 2, 0], cy)
    roll = np.where(ok, np.arctan2(m[:, 2, 1], m[:, 2, 2]), np.arctan2(-m[:, 1, 2], m[:, 1, 1]))
    return np.stack([yaw, pitch, roll], axis=1)


def _logmap_so3_one(r: np.ndarray) -> np.ndarray:
    tr = np.trace(r)
    if abs(tr + 1.0) < 1e-10:
        if abs(r[2, 2] + 1.0) > 1e-10:
            return (np.pi / np.sqrt(2.0 + 2.0 * r[2, 2])) * np.array(
                [r[0, 2], r[1, 2], 1.0 + r[2, 2]]
            )
        if abs(r[1, 1] + 1.0) > 1e-10:
            return (np.pi / np.sqrt(2.0 + 2.0 * r[1, 1])) * np.array(
                [r[0, 1], 1.0 + r[1, 1], r[2, 1]]
            )
        return (np.pi / np.sqrt(2.0 + 2.0 * r[0, 0])) * np.array([1.0 + r[0, 0], r[1, 0], r[2, 0]])
    tr_3 = tr - 3.0
    if tr_3 < -1e-7:
        theta = np.arccos((tr - 1.0) / 2.0)
        magnitude = theta / (2.0 * np.sin(theta))
    else:
        magnitude = 0.5 - tr_3 * tr_3 / 12.0
    return magnitude * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])


def rotation_angle_deg(m: np.ndarray) -> np.ndarray:
    """rpg's ``compute_angle`` for (N, >=3, >=3): arccos of the clipped (trace - 1) / 2, in degrees."""
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    return np.arccos(np.minimum(1, np.maximum(-1, (tr - 1) / 2))) * 180.0 / np.pi


def absolute_errors(p_es_aligned, q_es_aligned, p_gt, q_gt) -> dict:
    """rpg's ``compute_absolute_error``: per-pose translation [m], rotation [deg], ypr [rad], scale [%]."""
    e_trans_vec = p_gt - p_es_aligned
    e_trans = np.sqrt(np.sum(e_trans_vec**2, 1))
    e_r = np.matmul(quaternion_matrix(q_es_aligned), np.linalg.inv(quaternion_matrix(q_gt)))
    e_ypr = euler_rzyx(e_r)
    e_rot = np.array([np.rad2deg(np.linalg.norm(_logmap_so3_one(x[:3, :3]))) for x in e_r])
    dist_gt = np.sqrt(np.sum(p_gt * p_gt, 1))
    dist_es = np.sqrt(np.sum(p_es_aligned * p_es_aligned, 1))
    e_scale_perc = np.abs((dist_es / dist_gt - 1.0) * 100)
    return {
        "trans": e_trans,
        "trans_vec": e_trans_vec,
        "rot": e_rot,
        "ypr": e_ypr,
        "scale": e_scale_perc,
    }


def _rigid(q, p) -> np.ndarray:
    t = quaternion_matrix(q)
    t[:, 0:3, 3] = p
    return t


def relative_errors(
    p_es,
    q_es,
    p_gt,
    q_gt,
    dist: float,
    max_dist_diff: float | None = None,
    accum_distances=None,
    scale: float = 1.0,
) -> dict:
    """rpg's ``compute_relative_error`` (with T_cm = identity) at one sub-trajectory length.

    Returns the six metric vectors keyed as rpg's ``kRelMetrics`` (``rel_trans``, ...), plus ``pairs``
    (start, end) as rpg forms them."""
    if max_dist_diff is None or max_dist_diff < 0:
        max_dist_diff = 0.2 * dist
    if accum_distances is None or len(accum_distances) == 0:
        accum_distances = distance_from_start(p_gt)
    ends = comparison_indices(accum_distances, dist, max_dist_diff)
    empty = {k: np.array([]) for k in REL_METRICS}
    if len(ends) < 2:
        return {**empty, "pairs": np.zeros((0, 2), int)}
    i1 = np.arange(len(ends))
    i2 = np.array(ends)
    t_c1, t_c2 = _rigid(q_es[i1], p_es[i1]), _rigid(q_es[i2], p_es[i2])
    t_c1_c2 = np.matmul(np.linalg.inv(t_c1), t_c2)
    t_c1_c2[:, :3, 3] *= scale
    t_m1_m2 = np.matmul(np.linalg.inv(_rigid(q_gt[i1], p_gt[i1])), _rigid(q_gt[i2], p_gt[i2]))
    t_err_c2 = np.matmul(np.linalg.inv(t_m1_m2), t_c1_c2)
    t_c2_rot = np.zeros_like(t_c2)
    t_c2_rot[:, :3, :3] = t_c2[:, :3, :3]
    t_c2_rot[:, 3, 3] = 1.0
    e = np.matmul(t_c2_rot, np.matmul(t_err_c2, np.linalg.inv(t_c2_rot)))
    tn = np.sqrt(np.sum(e[:, 0:3, 3] ** 2, 1))
    ypr = euler_rzyx(e)
    e_rot = rotation_angle_deg(e)
    return {
        "rel_trans": tn,
        "rel_trans_perc": tn / dist * 100,
        "rel_yaw": np.abs(ypr[:, 0]) * 180.0 / np.pi,
        "rel_rot": e_rot,
        # rpg squares Python floats: x ** 2 is pow(x, 2), which is not always x * x
        "rel_gravity": np.sqrt([float(a) ** 2 + float(b) ** 2 for a, b in ypr[:, 1:]])
        * 180.0
        / np.pi,
        "rel_rot_deg_per_m": e_rot / dist,
        "pairs": np.stack([i1, i2], axis=1),
    }


def statistics(values) -> dict:
    """rpg's ``compute_statistics``: rmse, mean, median, std (population), min, max, num_samples."""
    v = np.asarray(values, dtype=float)
    if len(v) == 0:
        return {"rmse": 0, "mean": 0, "median": 0, "std": 0, "min": 0, "max": 0, "num_samples": 0}
    return {
        "rmse": float(np.sqrt(np.dot(v, v) / len(v))),
        "mean": float(np.mean(v)),
        "median": float(np.median(v)),
        "std": float(np.std(v)),
        "min": float(np.min(v)),
        "max": float(np.max(v)),
        "num_samples": len(v),
    }
