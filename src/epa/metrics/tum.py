"""The TUM RGB-D benchmark's scores, as its scripts compute them (Sturm et al. 2012;
``associate.py``, ``evaluate_ate.py``, ``evaluate_rpe.py`` of ``rgbd_benchmark_tools``).

- Association (ATE): every pair with ``|a - (b + offset)| < max_difference`` is a candidate; the
  candidates sorted by ``(difference, a, b)`` are taken greedily, each stamp at most once.
- ATE: positions only, the estimate's multiplied by ``scale``, Horn's SVD fit of the estimate onto
  the reference without scale, the per-pair distances.
- RPE: no alignment. Pairs ``(i, j)`` of estimate poses: every pair, or ``max_pairs`` drawn at random
  (Python's ``random`` seeded with 0), or with ``fixed_delta`` each ``i`` with the pose closest to
  ``delta`` further in ``s``, ``m``, ``rad``, ``deg`` or ``f`` (a pair whose closest pose is the last
  one is dropped, as the script does). Each estimate stamp is given the closest reference stamp,
  dropped beyond twice the median reference interval. The error is
  ``ominus(scale(ominus(E_j, E_i)), ominus(G_j, G_i))`` with ``ominus(a, b) = inv(a) b``: its
  translation's norm (m) and rotation angle.

The script's arithmetic is kept where its bits reach a printed digit: 4x4 matrices from the
quaternions as ``transform44`` builds them, general inverses, ``numpy.dot`` products and norms, its
closest-stamp search with its tie rule. The random draws are those of the script under Python 2 (the
published script; ``sampler="python2"``) or of its Python 3 port (``"python3"``): the two ``random``
modules draw different pairs from the same seed.
"""

from __future__ import annotations

import math
import random

import numpy as np

from epa.core.errors import EpaError
from epa.metrics.spec import Table, protocol

UNITS = ("s", "m", "rad", "deg", "f")
SAMPLERS = ("python2", "python3")
STATISTICS = ("rmse", "mean", "median", "std", "min", "max")
_EPS = np.finfo(float).eps * 4.0  # transform44's bound on the squared quaternion norm


def associate(
    first: np.ndarray, second: np.ndarray, offset: float, max_difference: float
) -> tuple[np.ndarray, np.ndarray]:
    """``associate.py``'s matches between two sorted, unique stamp arrays.

    Parameters
    ----------
    first, second : ndarray
        Stamps (s), increasing.
    offset : float
        Added to ``second``.
    max_difference : float
        Strict bound on ``|a - (b + offset)|``.

    Returns
    -------
    i_first, i_second : ndarray of int
        The matched indices, by increasing first stamp.
    """
    shifted = second + offset
    # windows of candidates, one wider each side than needed: the exact test below decides
    lo = np.clip(np.searchsorted(shifted, first - max_difference) - 1, 0, len(second))
    hi = np.clip(np.searchsorted(shifted, first + max_difference, side="right") + 1, 0, len(second))
    counts = np.maximum(hi - lo, 0)
    ia = np.repeat(np.arange(len(first)), counts)
    starts = np.cumsum(counts) - counts
    ib = lo[ia] + np.arange(len(ia)) - starts[ia]
    diff = np.abs(first[ia] - shifted[ib])
    keep = diff < max_difference
    ia, ib, diff = ia[keep], ib[keep], diff[keep]
    order = np.lexsort((ib, ia, diff))  # the stamps are increasing with their indices
    return _greedy(ia[order], ib[order], len(first), len(second))


