"""rpg_trajectory_evaluation's errors and statistics (uzh-rpg, ``analyze_trajectory_single.py``), in rpg's
own arithmetic, quirks included; and ``mode: rpg``'s metric, which writes them per case.

The arithmetic (each function names the rpg function it reproduces; the quirks are listed in
:mod:`epa.rpg.protocol` and docs/protocols-rpg.md): the absolute errors of the aligned estimate
(``trans``, ``rot`` through rpg's ``logmap_so3``, rpg's origin-distance ``scale``); the relative-error
distances (10..50 % of the whole reference path, truncated to two decimals); rpg's pair search and the
relative errors of the *unaligned* estimate (only the Sim3 scale entering); rpg's statistics; and the
statistics over trials (``MulTrajError``). ``epa rpg`` (:mod:`epa.rpg.command`) and ``mode: rpg`` both call
these, so a grid case and ``epa rpg`` on the same files give the same numbers.

The metric (``mode: rpg`` only; in the registry so the metrics stage computes it on the matched poses):
``metrics.json`` ``rpg`` holds rpg's statistics (``absolute``: ``trans``, ``rot``, ``scale``; ``relative``:
per distance ``trans``, ``trans_perc``, ``yaw``, ``rot``, ``gravity``, ``rot_deg_per_m``; each ``rmse, mean,
median, std, min, max, num_samples``), ``06_metrics/rpg_relative_errors.csv`` every pair's relative
errors, and ``06_metrics/rpg/`` rpg's own YAML files with the bytes ``epa rpg`` writes.
"""

from __future__ import annotations

import math

import numpy as np

from epa.core.trajectory import Trajectory
from epa.metrics.spec import Metric
from epa.steps.rpg import EPS, quaternion_matrix

BOXPLOT_PERCENTAGES = (0.1, 0.2, 0.3, 0.4, 0.5)
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


def path_length(p: np.ndarray) -> float:
    """rpg's ``traj_length``: the accumulated length of the whole (raw) groundtruth path."""
    return float(distance_from_start(p)[-1])


def errors(
    p_es, q_es, p_gt, q_gt, scale: float, p_al, q_al, traj_length: float, distances=None
) -> dict:
    """One trial's errors as rpg's ``Trajectory`` computes them, after the association and alignment.

    Parameters
    ----------
    p_es, q_es : ndarray (N, 3), (N, 4)
        The matched estimate, unaligned (the relative errors are computed on it).
    p_gt, q_gt : ndarray (N, 3), (N, 4)
        The matched groundtruth.
    scale : float
        The alignment's scale (1 but for ``sim3``): it multiplies the estimate's relative translations.
    p_al, q_al : ndarray (N, 3), (N, 4)
        The aligned estimate (:func:`epa.steps.rpg.apply_alignment`).
    traj_length : float
        The whole groundtruth's path length (:func:`path_length`), for the distances.
    distances : list of float, optional
        The relative-error distances; None: rpg's 10..50 % of ``traj_length``.

    Returns
    -------
    dict
        ``distances``, ``abs`` (per-pose ``trans``, ``trans_vec``, ``rot``, ``ypr``, ``scale``),
        ``abs_stats`` (``trans``, ``rot``, ``scale``), ``rel`` {distance: the six metric vectors,
        ``pairs`` and ``<metric>_stats``}; a distance listed twice is computed once, as rpg does.
    """
    accum = distance_from_start(p_gt)
    if distances is None:
        distances = boxplot_distances(traj_length)
    ab = absolute_errors(p_al, q_al, p_gt, q_gt)
    rel = {}
    for d in distances:
        if d in rel:
            continue
        e = relative_errors(p_es, q_es, p_gt, q_gt, d, 0.2 * d, accum, scale)
        e.update({m + "_stats": statistics(e[m]) for m in REL_METRICS})
        rel[d] = e
    return {
        "distances": list(distances),
        "abs": ab,
        "abs_stats": {k: statistics(ab[k]) for k in ("trans", "rot", "scale")},
        "rel": rel,
    }


MT_ABS = (("rmse_trans", "trans"), ("rmse_rot", "rot"), ("rmse_scale", "scale"))


