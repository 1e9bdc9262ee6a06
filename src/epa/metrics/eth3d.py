"""The ETH3D SLAM benchmark's score, as its evaluation program (``ETH3DSLAMEvaluation``,
github.com/ETH3D/slam-evaluation ``src/main.cc``) computes it; see docs/protocols.md.

- The image stamps: the reference's own stamps (``metrics.eth3d.image_stamps: null``) or those of a
  file of image stamps (a ``rgb.txt``-like list, the stamp first on each line).
- The reference at each image stamp: linear positions and slerp between the two reference poses
  around it; an image stamp outside the reference, or whose two poses are more than
  ``max_interpolation_timespan`` (1/75 s) apart, is dropped.
- The estimate at each remaining image stamp, interpolated alike with no gap limit, and held at its
  first or last pose outside its own span: missing output is penalised, never dropped.
- An Umeyama fit of those estimate positions onto the reference's, SE3 and Sim3 (``sim3: true``:
  Sim3 only, the program's ``--sim3``), and the ATE RMSE in cm.
- Relative errors at 0.5, 1.0, 1.5 and 2.0 m of reference path (the cumulative distance between
  consecutive image poses): the program's monotone search for the pose nearest that distance, a
  pair kept where its distance is within 0.025 m; the mean translation error in % of the distance
  and the mean rotation angle in deg/m, of the aligned estimate.

The arithmetic is the program's (Eigen's): its slerp, its rotation of a vector by a quaternion and
its quaternion of the fitted matrix, which under Sim3 is the quaternion of ``s R`` (not a unit one:
the relative translations of the Sim3-aligned estimate are turned by a distorted rotation, a
quirk of the program kept here and documented), and it turns positions by the quaternions as the
files print them, not normalised: the metric takes them from the files read again
(:func:`as_printed`; epica's unit ones, with a note, for a bag). Sums are sequential, as the
program's loops.
Everything is vectorised: the program's pair search is a running maximum (:func:`pairs`).
"""

from __future__ import annotations

import math

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics.spec import Table, protocol
from epa.steps import align as alignment

DISTANCES_M = (0.5, 1.0, 1.5, 2.0)
DISTANCE_TOLERANCE_M = 0.025
MAX_INTERPOLATION_TIMESPAN_S = 1 / 75.0
FEW_PAIRS = 50  # the program warns below this many pairs at a distance
MODES = ("SE3", "SIM3")
EPS = np.finfo(float).eps


