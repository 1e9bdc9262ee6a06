"""Error metrics on matched, aligned pose pairs: ATE, RPE (evo and ov_eval semantics), drift rate.

Pair selection is explicit (index arrays), so the drift stage can re-use the very same pairs and
errors when it keeps only the valid ones.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from epa.core import geometry, ranks
from epa.core.errors import EpaError
from epa.core.records import AccuracyRecord
from epa.core.stamps import closest_pair_blocks, closest_pairs, run_starts
from epa.core.trajectory import Trajectory

RPE_UNITS = ("frames", "m", "s", "deg", "rad")
# The time RPE as a declaration names it, whatever ``metrics.time_delta`` names its record and tables
# (rpe_time_1s, rpe_time_2s, ...: time_rpe_key): what a metric's record or table may follow.
TIME_RPE = "rpe_time"
# the keys of evaluate's record: what a registered metric's record can follow in metrics.json
RECORD_KEYS = (
    "n_matched",
    "ref_length_m",
    "duration_s",
    "ate",
    "rpe_distance",
    "drift_rate_pct",
    TIME_RPE,
    "rpe",
)
# the paper tables of these metrics (epa.outputs.tables), in order: what a metric's table can follow
# (base_tables gives them as the grid names them)
BASE_TABLES = (
    "ate",
    "rpe_distance",
    "drift_rate",
    TIME_RPE,
    "success_rate",
    "success_auc",
    "valid_ate",
    "valid_rpe_distance",
    "valid_drift_rate",
    f"valid_{TIME_RPE}",
)


STATISTICS = ("rmse", "mean", "median", "std", "min", "max")


def time_rpe_name(time_delta: float) -> str:
    """The time RPE's name under ``metrics.time_delta`` (s): 1.0 -> ``1s``, 2.0 -> ``2s``, 0.5 ->
    ``0.5s``. Its record in metrics.json and drift.json is ``rpe_time_<name>``, its tables
    ``rpe_time_<name>`` and ``valid_rpe_time_<name>``, its summary.csv columns ``time_rpe_<name>_*``."""
    return f"{float(time_delta):g}s"  # as segment_key spells a length


def time_rpe_key(time_delta: float) -> str:
    """The time RPE's record key under ``metrics.time_delta`` (``rpe_time_1s`` at 1 s)."""
    return "rpe_time_" + time_rpe_name(time_delta)


def time_rpe_in(record: dict) -> tuple[str, dict] | None:
    """The name (``1s``) and entry of the time RPE a written record holds, whatever the
    ``metrics.time_delta`` it was made with; None without one."""
    for key, value in record.items():
        if key.startswith("rpe_time_") and isinstance(value, dict):
            return key.removeprefix("rpe_time_"), value
    return None


def base_tables(time_delta: float) -> tuple[str, ...]:
    """BASE_TABLES with the time RPE's tables named after ``metrics.time_delta``."""
    named = time_rpe_key(time_delta)
    return tuple(
        named if t == TIME_RPE else f"valid_{named}" if t == f"valid_{TIME_RPE}" else t
        for t in BASE_TABLES
    )


def stats(x: np.ndarray) -> dict:
    """The statistics of a sample of errors.

    Parameters
    ----------
    x : ndarray
        The errors (any shape; flattened).

    Returns
    -------
    dict
        ``n`` and each of STATISTICS. An empty sample has ``n`` 0 and None for each statistic,
        never NaN: the record that holds it says why it is empty (a note).
    """
    x = np.asarray(x, float).ravel()
    if x.size == 0:
        return {"n": 0, **dict.fromkeys(STATISTICS)}
    # np.mean's and np.std's arithmetic (the sum divided by n; the mean of the squared deviations
    # from that mean), the mean summed once and the squares in one scratch array
    mean = np.add.reduce(x) / x.size
    work = np.multiply(x, x)
    rmse = np.sqrt(np.add.reduce(work) / x.size)
    np.subtract(x, mean, out=work)
    std = np.sqrt(np.add.reduce(np.multiply(work, work, out=work)) / x.size)
    return {
        "n": int(x.size),
        "rmse": float(rmse),
        "mean": float(mean),
        "median": float(np.median(x) if np.isnan(mean) else ranks.median(x)),
        "std": float(std),
        "min": float(np.min(x)),
        "max": float(np.max(x)),
    }


def drift_rate(trans_m: np.ndarray, length: float) -> float | None:
    """The mean translation error of segments of ``length`` metres as a percentage of the length;
    None without a segment."""
    return float(np.mean(trans_m / length) * 100) if len(trans_m) else None