def trial_rmse_statistics(abs_stats: list[dict]) -> dict:
    """rpg's ``MulTrajError`` absolute statistics: over the trials, the statistics of each trial's RMSE.

    Parameters
    ----------
    abs_stats : list of dict
        Each trial's absolute statistics (``trans``, ``rot``, ``scale``, each with its ``rmse``).

    Returns
    -------
    dict
        ``rmse_trans``, ``rmse_rot``, ``rmse_scale``: :func:`statistics` of the per-trial RMSEs
        (``analyze_trajectories.py``'s RMSE table prints ``rmse_trans``'s mean, median, min, max).
    """
    return {
        et: (
            None  # mode rpg leaves out a statistic that is not finite
            if any(a[lab] is None for a in abs_stats)
            else statistics(np.array([a[lab]["rmse"] for a in abs_stats]))
        )
        for et, lab in MT_ABS
    }


def multi_trial_statistics(results: list[dict]) -> dict:
    """rpg's ``MulTrajError``: statistics of the per-trial RMSEs, relative errors pooled over trials per
    distance, and pooled over all distances (``overall``).

    Parameters
    ----------
    results : list of dict
        The successful trials in order, each with ``abs_stats`` (``trans``, ``rot``, ``scale``, each
        with its ``rmse``), ``distances`` and ``rel`` {distance: {metric: vector}}, as :func:`errors`
        returns them.

    Returns
    -------
    dict
        ``rmse`` {``rmse_trans`` ...: per-trial list}, ``abs_stats`` (their statistics), ``rel`` (the
        pooled vectors per distance), ``rel_stats`` and ``overall``.
    """
    rmse = {et: [r["abs_stats"][lab]["rmse"] for r in results] for et, lab in MT_ABS}
    abs_stats = trial_rmse_statistics([r["abs_stats"] for r in results])
    rel: dict = {}
    for k, r in enumerate(results):
        for d in r["distances"]:
            e = r["rel"][d]
            if k == 0:
                rel[d] = {m: e[m] for m in REL_METRICS}
            else:  # rpg appends once per listed distance, so a repeated distance is appended twice
                rel[d] = {m: np.concatenate((rel[d][m], e[m])) for m in REL_METRICS}
    rel_stats = {d: {m: statistics(v[m]) for m in REL_METRICS} for d, v in rel.items()}
    overall = {m: statistics([x for d in rel for x in rel[d][m].tolist()]) for m in REL_METRICS}
    return {
        "rmse": rmse,
        "abs_stats": abs_stats,
        "rel": rel,
        "rel_stats": rel_stats,
        "overall": overall,
    }


# ----------------------------------------------------------------------------- rpg's files
def dist_str(d: float) -> str:
    """rpg's file-name form of a distance: ``'{:3.1f}'`` with ``.`` -> ``_``."""
    return f"{d:3.1f}".replace(".", "_")


def yaml_text(stats: dict) -> str:
    """A statistics file as rpg writes it (``yaml.dump(..., default_flow_style=False)``: keys sorted,
    block style, Python ``repr`` floats)."""
    import yaml

    return yaml.dump(stats, default_flow_style=False)


def rel_labels(e: dict) -> dict:
    """One distance's statistics under rpg's file labels (``trans``, ``trans_perc``, ...)."""
    return {lab: e[m + "_stats"] for m, lab in zip(REL_METRICS, REL_LABELS)}


# ----------------------------------------------------------------------------- mode: rpg
REL_COLUMNS = dict(
    zip(
        REL_METRICS, ("trans_m", "trans_perc", "yaw_deg", "rot_deg", "gravity_deg", "rot_deg_per_m")
    )
)


def enabled(cfg: dict) -> bool:
    return cfg.get("mode") == "rpg"


