"""Consistency: is the estimator's own uncertainty honest? NEES per pose, ±3σ bounds, and RMSE(t) /
NEES(t) across runs.

Convention: orientation covariance is of the *local* (body-frame) error, R_true = R_est Exp(d),
as OpenVINS writes it (its JPL quaternion error on the global-to-IMU rotation is this error);
ROS covariances are converted to it when read (see :mod:`epa.readers.bags`).

The errors are taken in the estimate's own frames, where its covariance is valid: the matched
reference is mapped into the estimate's world by the inverse of Step 3 and into its sensor frame by
the inverse of Step 2 (never the covariance into the reference's).
"""

from __future__ import annotations

import numpy as np

from epa.core import geometry, ranks
from epa.core.trajectory import Trajectory
from epa.metrics.spec import Metric, Table
from epa.steps.align import Similarity

SUMMARY_COLUMNS = ("nees_rot_mean", "nees_pos_mean", "outside_3sigma_pct")


def enabled(cfg: dict) -> bool:
    return True


def summary(record: dict) -> dict:
    """Empty without covariance."""
    return {k: record[k] for k in SUMMARY_COLUMNS} if record.get("available") else {}


def reference_in_estimate_frame(
    ref: Trajectory, alignment: Similarity, extrinsic=None
) -> tuple[np.ndarray, np.ndarray]:
    """Orientations ((4, N) quaternion rows x, y, z, w) and positions (N, 3) of the (matched)
    reference poses expressed as the estimate's poses would be: Step 3 undone (world), then Step 2
    undone (body -> sensor, scale). By quaternions, not (N, 3, 3) matrices: half the stage's time
    at 1M poses."""
    q, p = alignment.inverse().apply_rows(geometry.component_rows(ref.q), ref.p)
    return (q, p) if extrinsic is None else extrinsic.to_sensor_rows(q, p)