# ----------------------------------------------------------------------------- pair selection
def segment_pairs(d: np.ndarray, length: float, tol: float = 0.5, *, starts=None):
    """ov_eval's distance-segment pairs: end = pose whose path distance is closest to start + L,
    within tol. ``starts``: run_starts(d), made once for several lengths."""
    return closest_pairs(d, length, tol, strict=True, skip=0, starts=starts)


def time_pairs(t: np.ndarray, delta: float = 1.0, rel_tol: float = 0.1):
    """Pairs on the reference stamps: partner nearest t + delta, within ±rel_tol·delta."""
    return closest_pairs(t - t[0], delta, rel_tol * delta, strict=False, skip=1)


def consecutive_pairs(d: np.ndarray, delta: float):
    """evo's consecutive mode: a new pair starts where the accumulated amount since the last reaches delta."""
    ids = [0]
    n = len(d)
    while True:
        k = int(np.searchsorted(d, d[ids[-1]] + delta, side="left"))
        k = max(k, ids[-1] + 1)
        if k >= n:
            break
        ids.append(k)
    starts = np.asarray(ids)
    return starts[:-1], starts[1:]


def evo_pairs(
    traj: Trajectory, delta: float, unit: str, *, all_pairs: bool = False, rel_tol: float = 0.1
):
    """Pairs as evo's id_pairs_from_delta chooses them (frames, metres, degrees, radians) plus seconds
    in the same manner. Consecutive: a pair ends where the amount accumulated since its start
    (frames, path, summed rotation angle) reaches delta. All pairs: per start, the partner closest to
    delta within ±rel_tol·delta (frames: exactly delta; angles: every partner whose direct rotation
    angle is within the tolerance, as evo's filter_pairs_by_angle)."""
    n = len(traj)
    if unit == "frames":
        delta = int(delta)
        if delta < 1:
            raise EpaError("rpe delta in frames must be a positive integer")
        if all_pairs:
            i = np.arange(max(n - delta, 0))
            return i, i + delta
        ids = np.arange(0, n, delta)
        return ids[:-1], ids[1:]
    if unit in ("deg", "rad"):
        bound = 180.0 if unit == "deg" else np.pi
        if not 0 <= delta <= bound:
            raise EpaError(f"rpe delta angle must be within [0, {bound:g}] {unit}")
        rad = np.radians(delta) if unit == "deg" else delta
        if all_pairs:
            return _pairs_at_angle(traj.q, rad, rad * rel_tol)
        steps = geometry.quat_angle(geometry.quat_mul(geometry.quat_conj(traj.q[:-1]), traj.q[1:]))
        return consecutive_pairs(np.concatenate([[0.0], np.cumsum(steps)]), rad)
    if unit == "m":
        d = geometry.path_distances(traj.p)
    elif unit == "s":
        d = traj.t - traj.t[0]
    else:
        raise EpaError(f"unknown rpe unit {unit!r}; choose one of {', '.join(RPE_UNITS)}")
    if all_pairs:
        return closest_pairs(d, delta, delta * rel_tol, strict=False, skip=1)
    return consecutive_pairs(d, delta)


def _pairs_at_angle(q: np.ndarray, angle: float, tol: float, block: int = 256):
    """Every pair i < j whose relative rotation angle is within angle ± tol (O(N²), in blocks of starts)."""
    n = len(q)
    found_i, found_j = [], []
    for start in range(0, max(n - 1, 0), block):
        i = np.arange(start, min(start + block, n - 1))
        rel = geometry.quat_angle(
            geometry.quat_mul(geometry.quat_conj(q[i])[:, None, :], q[None, :, :])
        )
        hit = (np.abs(rel - angle) <= tol) & (np.arange(n)[None, :] > i[:, None])
        a, b = np.nonzero(hit)
        found_i.append(i[a])
        found_j.append(b)
    if not found_i:
        return np.zeros(0, int), np.zeros(0, int)
    return np.concatenate(found_i), np.concatenate(found_j)