def compute(
    ref: Trajectory,
    est: Trajectory,
    cfg: dict,
    *,
    unaligned: Trajectory,
    transform: dict,
    reference: Trajectory,
) -> tuple[dict, dict, list[str]]:
    """rpg's statistics of one case (``mode: rpg``: the association and alignment were rpg's).

    Parameters
    ----------
    ref : Trajectory
        The matched reference.
    est : Trajectory
        The matched estimate under rpg's alignment (:func:`epa.steps.rpg.fit`).
    unaligned : Trajectory
        The matched estimate before the alignment.
    transform : dict
        The alignment record (``method``, ``first_n``, ``scale``).
    reference : Trajectory
        The whole (cropped) reference: its path length gives the distances.

    Returns
    -------
    (record, arrays, notes)
    """
    length = path_length(reference.p)
    with np.errstate(divide="ignore", invalid="ignore"):  # a non-finite statistic is noted below
        res = errors(
            unaligned.p, unaligned.q, ref.p, ref.q, transform["scale"], est.p, est.q, length
        )
    notes = []

    def finite(stats: dict, what: str):
        """rpg's statistics, or None with a note where one is inf or nan (rpg would print it)."""
        if all(math.isfinite(v) for k, v in stats.items() if k != "num_samples"):
            return stats
        why = (
            " (rpg's scale error divides by the reference's distance from the origin, 0 where it"
            " passes through it)"
            if what == "absolute scale"
            else ""
        )
        notes.append(f"rpg: the {what} error is not finite at some pose{why}: left out")
        return None

    record = {
        "align_type": transform["method"],
        "align_num_frames": transform["first_n"],
        "traj_length_m": length,
        "distances_m": res["distances"],
        "absolute": {k: finite(v, f"absolute {k}") for k, v in res["abs_stats"].items()},
        "relative": [
            {
                "distance_m": d,
                **{k: finite(v, f"{d} m relative {k}") for k, v in rel_labels(e).items()},
            }
            for d, e in res["rel"].items()
        ],
    }
    notes += [
        f"rpg: fewer than 2 pairs {d} m apart in the {length:.2f} m reference: rpg's statistics at"
        " that distance are its zeros (num_samples 0)"
        for d, e in res["rel"].items()
        if not len(e["pairs"])
    ]
    return record, {"rpg_relative_errors": _relative_table(res["rel"])}, notes


def _relative_table(rel: dict) -> dict:
    """06_metrics/rpg_relative_errors.csv: every pair's relative errors, distance by distance."""
    rows = [(d, e) for d, e in rel.items() if len(e["pairs"])]
    return {
        "distance_m": np.concatenate(
            [np.full(len(e["pairs"]), d) for d, e in rows] or [np.zeros(0)]
        ),
        "i_start": np.concatenate([e["pairs"][:, 0] for _, e in rows] or [np.zeros(0)]).astype(int),
        "i_end": np.concatenate([e["pairs"][:, 1] for _, e in rows] or [np.zeros(0)]).astype(int),
        **{
            c: np.concatenate([e[m] for _, e in rows] or [np.zeros(0)])
            for m, c in REL_COLUMNS.items()
        },
    }


def summary(record: dict) -> dict:
    return {}


def align_str(record: dict) -> str:
    """rpg's ``<align_type>_<align_num_frames>`` of a record (its file names)."""
    return f"{record['align_type']}_{record['align_num_frames']}"


def documents(record: dict) -> dict[str, str]:
    """rpg's statistics files of one case, ``{file name: text}``: the bytes ``epa rpg`` writes into a
    fresh ``saved_results/traj_est/`` (two distances with one ``{:3.1f}`` name: the later one's), but
    for a statistic that is not finite, left out."""
    absolute = {k: v for k, v in record["absolute"].items() if v is not None}
    docs = {f"absolute_err_statistics_{align_str(record)}.yaml": yaml_text(absolute)}
    for rel in record["relative"]:
        stats = {k: v for k, v in rel.items() if k != "distance_m" and v is not None}
        docs[f"relative_error_statistics_{dist_str(rel['distance_m'])}.yaml"] = yaml_text(stats)
    return docs


METRIC = Metric(
    key="rpg",  # on in mode rpg only (no metrics.rpg key): rpg's statistics are a protocol's, not epica's
    stage="metrics",
    enabled=enabled,
    summary=summary,  # summary.csv keeps epica's columns; rpg's numbers are in results/rpg_*.txt
    settings=("mode",),
    compute=compute,
    # what compute() needs beyond the aligned matched poses (the metrics stage passes these)
    inputs=("unaligned", "transform", "reference"),
    arrays=("rpg_relative_errors.csv",),
    tables=(),  # rpg's summary table has its own layout (epa.outputs.tables.rpg)
    documents=documents,
)