# ----------------------------------------------------------------------------- Eigen's arithmetic
def _slerp(q0: np.ndarray, q1: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Eigen's ``q0.slerp(f, q1)`` row by row: the shorter arc, linear weights where the two are
    within machine epsilon, no normalisation."""
    d = np.sum(q0 * q1, axis=-1)
    abs_d = np.abs(d)
    near = abs_d >= 1.0 - EPS
    theta = np.arccos(np.where(near, 0.0, abs_d))
    sin_theta = np.where(near, 1.0, np.sin(theta))
    w0 = np.where(near, 1.0 - f, np.sin((1.0 - f) * theta) / sin_theta)
    w1 = np.where(near, f, np.sin(f * theta) / sin_theta)
    w1 = np.where(d < 0, -w1, w1)
    return w0[:, None] * q0 + w1[:, None] * q1


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions, not assumed unit."""
    av, aw = a[..., :3], a[..., 3:]
    bv, bw = b[..., :3], b[..., 3:]
    return np.concatenate(
        [
            aw * bv + bw * av + geometry.cross(av, bv),
            aw * bw - np.sum(av * bv, axis=-1, keepdims=True),
        ],
        axis=-1,
    )


def _inverse(q: np.ndarray) -> np.ndarray:
    """Eigen's ``inverse()``: the conjugate over the squared norm."""
    return q * np.array([-1.0, -1.0, -1.0, 1.0]) / np.sum(q * q, axis=-1, keepdims=True)


def _turn(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Eigen's ``q * v`` (``_transformVector``), which assumes a unit ``q`` and is used on any."""
    u, w = q[..., :3], q[..., 3:]
    uv = geometry.cross(u, v)
    uv = uv + uv
    return v + w * uv + geometry.cross(u, uv)


def _matrix_quaternion(m: np.ndarray) -> np.ndarray:
    """Eigen's ``Quaterniond(m)`` of a 3x3 matrix (Shoemake's), also of a scaled rotation."""
    trace = np.trace(m)
    if trace > 0:
        t = math.sqrt(trace + 1.0)
        h = 0.5 / t
        return np.array(
            [(m[2, 1] - m[1, 2]) * h, (m[0, 2] - m[2, 0]) * h, (m[1, 0] - m[0, 1]) * h, 0.5 * t]
        )
    i = 0
    if m[1, 1] > m[0, 0]:
        i = 1
    if m[2, 2] > m[i, i]:
        i = 2
    j, k = (i + 1) % 3, (i + 2) % 3
    t = math.sqrt(m[i, i] - m[j, j] - m[k, k] + 1.0)
    q = np.zeros(4)
    q[i] = 0.5 * t
    h = 0.5 / t
    q[3] = (m[k, j] - m[j, k]) * h
    q[j] = (m[j, i] + m[i, j]) * h
    q[k] = (m[k, i] + m[i, k]) * h
    return q


def _sequential_sum(x: np.ndarray) -> float:
    """The sum in index order, as the program's loop adds (``np.sum`` adds pairwise)."""
    return float(np.cumsum(x)[-1]) if len(x) else 0.0


# ----------------------------------------------------------------------------- the protocol
def poses_at(
    t: np.ndarray, p: np.ndarray, q: np.ndarray, stamps: np.ndarray, max_gap: float | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The poses of a trajectory at sorted stamps, as the program's ``ComputePosesAtTimestamps``.

    Parameters
    ----------
    t, p, q : ndarray
        The trajectory, sorted by stamp.
    stamps : ndarray
        Sorted stamps (s).
    max_gap : float or None
        The reference's rule: a stamp before the first pose, at or after the last one, or between
        two poses more than ``max_gap`` s apart is dropped. None (the estimate's rule): such a stamp
        takes the first or last pose, and any gap is interpolated.

    Returns
    -------
    keep : ndarray of bool
        The stamps kept (all of them without ``max_gap``).
    p, q : ndarray
        The poses at the kept stamps.
    """
    k = np.searchsorted(t, stamps, side="right")  # the first pose strictly after the stamp
    inside = (k > 0) & (k < len(t))
    lo, hi = np.clip(k - 1, 0, len(t) - 1), np.clip(k, 0, len(t) - 1)
    span = t[hi] - t[lo]
    with np.errstate(divide="ignore", invalid="ignore"):  # outside: a held pose, no fraction
        f = np.clip(np.where(inside, (stamps - t[lo]) / span, 0.0), 0.0, 1.0)
    p_at = (1.0 - f)[:, None] * p[lo] + f[:, None] * p[hi]
    q_at = _slerp(q[lo], q[hi], f)
    if max_gap is not None:
        keep = inside & ~(span > max_gap)
        return keep, p_at[keep], q_at[keep]
    held = ~inside  # before the first pose: lo = hi = 0; at or after the last: lo = hi = N - 1
    p_at[held], q_at[held] = p[hi[held]], q[hi[held]]
    return np.ones(len(stamps), bool), p_at, q_at


def path_from_start(p: np.ndarray) -> np.ndarray:
    """The cumulative distance of the image poses from the first, summed in order."""
    step = np.diff(p, axis=0)
    norms = np.sqrt(step[:, 0] * step[:, 0] + step[:, 1] * step[:, 1] + step[:, 2] * step[:, 2])
    return np.concatenate([[0.0], np.cumsum(norms)])


def _settle(index: np.ndarray, holds, lo: np.ndarray, hi: int) -> np.ndarray:
    """The first index in [lo, hi] where ``holds`` is true, from a guess off by rounding only
    (``holds`` is monotone): stepped back while the one before holds, on while it does not."""
    index = np.clip(index, lo, hi)
    for _ in range(64):  # rounding moves a guess by a pose or two
        back = (index > lo) & holds(np.maximum(index - 1, lo))
        on = ~back & (index < hi) & ~holds(index)
        if not (back.any() or on.any()):
            return index
        index = index - back + on
    raise AssertionError("eth3d: a pair search did not settle")  # monotone tests settle at once


def _jumps(d: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each second pose s the walk stands on: the first pose at which it steps on from s
    (n: never), and where that walk stops."""
    n = len(d)
    s = np.arange(n - 1)
    stall = d[1:] == d[:-1]  # equally far from any target: never left
    leave = np.searchsorted(target, 0.5 * (d[:-1] + d[1:]), side="right")  # target past midway

    def steps(i):
        i = np.minimum(i, n - 1)
        return np.abs(target[i] - d[s + 1]) < np.abs(target[i] - d[s])

    leave = np.where(stall, n, _settle(np.where(stall, n, leave), steps, np.zeros(n - 1, int), n))
    i = np.minimum(leave, n - 1)
    ref = np.abs(target[i] - d[s])  # the walk's reference distance: from where it started

    def stops(m):
        return ~(np.abs(target[i] - d[np.minimum(m, n - 1)]) < ref) | (m >= n)

    stop = _settle(np.searchsorted(d, target[i] + ref, side="left"), stops, s + 1, n)
    return np.append(leave, n), np.append(stop - 1, n - 1)


def pairs(d: np.ndarray, distance: float, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The program's pose pairs about ``distance`` m apart along the path ``d``.

    The program walks one second pose forward over the first poses in order: from where it stands,
    it steps on while the next pose is strictly nearer the target ``d[first] + distance`` than the
    pose it *started from* (that reference distance is not updated as it steps, so a walk that
    starts short of the target runs past it by as much); stepping onto the last pose ends the
    search; a zero-length step where it stands holds it for good. A pair is kept when its poses
    differ and its distance is within ``tol`` of ``distance``.

    Vectorised: once the walk has stopped at s, its next step depends on s alone (the first pose
    whose target is nearer the pose after s, :func:`_jumps`), so the stops form a chain in a
    functional graph, followed from 0 by pointer doubling (n log n).

    Parameters
    ----------
    d : ndarray
        Cumulative path distance (m) of the image poses, from 0, non-decreasing.
    distance, tol : float
        The evaluation distance and its tolerance (m).

    Returns
    -------
    first, second : ndarray of int
    """
    n = len(d)
    if n < 2:
        return np.zeros(0, int), np.zeros(0, int)
    leave, stop = _jumps(d, d + distance)
    after = np.where(leave < n, np.minimum(stop, n - 1), np.arange(n))  # n - 1: the search ended
    visited = np.zeros(n, bool)
    visited[0] = True
    jump = after
    for _ in range(int(n).bit_length()):  # after k rounds: the first 2^k stops
        visited[jump[visited]] = True
        jump = jump[jump]
    chain = np.flatnonzero(visited)
    ended = chain[-1] == n - 1
    stands = chain[:-1] if ended else chain
    first = np.arange(leave[stands[-1]] if ended else n)
    second = stands[np.searchsorted(leave[stands], first, side="right")]
    keep = (first != second) & ~(np.abs((d[second] - d[first]) - distance) > tol)
    return first[keep], second[keep]


def motions(p: np.ndarray, q: np.ndarray, i: np.ndarray, j: np.ndarray):
    """The program's ``T_j^-1 T_i`` of each pair: (quaternions, translations), its arithmetic."""
    inv = _inverse(q[j])
    return _product(inv, q[i]), _turn(inv, p[i]) + -_turn(inv, p[j])


def reference_pairs(g_p: np.ndarray, g_q: np.ndarray, d: np.ndarray) -> list[dict]:
    """Per distance, the pairs and the reference's relative motions (the same for both modes)."""
    out = []
    for distance in DISTANCES_M:  # four distances
        i, j = pairs(d, distance, DISTANCE_TOLERANCE_M)
        rot, trans = motions(g_p, g_q, i, j)
        out.append(
            {
                "distance": distance,
                "i": i,
                "j": j,
                "rot": rot,
                "trans": trans,
                "length": d[j] - d[i],
            }
        )
    return out


def relative(ref: dict, a_p: np.ndarray, a_q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation (% of the distance) and rotation (deg/m) errors of one distance's pairs
    (``ref``: :func:`reference_pairs`'), of the aligned estimate at the image stamps."""
    a_rot, a_trans = motions(a_p, a_q, ref["i"], ref["j"])
    step = ref["trans"] - a_trans
    trans = np.sqrt(step[:, 0] * step[:, 0] + step[:, 1] * step[:, 1] + step[:, 2] * step[:, 2])
    err = _product(_inverse(ref["rot"]), a_rot)
    angle = 2.0 * np.arctan2(np.linalg.norm(err[:, :3], axis=1), np.abs(err[:, 3]))
    return 100.0 * trans / ref["length"], (180.0 / np.pi) * angle / ref["length"]


def score(g_p, e_p, e_q, refs: list[dict], mode: str) -> tuple[dict, dict]:
    """One mode's numbers (``SE3`` or ``SIM3``): the fit, the ATE RMSE (cm) and the mean relative
    errors at each distance (None with no pair), and the per-pair errors."""
    fit = alignment.umeyama(e_p, g_p, with_scale=mode == "SIM3")
    m = fit.s * fit.R  # the program's transform block: s R, and its (not unit) quaternion
    a_p = e_p @ m.T + fit.t
    a_q = _product(_matrix_quaternion(m), e_q)
    sq = np.sum((g_p - a_p) ** 2, axis=1)
    per_distance: list[dict] = []
    record = {
        "mode": mode,
        "scale": fit.s,
        "ate_rmse_cm": 100.0 * math.sqrt(_sequential_sum(sq) / len(sq)),
        "relative": per_distance,
    }
    errors: dict[str, list] = {
        k: [] for k in ("sim3", "distance_m", "image", "translation_pct", "rotation_deg_per_m")
    }
    for ref in refs:
        trans, rot = relative(ref, a_p, a_q)
        n = len(trans)
        per_distance.append(
            {
                "distance_m": ref["distance"],
                "n_pairs": n,
                "translation_pct": _sequential_sum(trans) / n if n else None,
                "rotation_deg_per_m": _sequential_sum(rot) / n if n else None,
            }
        )
        for key, values in zip(
            errors,
            (np.full(n, int(mode == "SIM3")), np.full(n, ref["distance"]), ref["i"], trans, rot),
        ):
            errors[key].append(values)
    return record, errors


def evaluate(
    reference: Trajectory,
    estimate: Trajectory,
    stamps: np.ndarray,
    *,
    sim3: bool = False,
    max_interpolation_timespan: float = MAX_INTERPOLATION_TIMESPAN_S,
) -> tuple[dict, dict]:
    """The program's evaluation of one estimate.

    Parameters
    ----------
    reference, estimate : Trajectory
        Whole trajectories, sorted by stamp.
    stamps : ndarray
        The image stamps (s), sorted.
    sim3 : bool
        The program's ``--sim3``: Sim3 only; otherwise SE3, then Sim3.
    max_interpolation_timespan : float
        The reference's largest gap (s) an image stamp is interpolated across.

    Returns
    -------
    record : dict
        ``available`` False with a ``reason`` where the program prints no numbers.
    errors : dict
        Per pair: mode, distance, image index (of the first pose) and the two errors.
    """
    if len(stamps) == 0:
        raise EpaError("eth3d: no image stamps")
    if np.any(np.diff(stamps) < 0):
        raise EpaError("eth3d: the image stamps are not sorted")
    keep, g_p, g_q = poses_at(
        reference.t, reference.p, reference.q, stamps, max_interpolation_timespan
    )
    kept = stamps[keep]
    base = {
        "n_image_stamps": len(stamps),
        "n_images": len(kept),
        "max_interpolation_timespan_s": max_interpolation_timespan,
    }
    if len(kept) < 2:
        step = float(np.median(np.diff(reference.t)))
        raise EpaError(
            f"eth3d: {len(kept)} of {len(stamps)} image stamps lie between two reference poses at"
            f" most {max_interpolation_timespan:g} s apart (metrics.eth3d.max_interpolation_timespan;"
            f" the reference's median step is {step:g} s): at least 2 are needed"
        )
    if kept[0] >= estimate.t[-1]:  # the program interpolates none and prints nothing
        why = "the estimate ends at or before the first image stamp: the program prints no numbers"
        return {"available": False, "reason": why, **base}, {}
    _, e_p, e_q = poses_at(estimate.t, estimate.p, estimate.q, kept, None)
    if not np.any(np.ptp(e_p, axis=0) > 0):  # one point: no fit (the program would print nan)
        why = (
            "the estimate stands at one position at every image stamp (it starts after the last"
            " one, or does not move): no alignment"
        )
        return {"available": False, "reason": why, **base}, {}
    held = (kept < estimate.t[0]) | (kept > estimate.t[-1])
    d = path_from_start(g_p)
    refs = reference_pairs(g_p, g_q, d)
    modes: list[dict] = []
    tables: dict = {}
    for mode in MODES[1:] if sim3 else MODES:
        record, errors = score(g_p, e_p, e_q, refs, mode)
        modes.append(record)
        for key, parts in errors.items():
            tables.setdefault(key, []).extend(parts)
    record = {
        "available": True,
        **base,
        "n_held": int(np.sum(held)),  # image stamps outside the estimate: its end poses, penalised
        "path_length_m": float(d[-1]),
        "modes": modes,
        "warning": None,
    }
    return record, {k: np.concatenate(v) for k, v in tables.items()}


def printed(record: dict) -> str:
    """The program's standard output for a record: its lines, its ``%.14g`` numbers (C++'s
    ``setprecision(14)``), the distance in its label at 2 significant digits, a warning where a
    distance has fewer than 50 pairs, a blank line after each mode; a distance without pairs is not
    printed. Where the program prints no numbers, its two warnings (the last without a line end, as
    it prints it)."""
    if not record["available"] and "no alignment" in record["reason"]:
        return ""  # the program's numbers would be nan: none printed
    if not record["available"]:
        return (
            "WARNING: Failed to interpolate any pose, maybe the timestamps are incorrect?\n"
            "WARNING: Failed to interpolate the estimated poses. Not outputting any evaluation results."
        )
    lines = []
    for mode in record["modes"]:
        lines.append(f"{mode['mode']}_ATE_RMSE[cm]: {mode['ate_rmse_cm']:.14g}")
        for rel in mode["relative"]:
            n, label = rel["n_pairs"], f"{rel['distance_m']:.2g}"
            if n == 0:
                continue
            if n < FEW_PAIRS:
                lines.append(
                    "WARNING: Found less than 50 subsequences to evaluate relative errors for"
                    f" evaluation_distance {rel['distance_m']:g}. The results may be too noisy."
                )
            lines.append(
                f"{mode['mode']}_REL_TRANSLATION_{label}M[%]: {rel['translation_pct']:.14g}"
            )
            lines.append(
                f"{mode['mode']}_REL_ROTATION_{label}M[deg/m]: {rel['rotation_deg_per_m']:.14g}"
            )
        lines.append("")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- the metric


def as_printed(cropped: Trajectory, printed: Trajectory | None) -> Trajectory | None:
    """``cropped`` with the quaternions its file prints (``printed``: the same file read again with
    the same settings, quaternions not normalised), matched by stamp and position; None where there
    is none (a bag, KITTI, positions only) or a pose has no twin (repeated stamps kept)."""
    if printed is None:
        return None
    k = np.minimum(np.searchsorted(printed.t, cropped.t), len(printed) - 1)
    if not (np.array_equal(printed.t[k], cropped.t) and np.array_equal(printed.p[k], cropped.p)):
        return None
    return Trajectory(cropped.t, cropped.p, printed.q[k])


def _printed_sides(
    reference: Trajectory, estimate: Trajectory, printed: tuple
) -> tuple[Trajectory, Trajectory, list[str]]:
    """Both sides with their quaternions as printed where their files print them (the program's
    input), else epica's unit ones, with a note saying so."""
    out, notes = [], []
    for side, cropped, raw in zip(("reference", "estimate"), (reference, estimate), printed):
        matched = as_printed(cropped, raw)
        out.append(cropped if matched is None else matched)
        if matched is None:
            notes.append(
                f"eth3d: the {side}'s quaternions are epica's normalised ones (its source prints no"
                " quaternions as a text trajectory, e.g. a bag); the program turns positions by the"
                " quaternions a file prints: relative translation errors may differ from its in the"
                " 5th digit"
            )
    return out[0], out[1], notes


def compute(
    ref: Trajectory,
    est: Trajectory,
    cfg: dict,
    *,
    reference: Trajectory,
    estimate: Trajectory,
    image_stamps: np.ndarray | None,
    printed_quaternions: tuple = (None, None),
) -> tuple[dict, dict, list[str]]:
    """The ETH3D score of one case, on the whole cropped trajectories (its own association and
    alignment, not epica's matched and aligned poses).

    Parameters
    ----------
    ref, est : Trajectory
        epica's matched poses (unused: the protocol matches at the image stamps).
    reference, estimate : Trajectory
        The whole cropped reference and estimate.
    image_stamps : ndarray or None
        The image stamps read from ``metrics.eth3d.image_stamps``; None: the reference's stamps.
    printed_quaternions : (Trajectory or None, Trajectory or None)
        The reference's and the estimate's files read again, their quaternions as printed (the
        program computes on them); None for a side that prints none.

    Returns
    -------
    (record, arrays, notes)
    """
    c = cfg["metrics"]["eth3d"]
    reference, estimate, printed_notes = _printed_sides(reference, estimate, printed_quaternions)
    stamps = reference.t if image_stamps is None else image_stamps
    record, errors = evaluate(
        reference,
        estimate,
        stamps,
        sim3=c["sim3"],
        max_interpolation_timespan=c["max_interpolation_timespan"],
    )
    record = {"image_stamps": c["image_stamps"] or "reference", **record}
    if not record["available"]:
        return record, {}, printed_notes + [f"eth3d: {record['reason']}"]
    notes = printed_notes
    if record["n_held"]:
        notes.append(
            f"eth3d: {record['n_held']} of {record['n_images']} image stamps lie outside the"
            " estimate: it is held at its first or last pose there (the benchmark's penalty for"
            " missing output)"
        )
    for rel in record["modes"][0]["relative"]:
        if rel["n_pairs"] < FEW_PAIRS:
            notes.append(
                f"eth3d: {rel['n_pairs']} pose pairs {rel['distance_m']:g} m apart (the program"
                f" warns below {FEW_PAIRS})"
                + (": no relative error at that distance" if not rel["n_pairs"] else "")
            )
    return record, {"eth3d_relative_errors": errors}, notes


def _mode(record: dict, mode: str) -> dict | None:
    return next((m for m in record.get("modes", ()) if m["mode"] == mode), None)


def summary(record: dict) -> dict:
    """summary.csv's eth3d_* columns (only with metrics.eth3d on): each mode's ATE RMSE (cm) and
    its mean relative translation error at 1 m (%), empty where not computed."""
    out = {}
    for mode in MODES:
        m = _mode(record, mode)
        rel = next((r for r in m["relative"] if r["distance_m"] == 1.0), None) if m else None
        out[f"eth3d_{mode.lower()}_ate_rmse_cm"] = m["ate_rmse_cm"] if m else None
        out[f"eth3d_{mode.lower()}_rel_trans_1m_pct"] = rel["translation_pct"] if rel else None
    return out


def per_run(record: dict) -> tuple[float]:
    """One run's ATE RMSE (cm) of the first mode the program prints: SE3, or Sim3 with sim3."""
    return (record["modes"][0]["ate_rmse_cm"],)


def documents(record: dict) -> dict[str, str]:
    """``06_metrics/eth3d/eth3d.txt``: what the program prints for the case."""
    return {"eth3d.txt": printed(record)}


METRIC = protocol(
    "eth3d",  # metrics.eth3d: off by default; epa eval --protocol eth3d
    summary=summary,
    compute=compute,
    inputs=("reference", "estimate", "image_stamps", "printed_quaternions"),
    arrays=("eth3d_relative_errors.csv",),
    summary_columns=tuple(
        f"eth3d_{m.lower()}_{q}" for m in MODES for q in ("ate_rmse_cm", "rel_trans_1m_pct")
    ),
    tables=(
        Table(
            "eth3d",
            "ETH3D SLAM LATEX TABLE (ATE RMSE CM AT THE IMAGE STAMPS: SE3, SIM3 WITH SIM3: TRUE;"
            " MEAN OVER RUNS)",
            pair=False,
            per_run=per_run,
            has=lambda r: bool(r.get("available")),
            missing="no ETH3D score",
        ),
    ),
    documents=documents,
)
