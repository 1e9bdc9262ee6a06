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

from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.metrics.spec import Table

KEY = "kitti"  # metrics.kitti: off by default
STAGE = "metrics"
AFTER = None
ARRAYS = ("kitti_segments.csv",)
SUMMARY_COLUMNS = ("kitti_trans_pct", "kitti_rot_deg_per_100m")

LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
STEP = 10


def segments(
    dist: np.ndarray, lengths=LENGTHS_M, step: int = STEP
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(first, last, length) of every segment: lastFrameFromSegmentLength, a start every ``step`` poses."""
    first = np.arange(0, len(dist), step)
    firsts, lasts, lens = [], [], []
    for length in lengths:
        last = np.searchsorted(
            dist, dist[first] + length, side="right"
        )  # first pose strictly beyond
        ok = last < len(dist)
        firsts.append(first[ok])
        lasts.append(last[ok])
        lens.append(np.full(int(ok.sum()), length))
    # the devkit's order: by start, then by length
    f, l, L = np.concatenate(firsts), np.concatenate(lasts), np.concatenate(lens)
    order = np.lexsort((L, f))
    return f[order], l[order], L[order]


def odometry(ref: Trajectory, est: Trajectory) -> tuple[dict, dict]:
    """Summary (means, and per length) and the per-segment table. The per-segment error is the RPE's
    (``geometry.relative_errors``): the devkit's inv(delta_est) delta_ref has the same angle and
    translation norm as the RPE's inv(delta_ref) delta_est."""
    f, l, lengths = segments(geometry.path_distances(ref.p))
    rot_deg, trans_m = geometry.relative_errors(
        geometry.pose_discrepancy(ref.q, est.q), ref.p, est.p, f, l
    )
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


TABLES = (
    Table(
        "kitti",
        "KITTI ODOMETRY LATEX TABLE (ROT DEG/100M / TRANS %, 100-800 M SEGMENTS)",
        per_run=lambda r: (r["rot_deg_per_100m"], r["trans_pct"]),
        has=lambda r: bool(r.get("n_segments")),
        in_text=False,
    ),
)