def _quadratic(e: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """e^T C^-1 e per pose; nan where C is not positive definite. C = L L^T by the 3x3 Cholesky
    written out over all poses at once (LAPACK's, pose by pose, cost 0.4 µs a pose): L's pivots in
    LAPACK's order, and C is not positive definite where one is <= 0 or NaN, LAPACK's test. Only
    the lower triangle is read, as numpy.linalg.cholesky reads it."""
    c = np.ascontiguousarray(np.reshape(cov, (len(cov), 9)).T)  # each entry contiguous: faster
    e0, e1, e2 = np.ascontiguousarray(np.transpose(e))
    with np.errstate(invalid="ignore", divide="ignore"):
        l00 = np.sqrt(c[0])
        l10, l20 = c[3] / l00, c[6] / l00
        p1 = c[4] - l10 * l10
        l11 = np.sqrt(p1)
        l21 = (c[7] - l20 * l10) / l11
        p2 = c[8] - (l20 * l20 + l21 * l21)
        good = (c[0] > 0) & (p1 > 0) & (p2 > 0)  # NaN compares false: not positive definite
        # L y = e by forward substitution; e^T C^-1 e = |y|^2
        y0 = e0 / l00
        y1 = (e1 - l10 * y0) / l11
        y2 = (e2 - (l20 * y0 + l21 * y1)) / np.sqrt(p2)
        return np.where(good, y0 * y0 + y1 * y1 + y2 * y2, np.nan)


def evaluate(
    ref: Trajectory, est: Trajectory, alignment: Similarity, extrinsic=None
) -> tuple[dict, dict]:
    """NEES and ±3σ statistics of matched poses. ``est`` is the estimate as read (with its own
    covariance); ``ref`` the matched reference; ``alignment``/``extrinsic`` what Steps 3/2 found."""
    if est.cov_rot is None or est.cov_pos is None:
        return {"available": False, "reason": "the estimate has no covariance"}, {}
    q_ref, p_ref = reference_in_estimate_frame(ref, alignment, extrinsic)
    e_pos = p_ref - est.p
    # R_ref = R_est Exp(e_rot): e_rot = log(q_est^-1 q_ref), (N, 3) over its rows
    inv_est = geometry.conj_rows(geometry.component_rows(est.q))
    e_rot = geometry.log_rows(geometry.mul_rows(inv_est, q_ref)).T
    nees_pos = _quadratic(e_pos, est.cov_pos)
    nees_rot = _quadratic(e_rot, est.cov_rot)
    sig_pos = np.sqrt(np.clip(np.diagonal(est.cov_pos, axis1=1, axis2=2), 0, None))
    sig_rot = np.sqrt(np.clip(np.diagonal(est.cov_rot, axis1=1, axis2=2), 0, None))
    valid = np.isfinite(nees_pos) & np.isfinite(nees_rot)
    outside = np.concatenate([np.abs(e_pos) > 3 * sig_pos, np.abs(e_rot) > 3 * sig_rot], axis=1)[
        valid
    ]
    axes = ["pos_x", "pos_y", "pos_z", "rot_x", "rot_y", "rot_z"]
    n = int(valid.sum())
    summary = {
        "available": n > 0,
        "n": n,
        "n_not_positive_definite": int((~valid).sum()),
        "convention": "local orientation error, R_true = R_est Exp(e); errors in the estimate's frames",
        "nees_pos_mean": float(np.mean(nees_pos[valid])) if n else None,
        "nees_rot_mean": float(np.mean(nees_rot[valid])) if n else None,
        "nees_pos_median": ranks.median(nees_pos[valid]) if n else None,
        "nees_rot_median": ranks.median(nees_rot[valid]) if n else None,
        # mean over the six axes of the share of poses outside ±3σ (0.27 % for a consistent Gaussian)
        "outside_3sigma_pct": float(100 * outside.mean()) if n else None,
        "outside_3sigma_pct_by_axis": dict(zip(axes, (100 * outside.mean(axis=0)).tolist()))
        if n
        else None,
    }
    if not n:
        summary["reason"] = "no pose has a positive-definite covariance"
    table = {
        "t": est.t,
        "nees_pos": nees_pos,
        "nees_rot": nees_rot,
        **{f"err_{a}": e_pos[:, k] for k, a in enumerate("xyz")},
        **{f"sigma_{a}": sig_pos[:, k] for k, a in enumerate("xyz")},
        **{f"err_rot_{a}": e_rot[:, k] for k, a in enumerate("xyz")},
        **{f"sigma_rot_{a}": sig_rot[:, k] for k, a in enumerate("xyz")},
    }
    return summary, table


def across_runs(runs: dict[str, dict]) -> tuple[dict, dict]:
    """RMSE(t) and NEES(t) over the stamps of the first run (by name) that every run matched within
    half its median pose spacing. Runs of a simulator share stamps exactly (ov_eval's case); real runs of
    one sequence evaluate at slightly different reference poses, and would otherwise share none.
    ``runs``: run -> {"t": stamps, "trans_m", "rot_deg": APE per pose, "nees_pos", "nees_rot": NEES per
    pose or None}. NEES(t) only when every run has covariance."""
    if not runs:
        return {"runs": 0}, {}
    from epa.core.stamps import nearest_from

    stamps = {k: np.asarray(r["t"], float) for k, r in runs.items()}
    grid = stamps[min(stamps)]
    tol = 0.5 * ranks.median(np.diff(grid)) if len(grid) > 1 else 0.0
    keep = np.ones(len(grid), bool)
    sel = {}
    for k, t in stamps.items():
        if not len(t):
            keep[:] = False
            sel[k] = np.zeros(len(grid), np.intp)
            continue
        sel[k] = nearest_from(t, grid, np.zeros(len(grid), np.int64))
        keep &= np.abs(t[sel[k]] - grid) <= tol * (1 + 1e-9)
    common = grid[keep]
    sel = {k: idx[keep] for k, idx in sel.items()}

    def stack(name):
        return np.array([np.asarray(runs[k][name], float)[sel[k]] for k in runs])

    table = {
        "t": common,
        "rmse_pos_m": np.sqrt(np.mean(stack("trans_m") ** 2, axis=0)),
        "rmse_rot_deg": np.sqrt(np.mean(stack("rot_deg") ** 2, axis=0)),
    }
    if all(runs[k].get("nees_pos") is not None for k in runs):
        table["nees_pos"] = np.nanmean(stack("nees_pos"), axis=0) if len(common) else np.zeros(0)
        table["nees_rot"] = np.nanmean(stack("nees_rot"), axis=0) if len(common) else np.zeros(0)
    n = len(common)
    mean = lambda name: float(np.sqrt(np.mean(table[name] ** 2))) if n else None  # noqa: E731
    summary = {
        "runs": len(runs),
        "n_common": int(n),
        "rmse_pos_m": mean("rmse_pos_m"),
        "rmse_rot_deg": mean("rmse_rot_deg"),
        "nees_pos_mean": float(np.nanmean(table["nees_pos"]))
        if n and "nees_pos" in table
        else None,
        "nees_rot_mean": float(np.nanmean(table["nees_rot"]))
        if n and "nees_rot" in table
        else None,
    }
    return summary, table


_TABLES = (
    Table(
        "nees",
        "NEES LATEX TABLE (ORI / POS, 3 = CONSISTENT)",
        per_run=lambda r: (r["nees_rot_mean"], r["nees_pos_mean"]),
        has=lambda r: bool(r.get("available")),
        missing="no covariance",
    ),
)


METRIC = Metric(
    key="consistency",
    stage="consistency",  # its own stage: records available false without covariance
    enabled=enabled,
    summary=summary,
    arrays=("nees.csv",),
    summary_columns=SUMMARY_COLUMNS,
    tables=_TABLES,
)
