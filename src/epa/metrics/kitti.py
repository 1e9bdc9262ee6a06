"""The KITTI odometry benchmark's metric, as its devkit (``evaluate_odometry.cpp``) defines it.

Segments start every 10th pose and are 100, 200, ..., 800 m long along the reference path; a segment
ends at the first pose whose path distance from the start exceeds its length. For each, the error of
the relative motion ``inv(inv(E_a) E_b) inv(R_a) R_b`` gives a translation error (its norm) and a
rotation error (its angle), both divided by the segment length. The benchmark reports their means
over every segment: translation in %, rotation in deg per 100 m.

Poses are the matched pairs (frame k of the devkit is matched pair k: on a KITTI sequence with its
times, every frame). The estimate is the aligned one; relative motion does not depend on a rigid
alignment, so with ``align.method: se3`` (or none) these are the devkit's numbers on the raw poses,
and with ``sim3`` the scale-corrected ones monocular evaluations report.
"""

from __future__ import annotations

import numpy as np

from epa.trajectory import Trajectory

LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
STEP = 10


def path_distances(p: np.ndarray) -> np.ndarray:
    """Distance along the path at each pose (trajectoryDistances: a running sum, in pose order)."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def segments(dist: np.ndarray, lengths=LENGTHS_M, step: int = STEP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(first, last, length) of every segment: lastFrameFromSegmentLength, a start every ``step`` poses."""
    first = np.arange(0, len(dist), step)
    firsts, lasts, lens = [], [], []
    for length in lengths:
        last = np.searchsorted(dist, dist[first] + length, side="right")  # first pose strictly beyond
        ok = last < len(dist)
        firsts.append(first[ok])
        lasts.append(last[ok])
        lens.append(np.full(int(ok.sum()), length))
    # the devkit's order: by start, then by length
    f, l, L = np.concatenate(firsts), np.concatenate(lasts), np.concatenate(lens)
    order = np.lexsort((L, f))
    return f[order], l[order], L[order]


def odometry(ref: Trajectory, est: Trajectory) -> tuple[dict, dict]:
    """Summary (means, and per length) and the per-segment table."""
    f, l, lengths = segments(path_distances(ref.p))
    # relative motion of each: delta = inv(P_f) P_l
    r_ref = np.einsum("nji,njk->nik", ref.r[f], ref.r[l])
    t_ref = np.einsum("nji,nj->ni", ref.r[f], ref.p[l] - ref.p[f])
    r_est = np.einsum("nji,njk->nik", est.r[f], est.r[l])
    t_est = np.einsum("nji,nj->ni", est.r[f], est.p[l] - est.p[f])
    # error = inv(delta_est) delta_ref
    r_err = np.einsum("nji,njk->nik", r_est, r_ref)
    t_err = np.einsum("nji,nj->ni", r_est, t_ref - t_est)
    cos = np.clip(0.5 * (np.trace(r_err, axis1=1, axis2=2) - 1.0), -1.0, 1.0)
    rot = np.arccos(cos) / lengths  # rad per m
    trans = np.linalg.norm(t_err, axis=1) / lengths  # m per m
    table = {"first": f, "last": l, "length_m": lengths, "trans_pct": 100.0 * trans,
             "rot_deg_per_100m": np.degrees(rot) * 100.0}
    n = len(f)
    summary = {"n_segments": int(n),
               "trans_pct": float(np.mean(table["trans_pct"])) if n else None,
               "rot_deg_per_100m": float(np.mean(table["rot_deg_per_100m"])) if n else None,
               "per_length": {f"{L:g}": {"n": int((lengths == L).sum()),
                                         "trans_pct": float(np.mean(table["trans_pct"][lengths == L])),
                                         "rot_deg_per_100m": float(np.mean(table["rot_deg_per_100m"][lengths == L]))}
                              for L in LENGTHS_M if (lengths == L).any()}}
    return summary, table
