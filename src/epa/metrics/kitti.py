"""The KITTI odometry benchmark's metric, as its devkit (``evaluate_odometry.cpp``) defines it.

Segments start every 10th pose and are 100, 200, ..., 800 m long along the reference path; a segment
ends at the first pose whose path distance from the start exceeds its length. For each, the error of
the relative motion ``inv(inv(E_a) E_b) inv(R_a) R_b`` gives a translation error (its norm) and a
rotation error (``acos((trace - 1) / 2)`` of its rotation block), both divided by the segment length.
The benchmark reports their means over every segment: translation in %, rotation in deg per 100 m.

The arithmetic is the devkit's, on the devkit's matrices: 4x4 poses with the rotation blocks as a
KITTI file prints them (``Trajectory.r_as_printed``; orthonormal to 2e-7 only, which moves the small
per-segment angles by up to 3e-5 relative from those of the nearest rotations), general inverses,
the angle from the trace. On other inputs the matrices are those of the unit quaternions.

Poses are the matched pairs (frame k of the devkit is matched pair k: on a KITTI sequence with its
times, every frame). The estimate is the aligned one, its printed blocks turned by the alignment's
rotation; relative motion does not depend on a rigid alignment, so with ``align.method: se3`` (or
none) these are the devkit's numbers on the raw poses (to rounding, 1e-13), and with ``sim3`` the
scale-corrected ones monocular evaluations report.
"""

from __future__ import annotations

import numpy as np

from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.metrics.spec import Metric, Table

LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
STEP = 10


def segments(
    dist: np.ndarray, lengths=LENGTHS_M, step: int = STEP
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(first, last, length) of every segment: lastFrameFromSegmentLength, a start every ``step`` poses."""
    first = np.arange(0, len(dist), step)
    firsts, lasts, lens = [], [], []
    for length in lengths:
        # first pose strictly beyond
        last = np.searchsorted(dist, dist[first] + length, side="right")
        ok = last < len(dist)
        firsts.append(first[ok])
        lasts.append(last[ok])
        lens.append(np.full(int(ok.sum()), length))
    # the devkit's order: by start, then by length
    f, l, L = np.concatenate(firsts), np.concatenate(lasts), np.concatenate(lens)
    order = np.lexsort((L, f))
    return f[order], l[order], L[order]


def _poses(traj: Trajectory, idx: np.ndarray) -> np.ndarray:
    """(M, 4, 4) poses [R | p] of the rows ``idx``, R as printed (loadPoses)."""
    m = np.zeros((len(idx), 4, 4))
    m[:, :3, :3] = traj.r_as_printed[idx]
    m[:, :3, 3] = traj.p[idx]
    m[:, 3, 3] = 1.0
    return m


def segment_errors(
    ref: Trajectory, est: Trajectory, first: np.ndarray, last: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The devkit's per-segment errors (calcSequenceErrors, before the division by the length).

    Parameters
    ----------
    ref, est : Trajectory
        Matched pose for pose (``r_as_printed``: the matrices the devkit reads).
    first, last : ndarray of int
        Each segment's first and last pose.

    Returns
    -------
    rot_rad, trans_m : ndarray
        ``acos(clip((trace(R_err) - 1) / 2))`` and ``|t_err|`` of
        ``err = inv(inv(E_first) E_last) inv(G_first) G_last``, with general 4x4 inverses.
    """
    if len(first) == 0:
        return np.zeros(0), np.zeros(0)
    inv = np.linalg.inv
    delta_gt = inv(_poses(ref, first)) @ _poses(ref, last)
    delta_res = inv(_poses(est, first)) @ _poses(est, last)
    err = inv(delta_res) @ delta_gt
    d = 0.5 * (err[:, 0, 0] + err[:, 1, 1] + err[:, 2, 2] - 1.0)
    return np.arccos(np.clip(d, -1.0, 1.0)), np.linalg.norm(err[:, :3, 3], axis=1)


def odometry(ref: Trajectory, est: Trajectory) -> tuple[dict, dict]:
    """Summary (means, and per length) and the per-segment table, by the devkit's arithmetic
    (:func:`segment_errors`)."""
    f, l, lengths = segments(geometry.path_distances(ref.p))
    rot_rad, trans_m = segment_errors(ref, est, f, l)
    rot_deg = np.degrees(rot_rad)
    table = {
        "first": f,
        "last": l,
        "length_m": lengths,
        "trans_pct": 100.0 * trans_m / lengths,
        "rot_deg_per_100m": 100.0 * rot_deg / lengths,
    }
    n = len(f)
    summary = {
        "n_segments": int(n),
        "trans_pct": float(np.mean(table["trans_pct"])) if n else None,
        "rot_deg_per_100m": float(np.mean(table["rot_deg_per_100m"])) if n else None,
        "per_length": {
            f"{L:g}": {
                "n": int((lengths == L).sum()),
                "trans_pct": float(np.mean(table["trans_pct"][lengths == L])),
                "rot_deg_per_100m": float(np.mean(table["rot_deg_per_100m"][lengths == L])),
            }
            for L in LENGTHS_M
            if (lengths == L).any()
        },
    }
    return summary, table


def enabled(cfg: dict) -> bool:
    return bool(cfg["metrics"]["kitti"])


def compute(ref: Trajectory, est: Trajectory, cfg: dict) -> tuple[dict, dict, list[str]]:
    record, table = odometry(ref, est)
    notes = []
    if not record["n_segments"]:
        notes.append(
            f"no 100 m KITTI segment fits in the {ref.length():.3f} m matched path: the KITTI"
            " metric is empty"
        )
    return record, {"kitti_segments": table}, notes


def summary(record: dict) -> dict:
    """Empty unless metrics.kitti is on."""
    return {
        "kitti_trans_pct": record.get("trans_pct"),
        "kitti_rot_deg_per_100m": record.get("rot_deg_per_100m"),
    }


_TABLES = (
    Table(
        "kitti",
        "KITTI ODOMETRY LATEX TABLE (ROT DEG/100M / TRANS %, 100-800 M SEGMENTS)",
        per_run=lambda r: (r["rot_deg_per_100m"], r["trans_pct"]),
        has=lambda r: bool(r.get("n_segments")),
        in_text=False,
    ),
)


METRIC = Metric(
    key="kitti",  # metrics.kitti: off by default
    stage="metrics",
    enabled=enabled,
    summary=summary,
    settings=("metrics.kitti",),
    compute=compute,
    arrays=("kitti_segments.csv",),
    summary_columns=("kitti_trans_pct", "kitti_rot_deg_per_100m"),
    tables=_TABLES,
)