# ----------------------------------------------------------------------------- errors
def segment_lengths(spec, path_length_m: float) -> list[float]:
    """The distance-RPE segment lengths (m) of ``metrics.segments`` for a reference path of
    ``path_length_m`` (the whole cropped reference's, as rpg takes its groundtruth's): a list as
    given; ``auto``, rpg_trajectory_evaluation's 10-50 % of it (truncated to 2 decimals, as rpg
    does); ``kitti``, the devkit's 100-800 m.

    Parameters
    ----------
    spec : list of float or {"auto", "kitti"}
    path_length_m : float

    Returns
    -------
    list of float
    """
    if spec == "auto":
        from epa.metrics import rpg

        return [float(d) for d in rpg.boxplot_distances(path_length_m)]
    if spec == "kitti":
        from epa.metrics import kitti

        return list(kitti.LENGTHS_M)
    return [float(length) for length in spec]


def recorded_lengths(record: dict) -> list[float]:
    """The segment lengths (m) a metrics record was computed with, in order."""
    return [float(key) for key in record["rpe_distance"]]


def segment_key(length) -> str:
    """The one spelling of a segment length in keys, columns and labels: 8, 16, 0.5."""
    return f"{float(length):g}"


def ape(
    ref: Trajectory,
    est: Trajectory,
    d: np.ndarray | None = None,
    *,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pose translation error (m) and rotation error (deg) of aligned, matched poses; the
    rotation's from ``d`` (D = Q P^T), or from the first four of geometry.pair_rows' ``rows``."""
    trans = geometry.norms(est.p - ref.p)
    if rows is not None:
        return trans, np.degrees(geometry.rows_angle(*rows[:4]))
    d = geometry.pose_discrepancy(ref.q, est.q) if d is None else d
    return trans, np.degrees(geometry.quat_angle(d))


def evaluate(
    ref: Trajectory,
    est: Trajectory,
    *,
    segments=(8, 16, 24, 32, 40, 48),
    segment_tol: float = 0.5,
    time_delta: float = 1.0,
    time_tol: float = 0.1,
    rpe=(),
    discrepancy: np.ndarray | None = None,
    dist: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> tuple[AccuracyRecord, dict]:
    """All metrics of one case. Returns (summary dict for metrics.json, per-pose/per-pair tables).
    ``discrepancy``: D = Q P^T of every matched pose when not the poses' own (position-only: I).
    ``dist``: the reference's path distances (geometry.path_distances), when the caller has them;
    ``rows``: geometry.pair_rows of the poses (their own D), when the caller has them."""
    if len(ref) != len(est):
        raise EpaError("reference and estimate must be matched pose for pose")
    # once, shared by every metric below: D = Q P^T and the positions, as rows (geometry.pair_rows)
    if rows is None:
        rows = geometry.pair_rows(discrepancy, ref.p, est.p, q=(ref.q, est.q))
    trans, rot = ape(ref, est, rows=rows)
    dist = geometry.path_distances(ref.p) if dist is None else dist
    summary: dict[str, Any] = {
        "n_matched": len(ref),
        "ref_length_m": float(dist[-1]) if len(dist) else 0.0,
        "duration_s": float(ref.t[-1] - ref.t[0]),
        "ate": {"trans_m": stats(trans), "rot_deg": stats(rot)},
    }
    tables = {
        "ape": {
            "t": ref.t,
            "dist_m": dist,
            "trans_m": trans,
            "rot_deg": rot,
        }
    }

    summary["rpe_distance"], summary["drift_rate_pct"], tables["rpe_segments"] = segment_rpe(
        dist, rows, segments, segment_tol
    )

    i, j = time_pairs(ref.t, time_delta, time_tol)
    er, et = geometry.pair_errors(rows, i, j)
    summary[time_rpe_key(time_delta)] = {
        "delta_s": time_delta,
        "trans_m": stats(et),
        "rot_deg": stats(er),
    }
    tables["rpe_time"] = {"i": i, "j": j, "t": ref.t[i], "rot_deg": er, "trans_m": et}

    summary["rpe"] = []
    for spec in rpe:
        pairs_from = ref if spec.get("pairs_from", "est") == "ref" else est
        i, j = evo_pairs(
            pairs_from,
            spec["delta"],
            spec["unit"],
            all_pairs=spec.get("all_pairs", False),
            rel_tol=spec.get("rel_tol", 0.1),
        )
        er, et = geometry.pair_errors(rows, i, j)
        summary["rpe"].append({**spec, "trans_m": stats(et), "rot_deg": stats(er)})
    # built as a plain dict: the time RPE's key follows time_delta, which a TypedDict cannot name
    return cast(AccuracyRecord, summary), tables


def segment_rpe(
    dist: np.ndarray, rows: np.ndarray, segments, tol: float
) -> tuple[dict, dict, dict]:
    """The distance RPE and drift rate of each segment length, and their pairs' table (evaluate's
    ``rpe_segments``). Every length's pairs form one set, whose errors are computed in one pass
    straight into the table's columns; each length's statistics are those of its stretch.
    ``rows``: geometry.pair_rows of the matched poses."""
    lengths = [float(length) for length in segments]
    starts = run_starts(dist)
    i, j, sizes = _joined_pairs(dist, lengths, tol, starts)
    er, et = geometry.pair_errors(rows, i, j)
    rpe, drift = {}, {}
    for length, end, size in zip(lengths, np.cumsum(sizes, dtype=int), sizes):
        key, one = segment_key(length), slice(end - size, end)
        rpe[key] = {"trans_m": stats(et[one]), "rot_deg": stats(er[one])}
        drift[key] = drift_rate(et[one], length)
    table = {
        "length_m": _repeat(lengths, sizes),
        "i": i,
        "j": j,
        "rot_deg": er,
        "trans_m": et,
    }
    return rpe, drift, table


def _joined_pairs(dist: np.ndarray, lengths: list[float], tol: float, starts: np.ndarray):
    """Every length's segment pairs, joined (i, j), and each length's count: each block of pairs
    copied once as it is made, into arrays of room for every start of every length (the room
    never written is never touched)."""
    if not lengths:
        return np.zeros(0), np.zeros(0), []
    room = len(lengths) * len(dist)
    i, j = np.empty(room, np.intp), np.empty(room, np.intp)
    sizes, end = [], 0
    for length in lengths:
        begin = end
        for a, b in closest_pair_blocks(dist, length, tol, strict=True, skip=0, starts=starts):
            i[end : end + len(a)], j[end : end + len(a)] = a, b
            end += len(a)
        sizes.append(end - begin)
    return i[:end], j[:end], sizes


def _repeat(values: list[float], sizes: list[int]) -> np.ndarray:
    """np.repeat(values, sizes) as floats, each stretch filled (as fast as repeat in warm memory,
    8x faster on fresh pages at 6M values: 15 against 118 ms)."""
    out = np.empty(sum(sizes))
    for value, end, size in zip(values, np.cumsum(sizes, dtype=int), sizes):
        out[end - size : end] = value
    return out


# ----------------------------------------------------------------------------- position-only estimates
def position_only_note(which: str) -> str:
    """Why a case's rotation errors are null; ``which``: :func:`epa.core.trajectory.position_only`."""
    return (
        f"{which}: every rotation error is null (no orientation was read and none is derived from"
        " positions); the RPE's translation error is the world-frame displacement error"
    )