def _greedy(ia: np.ndarray, ib: np.ndarray, n_first: int, n_second: int):
    """Greedy matching of ranked candidates, in rounds: a candidate first in rank for both its
    stamps among those left is the one the sequential greedy takes; its rivals are dropped."""
    used_a, used_b = np.zeros(n_first, bool), np.zeros(n_second, bool)
    alive = np.ones(len(ia), bool)
    taken = np.zeros(len(ia), bool)
    while alive.any():
        idx = np.flatnonzero(alive)
        a, b = ia[idx], ib[idx]
        first_a = np.zeros(len(idx), bool)
        first_a[np.unique(a, return_index=True)[1]] = True
        first_b = np.zeros(len(idx), bool)
        first_b[np.unique(b, return_index=True)[1]] = True
        win = first_a & first_b
        taken[idx[win]] = True
        used_a[a[win]] = True
        used_b[b[win]] = True
        alive[idx] = ~(used_a[a] | used_b[b])
    order = np.argsort(ia[taken], kind="stable")
    return ia[taken][order], ib[taken][order]


def horn(model: np.ndarray, data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``evaluate_ate.align``: the rotation and translation taking ``model`` (N, 3) onto ``data``
    (N, 3) in the least-squares sense, without scale.

    Parameters
    ----------
    model, data : ndarray (N, 3)

    Returns
    -------
    rot : ndarray (3, 3)
    trans : ndarray (3,)
    """
    model_mean, data_mean = model.mean(axis=0), data.mean(axis=0)
    w = (model - model_mean).T @ (data - data_mean)
    u, _, vh = np.linalg.svd(w.T)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vh) < 0:
        s[2, 2] = -1.0
    rot = u @ s @ vh
    return rot, data_mean - rot @ model_mean


def ate(ref_t, ref_p, est_t, est_p, *, offset=0.0, scale=1.0, max_difference=0.02) -> dict:
    """``evaluate_ate.py``'s numbers.

    Parameters
    ----------
    ref_t, est_t : ndarray
        Increasing unique stamps (s).
    ref_p, est_p : ndarray (N, 3)
        Positions (m).
    offset, scale, max_difference : float
        The script's options.

    Returns
    -------
    dict
        ``i_ref``, ``i_est`` (the matches), ``rot``, ``trans`` (the fit of the scaled estimate),
        ``error`` (per pair, m).
    """
    i_ref, i_est = associate(ref_t, est_t, offset, max_difference)
    if len(i_ref) < 2:
        raise EpaError(
            "Couldn't find matching timestamp pairs between groundtruth and estimated trajectory!"
            " Did you choose the correct sequence?"
        )
    first, second = ref_p[i_ref], est_p[i_est] * scale
    rot, trans = horn(second, first)
    diff = second @ rot.T + trans - first
    error = np.sqrt(np.sum(diff * diff, axis=1))
    return {"i_ref": i_ref, "i_est": i_est, "rot": rot, "trans": trans, "error": error}


def statistics(error: np.ndarray) -> dict:
    """The scripts' statistics: ``rmse`` as ``sqrt(dot(e, e) / n)``, population ``std``."""
    return {
        "rmse": float(np.sqrt(np.dot(error, error) / len(error))),
        "mean": float(np.mean(error)),
        "median": float(np.median(error)),
        "std": float(np.std(error)),
        "min": float(np.min(error)),
        "max": float(np.max(error)),
    }


def transform44(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses from quaternions (x, y, z, w) and positions, by ``transform44``'s arithmetic
    (``numpy.dot`` for the norm: a stacked 1x4 by 4x1 product takes the same BLAS dot)."""
    q = np.array(q, dtype=float)
    nq = (q[:, None, :] @ q[:, :, None])[:, 0, 0]
    if (nq < _EPS).any():
        raise EpaError(
            f"pose {int(np.argmax(nq < _EPS))} (by increasing stamp): a quaternion of norm almost 0"
        )
    q *= np.sqrt(2.0 / nq)[:, None]
    o = q[:, :, None] * q[:, None, :]
    m = np.zeros((len(q), 4, 4))
    m[:, 0] = np.column_stack(
        [1.0 - o[:, 1, 1] - o[:, 2, 2], o[:, 0, 1] - o[:, 2, 3], o[:, 0, 2] + o[:, 1, 3], p[:, 0]]
    )
    m[:, 1] = np.column_stack(
        [o[:, 0, 1] + o[:, 2, 3], 1.0 - o[:, 0, 0] - o[:, 2, 2], o[:, 1, 2] - o[:, 0, 3], p[:, 1]]
    )
    m[:, 2] = np.column_stack(
        [o[:, 0, 2] - o[:, 1, 3], o[:, 1, 2] + o[:, 0, 3], 1.0 - o[:, 0, 0] - o[:, 1, 1], p[:, 2]]
    )
    m[:, 3, 3] = 1.0
    return m


def closest_index(values: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``find_closest_index`` for every target at once: the same bisection, the same tie rule
    (the first visited of two equally close values wins)."""
    values, targets = np.asarray(values, dtype=float), np.asarray(targets, dtype=float)
    lo = np.zeros(len(targets), dtype=np.int64)
    hi = np.full(len(targets), len(values), dtype=np.int64)
    best = np.zeros(len(targets), dtype=np.int64)
    difference = np.abs(values[0] - targets)
    running = lo < hi
    while running.any():
        mid = (lo + hi) // 2
        at = values[np.minimum(mid, len(values) - 1)]
        d = np.abs(at - targets)
        better = running & (d < difference)
        difference = np.where(better, d, difference)
        best = np.where(better, mid, best)
        hit = running & (targets == at)
        best = np.where(hit, mid, best)
        left = running & ~hit & (at > targets)
        right = running & ~hit & ~(at > targets)
        hi = np.where(left, mid, hi)
        lo = np.where(right, mid + 1, lo)
        running = running & ~hit & (lo < hi)
    return best


def ominus(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``inv(a) b`` of stacked 4x4 poses, with general inverses."""
    return np.linalg.inv(a) @ b


def _norms(v: np.ndarray) -> np.ndarray:
    """``numpy.linalg.norm`` of each row as the script takes it: the square root of a BLAS dot."""
    return np.sqrt((v[:, None, :] @ v[:, :, None])[:, 0, 0])


def _angles(m: np.ndarray) -> np.ndarray:
    """``compute_angle``: ``arccos`` of ``(trace - 1) / 2`` clipped to [-1, 1]."""
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    return np.arccos(np.minimum(1, np.maximum(-1, (trace - 1) / 2)))


def _along(poses: np.ndarray, unit: str) -> np.ndarray:
    """The estimate's index in ``unit`` (``distances_along_trajectory`` and
    ``rotations_along_trajectory``: running sums of each step's motion)."""
    if len(poses) < 2:
        return np.zeros(len(poses))
    motion = ominus(poses[1:], poses[:-1])
    if unit == "m":
        step = _norms(motion[:, :3, 3])
    else:
        step = _angles(motion) * (1 if unit == "rad" else 180 / np.pi)
    return np.concatenate([[0.0], np.cumsum(step)])


def _python2_sample(rng: random.Random, n: int, k: int) -> list[int]:
    """The indices Python 2.7's ``random.sample`` picks from a list of ``n`` (its two methods:
    a shrinking pool for small populations, rejection from a set otherwise; ``int(random() * n)``
    where Python 3 draws bits)."""
    setsize = 21
    if k > 5:
        setsize += 4 ** math.ceil(math.log(k * 3, 4))
    out: list[int] = []
    if n <= setsize:
        pool = list(range(n))
        for i in range(k):
            j = int(rng.random() * (n - i))
            out.append(pool[j])
            pool[j] = pool[n - i - 1]
        return out
    selected: set[int] = set()
    for _ in range(k):
        j = int(rng.random() * n)
        while j in selected:
            j = int(rng.random() * n)
        selected.add(j)
        out.append(j)
    return out


def _random_pairs(n: int, max_pairs: int, sampler: str) -> np.ndarray:
    """``max_pairs`` pairs ``(randint(0, n-1), randint(0, n-1))`` from ``random.seed(0)``."""
    rng = random.Random(0)
    if sampler == "python2":  # Python 2's randint(0, n-1) is int(random() * n)
        draws = np.array([rng.random() for _ in range(2 * max_pairs)])
        return (draws * n).astype(np.int64).reshape(-1, 2)
    return np.array([rng.randint(0, n - 1) for _ in range(2 * max_pairs)]).reshape(-1, 2)


def pose_pairs(index: np.ndarray, *, fixed_delta, delta, max_pairs, sampler) -> np.ndarray:
    """The (i, j) estimate pairs ``evaluate_trajectory`` compares, in its order.

    Parameters
    ----------
    index : ndarray
        The estimate's poses in the delta unit.
    fixed_delta, delta, max_pairs, sampler
        The script's options; ``sampler``: which Python's ``random`` draws (see module docstring).

    Returns
    -------
    ndarray (K, 2) of int
    """
    n = len(index)
    if not fixed_delta:
        if max_pairs == 0 or n < np.sqrt(max_pairs):
            i, j = np.divmod(np.arange(n * n), n)
            return np.column_stack([i, j])
        return _random_pairs(n, max_pairs, sampler)
    j = closest_index(index, index + delta)
    pairs = np.column_stack([np.arange(n), j])[j != n - 1]
    if max_pairs != 0 and len(pairs) > max_pairs:
        rng = random.Random(0)
        if sampler == "python2":
            picked = _python2_sample(rng, len(pairs), max_pairs)
        else:
            picked = rng.sample(range(len(pairs)), max_pairs)
        pairs = pairs[np.array(picked, dtype=np.int64)]
    return pairs


def rpe(
    gt_t,
    gt_poses,
    est_t,
    est_poses,
    *,
    max_pairs=10000,
    fixed_delta=False,
    delta=1.0,
    delta_unit="s",
    offset=0.0,
    scale=1.0,
    sampler="python2",
) -> np.ndarray:
    """``evaluate_rpe.evaluate_trajectory``'s result.

    Parameters
    ----------
    gt_t, est_t : ndarray
        Increasing unique stamps (s).
    gt_poses, est_poses : ndarray (N, 4, 4)
        Poses as :func:`transform44` builds them.
    max_pairs, fixed_delta, delta, delta_unit, offset, scale
        The script's options; ``sampler``: ``python2`` or ``python3`` (its ``random``).

    Returns
    -------
    ndarray (K, 6)
        Rows ``stamp_est_0, stamp_est_1, stamp_gt_0, stamp_gt_1, trans (m), rot (rad)``.
    """
    if delta_unit not in UNITS:
        raise EpaError(f"Unknown unit for delta: '{delta_unit}'")
    back = est_t[closest_index(est_t, gt_t[closest_index(gt_t, est_t + offset)] - offset)]
    if len(np.unique(back)) < 2:
        raise EpaError(
            "Number of overlap in the timestamps is too small. Did you run the evaluation on the"
            " right files?"
        )
    index = {"s": est_t, "f": np.arange(len(est_t))}.get(delta_unit)
    index = _along(est_poses, delta_unit) if index is None else index
    pairs = pose_pairs(
        index, fixed_delta=fixed_delta, delta=delta, max_pairs=max_pairs, sampler=sampler
    )
    max_gap = 2 * np.median(gt_t[1:] - gt_t[:-1])
    e0, e1 = est_t[pairs[:, 0]], est_t[pairs[:, 1]]
    g0, g1 = closest_index(gt_t, e0 + offset), closest_index(gt_t, e1 + offset)
    ok = ~(
        (np.abs(gt_t[g0] - (e0 + offset)) > max_gap) | (np.abs(gt_t[g1] - (e1 + offset)) > max_gap)
    )
    pairs, g0, g1 = pairs[ok], g0[ok], g1[ok]
    motion = ominus(est_poses[pairs[:, 1]], est_poses[pairs[:, 0]])
    motion[:, :3, 3] *= scale
    error = ominus(motion, ominus(gt_poses[g1], gt_poses[g0]))
    rows = np.column_stack(
        [
            est_t[pairs[:, 0]],
            est_t[pairs[:, 1]],
            gt_t[g0],
            gt_t[g1],
            _norms(error[:, :3, 3]),
            _angles(error),
        ]
    )
    if len(rows) < 2:
        raise EpaError(
            "Couldn't find matching timestamp pairs between groundtruth and estimated trajectory!"
        )
    return rows


def ate_lines(error: np.ndarray, verbose: bool) -> list[str]:
    """What ``evaluate_ate.py`` prints."""
    s = statistics(error)
    if not verbose:
        return [f"{s['rmse']:f}"]
    return [f"compared_pose_pairs {len(error)} pairs"] + [
        f"absolute_translational_error.{k} {s[k]:f} m" for k in STATISTICS
    ]


def rpe_lines(rows: np.ndarray, verbose: bool) -> list[str]:
    """What ``evaluate_rpe.py`` prints: the mean translational error alone as Python prints a
    float, or every statistic; ``rotational_error.median`` is printed in rad with the unit ``deg``,
    as the script prints it."""
    trans, rot = rows[:, 4], rows[:, 5]
    if not verbose:
        return [str(np.mean(trans))]
    t, r = statistics(trans), statistics(rot)
    return (
        [f"compared_pose_pairs {len(trans)} pairs"]
        + [f"translational_error.{k} {t[k]:f} m" for k in STATISTICS]
        + [
            f"rotational_error.{k} {r[k] if k == 'median' else r[k] * 180.0 / np.pi:f} deg"
            for k in STATISTICS
        ]
    )


def evaluate(reference, estimate, c: dict) -> dict:
    """The record of both scripts on two trajectories (``Trajectory``: t, p, q), with the settings
    ``c`` of ``metrics.tum``: the ATE's and the RPE's statistics as the scripts print them, every
    angle in deg (the printed RPE median is in rad, a quirk of the script kept only in its text)."""
    fit = ate(
        reference.t,
        reference.p,
        estimate.t,
        estimate.p,
        offset=c["offset"],
        scale=c["scale"],
        max_difference=c["max_difference"],
    )
    rows = rpe(
        reference.t,
        transform44(reference.q, reference.p),
        estimate.t,
        transform44(estimate.q, estimate.p),
        max_pairs=c["max_pairs"],
        fixed_delta=c["fixed_delta"],
        delta=c["delta"],
        delta_unit=c["delta_unit"],
        offset=c["offset"],
        scale=c["scale"],
        sampler=c["sampler"],
    )
    rot = statistics(rows[:, 5])
    return {
        "ate": {"pairs": len(fit["error"]), "trans_m": statistics(fit["error"])},
        "rpe": {
            "pairs": len(rows),
            "trans_m": statistics(rows[:, 4]),
            "rot_deg": {k: v * 180.0 / np.pi for k, v in rot.items()},
        },
        "settings": dict(c),
    }


def compute(ref, est, cfg: dict, *, reference, estimate) -> tuple[dict, dict, list[str]]:
    """The protocol on the whole cropped trajectories: its own association, no epica alignment."""
    c = {k: v for k, v in cfg["metrics"]["tum"].items() if k != "enabled"}
    return evaluate(reference, estimate, c), {}, []


def summary(record: dict) -> dict:
    """Empty unless metrics.tum is on."""
    if not record:
        return {}
    return {
        "tum_ate_rmse_m": record["ate"]["trans_m"]["rmse"],
        "tum_rpe_trans_rmse_m": record["rpe"]["trans_m"]["rmse"],
        "tum_rpe_rot_rmse_deg": record["rpe"]["rot_deg"]["rmse"],
    }


_TABLES = (
    Table(
        "tum",
        "TUM RGB-D LATEX TABLE (ATE RMSE M / RPE TRANS RMSE M, THE BENCHMARK'S SCRIPTS)",
        per_run=lambda r: (r["ate"]["trans_m"]["rmse"], r["rpe"]["trans_m"]["rmse"]),
    ),
)


METRIC = protocol(
    "tum",  # metrics.tum: off by default; epa eval --protocol tum
    summary=summary,
    compute=compute,
    inputs=("reference", "estimate"),  # its own association, not epica's matched poses
    summary_columns=("tum_ate_rmse_m", "tum_rpe_trans_rmse_m", "tum_rpe_rot_rmse_deg"),
    tables=_TABLES,
)