def evaluate_positions(
    ref: Trajectory, est: Trajectory, *, rpe=(), **settings
) -> tuple[dict, dict]:
    """:func:`evaluate` for a position-only estimate: the translation errors with D = I (a relative
    translation compared in the aligned world frame, |(p_j - p_i) - (q_j - q_i)|: the estimate's
    orientation at pose i is unknown), every rotation statistic empty (``n`` 0, None) and every
    per-pose and per-pair rotation error NaN (not a number: no orientation). An RPE whose pairs are
    chosen by the estimate's rotation angle cannot be formed: an error."""
    for spec in rpe:
        side = "reference" if spec.get("pairs_from", "est") == "ref" else "estimate"
        if spec["unit"] in ("deg", "rad") and (ref if side == "reference" else est).position_only:
            raise EpaError(
                f"rpe delta {spec['delta']:g} {spec['unit']}: its pairs are chosen by the {side}'s"
                f" rotation angle, and the {side} is position-only (no orientation); use frames, m or s"
                + (" or pairs_from: ref" if side == "estimate" and not ref.position_only else "")
            )
    identity = np.zeros((len(ref), 4))
    identity[:, 3] = 1.0
    summary, tables = evaluate(ref, est, rpe=rpe, discrepancy=identity, **settings)
    for table in tables.values():
        if "rot_deg" in table:
            table["rot_deg"] = np.full(len(table["rot_deg"]), np.nan)
    return null_rotation(summary), tables


def null_rotation(record):
    """``record`` with every ``rot_deg`` statistics emptied (``n`` 0, each statistic None)."""
    if isinstance(record, list):
        return [null_rotation(v) for v in record]
    if not isinstance(record, dict):
        return record
    return {
        k: stats(np.zeros(0)) if k == "rot_deg" else null_rotation(v) for k, v in record.items()
    }
