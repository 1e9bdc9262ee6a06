"""Local drift/fail detection, success rate and drift-valid metrics (EPA's definitions).

Signals are computed on the final aligned case: the time-RPE pairs (``metrics.time_delta``, 1 s by
default) and the APE translation series. A pose is invalid when a time-RPE pair spanning it has a
translation error above the threshold (or not finite), or when it lies in an APE growth stretch. An
interval between consecutive poses is valid when both ends are valid. A constant bias never
invalidates anything: only growth does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from epa.core import ranks
from epa.metrics.accuracy import drift_rate, segment_key, stats, time_rpe_key


def thresholds(settings: dict, ref_t: np.ndarray, ref_dist: np.ndarray, time_pairs) -> dict:
    """The thresholds in force: the fixed defaults, or derived from the reference's own motion."""
    th = {k: settings[k] for k in THRESHOLD_KEYS}
    th["mode"] = settings["mode"]
    if settings["mode"] == "scale_aware":
        i, j = time_pairs
        step = ranks.median(ref_dist[j] - ref_dist[i]) if len(i) else 0.0
        length = ref_dist[-1] if len(ref_dist) else 0.0
        th["rpe_trans_max_m"] = max(settings["scale_rpe_factor"] * step, 0.1)
        th["jump_rise_m"] = th["jump_hold_m"] = max(settings["scale_jump_factor"] * length, 0.5)
        th["jump_rate_m_s"] = th["jump_rise_m"] / 5.0
    return th


def _span_mask(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Poses covered by any of the index spans [i, j]."""
    marks = np.zeros(n + 1, int)
    np.add.at(marks, i, 1)
    np.add.at(marks, j + 1, -1)
    return np.cumsum(marks[:-1]) > 0


def growth_stretches(
    t: np.ndarray,
    ape: np.ndarray,
    pi: np.ndarray,
    pj: np.ndarray,
    *,
    rise: float,
    rate: float,
    hold: float,
    steps: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[tuple[int, int]]:
    """APE jumps: a 1 s step (pi -> pj) rising more than ``rise`` faster than ``rate`` starts a
    stretch at pi, which lasts while APE stays above the level before the jump plus ``hold``.
    ``steps``: :func:`ape_steps` of the same pairs, made once for several thresholds."""
    d_ape, slope = ape_steps(t, ape, pi, pj) if steps is None else steps
    starts = np.flatnonzero((d_ape > rise) & (slope > rate))
    out: list[tuple[int, int]] = []
    end_prev = -1
    for s in starts:  # few: one per jump, not one per pose
        a = int(pi[s])
        if a <= end_prev:
            continue
        below = np.flatnonzero(ape[pj[s] :] <= ape[a] + hold)
        b = int(pj[s] + below[0] - 1) if len(below) else len(ape) - 1
        out.append((a, b))
        end_prev = b
    return out


def ape_steps(t: np.ndarray, ape: np.ndarray, pi: np.ndarray, pj: np.ndarray):
    """Each pair's APE rise (m) and its rate (m/s), what :func:`growth_stretches` thresholds."""
    d_ape = ape[pj] - ape[pi]
    return d_ape, d_ape / np.maximum(t[pj] - t[pi], 1e-9)


def knee_threshold(ape: np.ndarray, lo: float = 5.0, hi: float = 30.0) -> dict:
    """Knee of the sorted APE curve (largest gap below the chord, tail above p95 trimmed), else p95;
    clamped. Without a finite APE: mode none, raw_m None and the upper bound."""
    finite = ape[np.isfinite(ape)]  # a copy: partitioned in place (np.percentile would copy it)
    if finite.size == 0:
        return {
            "threshold_m": hi,
            "mode": "none",
            "raw_m": None,
            "clamped": True,
            "bounds_m": [lo, hi],
        }
    p95 = float(np.percentile(finite, 95, overwrite_input=True))
    y = finite[finite <= p95]
    raw, mode = p95, "p95"
    knee = _knee(y) if y.size >= 3 else None
    if knee is not None:
        raw, mode = knee, "knee"
    thr = float(np.clip(raw, lo, hi))
    return {
        "threshold_m": thr,
        "mode": mode,
        "raw_m": raw,
        "clamped": thr != raw,
        "bounds_m": [lo, hi],
    }


KNEE_GAP = 0.05  # a curve within 5% of its chord has no knee worth the name
# Bins of the normalised APE in _knee: a power of two, so that yn * KNEE_BINS is exact and bin b
# holds exactly the values with b <= yn * KNEE_BINS < b + 1
KNEE_BINS = 4096


def _knee(y: np.ndarray) -> float | None:
    """The value at the knee of the curve of the values ``y`` sorted (an unsorted sample without
    NaN): at the first largest gap between its chord from (0, 0) to (1, 1) and the curve, the
    values normalised to (y - min) / (max - min) at x = linspace(0, 1, n); None where that gap is
    not above KNEE_GAP (or the values are all equal).

    Without sorting them all (60 of drift's 140 ms at 1,000,000 poses): the values are counted
    into bins of the normalised value, which tells each bin's ranks; a bin's gap is at most its
    last x less its least value, and only the bins that may hold the largest gap are sorted (2-5 %
    of the values). The same gaps are computed, value by value, on the same x: the same knee."""
    y0, y1 = y.min(), y.max()
    if not y1 > y0:
        return None
    span = y1 - y0
    x = np.linspace(0.0, 1.0, y.size)
    if y.size <= 4 * KNEE_BINS:  # small: sorted whole
        s = np.sort(y)
        gap = x - (s - y0) / span
        k = int(np.argmax(gap))
        return float(s[k]) if gap[k] > KNEE_GAP else None
    bins = np.multiply((y - y0) / span, KNEE_BINS)
    bins = np.minimum(bins.astype(np.intp), KNEE_BINS - 1)  # the maximum: the last bin
    counts = np.bincount(bins, minlength=KNEE_BINS)
    ends = np.cumsum(counts)
    starts = ends - counts
    full = counts > 0
    # the rounded differences only grow with x and shrink with the value: a bound of each gap
    bound = np.full(KNEE_BINS, -np.inf)
    bound[full] = x[ends[full] - 1] - np.flatnonzero(full) / KNEE_BINS
    top = int(np.argmax(bound))
    if bound[top] <= KNEE_GAP:
        return None
    # the largest gap in the most promising bin: only bins bounded by no less can hold the largest
    s = np.sort(y[bins == top])
    least = (x[starts[top] : ends[top]] - (s - y0) / span).max()
    keep = (bound >= least) & (bound > KNEE_GAP)
    # each kept bin's values sorted are its ranks' values (the bins are in the values' order)
    s = np.sort(y[keep[bins]])
    kept = np.flatnonzero(keep)
    before = np.cumsum(counts[kept]) - counts[kept]  # where each kept bin starts in s
    rank = np.arange(s.size) + np.repeat(starts[kept] - before, counts[kept])
    gap = x[rank] - (s - y0) / span
    k = int(np.argmax(gap))  # the first largest: rank order
    return float(s[k]) if gap[k] > KNEE_GAP else None


THRESHOLD_KEYS = ("rpe_trans_max_m", "jump_rise_m", "jump_rate_m_s", "jump_hold_m")
# the success-rate curve: every drift threshold multiplied by these factors (log-spaced, 0.1-10)
CURVE_FACTORS = np.logspace(-1, 1, 21)


def _invalid(t, ape_trans, time_i, time_j, time_trans, th: dict, shared: dict | None = None):
    """Invalid poses under thresholds ``th``, and the APE growth stretches. ``shared``: what does
    not depend on the thresholds (:func:`_shared`), made once for the success curve's 21."""
    sh = _shared(t, ape_trans, time_i, time_j, time_trans) if shared is None else shared
    bad_pair = sh["bad_pair"] | (time_trans > th["rpe_trans_max_m"])
    stretches = growth_stretches(
        t,
        ape_trans,
        time_i,
        time_j,
        rise=th["jump_rise_m"],
        rate=th["jump_rate_m_s"],
        hold=th["jump_hold_m"],
        steps=sh["steps"],
    )
    if not stretches and not bad_pair.any():  # (the usual case at all but the lowest thresholds)
        return sh["bad_ape"], stretches
    invalid = _span_mask(len(t), time_i[bad_pair], time_j[bad_pair])
    if stretches:
        invalid |= _span_mask(
            len(t), np.array([a for a, _ in stretches]), np.array([b for _, b in stretches])
        )
    return invalid | sh["bad_ape"], stretches


def _shared(t, ape_trans, time_i, time_j, time_trans) -> dict:
    """The parts of :func:`_invalid` that no threshold changes."""
    return {
        "bad_pair": ~np.isfinite(time_trans),
        "bad_ape": ~np.isfinite(ape_trans),
        "steps": ape_steps(t, ape_trans, time_i, time_j),
    }


def _success_distance(dist, invalid) -> float | None:
    """% of the path length whose intervals are valid (both ends valid); None on a path without
    length (the metrics stage refuses such a reference first)."""
    valid_iv = ~invalid[:-1] & ~invalid[1:]
    total = float(dist[-1] - dist[0])
    return 100.0 * np.diff(dist)[valid_iv].sum() / total if total > 0 else None


def success_curve(t, dist, ape_trans, time_i, time_j, time_trans, th: dict) -> dict:
    """The distance success rate with every drift threshold multiplied by each of CURVE_FACTORS, and
    its area: the mean over the log-spaced factors (%), so a ranking need not hinge on one threshold."""
    shared = _shared(t, ape_trans, time_i, time_j, time_trans)
    rates: list = []
    last = None
    for f in CURVE_FACTORS:
        scaled = {k: f * th[k] for k in THRESHOLD_KEYS}
        invalid = _invalid(t, ape_trans, time_i, time_j, time_trans, scaled, shared)[0]
        # a factor that invalidates nothing beyond a non-finite APE: the rate of the one before
        same = bool(rates) and invalid is shared["bad_ape"] and last is invalid
        rates.append(rates[-1] if same else _success_distance(dist, invalid))
        last = invalid
    known = [r for r in rates if r is not None]
    auc = float(np.mean(known)) if len(known) == len(rates) else None  # None: a path without length
    return {
        "factor": CURVE_FACTORS,
        "rpe_trans_max_m": CURVE_FACTORS * th["rpe_trans_max_m"],
        "success_rate_distance_pct": rates if auc is None else np.array(rates),
        "auc_pct": auc,
    }


def detect(t, dist, ape_trans, ape_rot, time_i, time_j, time_trans, settings: dict) -> dict:
    """Validity of every pose and interval, the fail segments and the success rates."""
    th = thresholds(settings, t, dist, (time_i, time_j))
    invalid, stretches = _invalid(t, ape_trans, time_i, time_j, time_trans, th)
    valid_iv = ~invalid[:-1] & ~invalid[1:]
    seg_dur = np.diff(t)
    total_dur = float(t[-1] - t[0])
    sr_dist = _success_distance(dist, invalid)
    sr_time = 100.0 * seg_dur[valid_iv].sum() / total_dur if total_dur > 0 else None

    # maximal runs of invalid poses
    edges = np.diff(np.concatenate([[0], invalid.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    segments = {
        "index_start": starts,
        "index_end": ends,
        "t_start": t[starts],
        "t_end": t[ends],
        "dist_start_m": dist[starts],
        "dist_end_m": dist[ends],
        "duration_s": t[ends] - t[starts],
        "length_m": dist[ends] - dist[starts],
        "ape_max_m": np.array([ape_trans[a : b + 1].max() for a, b in zip(starts, ends)]),
        "ape_mean_m": np.array([ape_trans[a : b + 1].mean() for a, b in zip(starts, ends)]),
    }
    finite = ape_trans[np.isfinite(ape_trans)]  # a copy: partitioned in place
    p5 = float(np.percentile(finite, 5, overwrite_input=True)) if finite.size else None
    global_failed = p5 is None or p5 > settings["global_fail_p5_m"]
    knee = knee_threshold(ape_trans, settings["knee_min_m"], settings["knee_max_m"])
    return {
        "thresholds": th,
        "invalid": invalid,
        "valid_interval": valid_iv,
        "success_rate_distance_pct": sr_dist,
        "success_rate_time_pct": sr_time,
        "ape_p5_m": p5,
        "global_failed": bool(global_failed),
        "knee": knee,
        "fail_segments": segments,
        "growth_stretches": stretches,
    }


def pair_valid(valid_interval: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """A pair is valid when every interval it spans is valid."""
    if valid_interval.all():
        return np.ones(len(i), bool)
    bad = np.concatenate([[0], np.cumsum(~valid_interval)])
    return (bad[j] - bad[i]) == 0


NO_VALID_INTERVAL = (
    "no drift-valid interval (distance success rate 0 %): every drift-valid metric is empty"
)


def _valid_stats(x: np.ndarray, keep: np.ndarray | None, known) -> dict:
    """stats(x[keep]) (of all of x where ``keep`` is None). ``known``: the metrics stage's
    statistics of x, taken when ``keep`` keeps all of it (every pose or pair valid, the usual
    case): the same sample, so the same numbers, not computed a second time."""
    kept = len(x) if keep is None else int(np.count_nonzero(keep))
    if isinstance(known, dict) and known.get("n") == len(x) == kept:
        return dict(known)
    return stats(x if keep is None else x[keep])


def length_runs(lengths: np.ndarray) -> dict[float, slice] | None:
    """{segment length: its rows} where each length's rows are one run of the column, as the
    metrics stage writes rpe_segments (the drift stage and the tables read them so); None where a
    length comes back after another, or for a column of another type than float64 (a float32 0.1 is
    no float 0.1: its mask compares in the column's type)."""
    lengths = np.asarray(lengths)
    if lengths.dtype != np.float64:
        return None
    if not len(lengths):
        return {}
    edges = [0, *(np.flatnonzero(lengths[1:] != lengths[:-1]) + 1).tolist(), len(lengths)]
    runs = {float(lengths[a]): slice(a, b) for a, b in zip(edges[:-1], edges[1:])}
    return runs if len(runs) == len(edges) - 1 else None


def of_length(seg: dict, valid: np.ndarray | None, runs: dict | None, length: float) -> tuple:
    """One segment length's pairs' translation and rotation errors and their validity (None without
    ``valid``): its run of rows where each length has one (``runs``, :func:`length_runs`: the metrics
    stage writes them so, 6 passes over a run, not over every pair), else by ``seg["length_m"]``'s
    mask. Contiguous either way, as a mask's gather is: the same sums. The drift stage and the
    tables take a length's pairs here."""
    if runs is None:
        of = seg["length_m"] == length
        return seg["trans_m"][of], seg["rot_deg"][of], None if valid is None else valid[of]
    at = runs.get(length, slice(0, 0))
    return (
        np.ascontiguousarray(seg["trans_m"][at]),
        np.ascontiguousarray(seg["rot_deg"][at]),
        None if valid is None else valid[at],
    )


def valid_metrics(
    det: dict,
    ape_trans,
    ape_rot,
    seg: dict,
    tpairs: dict,
    segments,
    *,
    time_delta: float,
    known: dict | None = None,
) -> tuple[dict, np.ndarray, np.ndarray, list[str]]:
    """Drift-valid ATE (poses touching a valid interval) and RPE / drift rate / time RPE over valid pairs
    (the time RPE keyed by ``time_delta``, :func:`epa.metrics.accuracy.time_rpe_key`). ``known``:
    the metrics stage's record of the same errors, whose statistics stand where every sample is valid.

    Returns the metrics, the validity of each segment pair and each time pair (all False when
    the case is globally failed or has no valid path) and a note for each drift-valid quantity left
    without samples, whose statistics are None (no note for a globally failed case: its status
    says why every one is empty)."""
    viv = det["valid_interval"]
    touch = np.zeros(len(ape_trans), bool)
    touch[:-1] |= viv
    touch[1:] |= viv
    k = known or {}
    out: dict[str, Any] = {
        "ate": _stats_pair(ape_trans, ape_rot, touch, k.get("ate")),
        "rpe_distance": {},
        "drift_rate_pct": {},
    }
    sv = (
        pair_valid(viv, _indices(seg["i"]), _indices(seg["j"]))
        if len(seg["i"])
        else np.zeros(0, bool)
    )
    every = bool(sv.all())  # the usual case: each length's valid pairs are all of its pairs
    notes = []
    runs = length_runs(seg["length_m"])
    for length in segments:
        key = segment_key(length)
        trans, rot, keep = of_length(seg, sv, runs, float(length))
        known_rpe = k.get("rpe_distance", {}).get(key)
        out["rpe_distance"][key] = _stats_pair(trans, rot, None if every else keep, known_rpe)
        valid = trans if every else trans[keep]
        out["drift_rate_pct"][key] = drift_rate(valid, length)
        if not len(valid):
            notes.append(
                f"none of the {len(trans)} {key} m segments lies in drift-valid intervals:"
                f" its drift-valid RPE and drift rate are empty"
                if len(trans)
                else f"no {key} m segment fits in the matched path: its drift-valid RPE and drift"
                " rate are empty"
            )
    tv = (
        pair_valid(viv, _indices(tpairs["i"]), _indices(tpairs["j"]))
        if len(tpairs["i"])
        else np.zeros(0, bool)
    )
    name = time_rpe_key(time_delta)
    out[name] = _stats_pair(tpairs["trans_m"], tpairs["rot_deg"], tv, k.get(name))
    if not tv.any():
        notes.append(
            f"none of the {len(tv)} time-RPE pairs lies in drift-valid intervals: the drift-valid"
            " time RPE is empty"
            if len(tv)
            else "no time-RPE pair in the matched poses: the drift-valid time RPE is empty"
        )
    if det["global_failed"]:  # the record's status says why every drift-valid metric is empty
        notes = []
    elif not det["success_rate_distance_pct"]:  # 0, or None on a path without length
        notes = [NO_VALID_INTERVAL]
    else:
        return out, sv, tv, notes
    return _empty_like(out), np.zeros_like(sv), np.zeros_like(tv), notes


def _indices(column) -> np.ndarray:
    """A table's index column as integers, not copied where it is (6M pairs at 1M poses)."""
    return np.asarray(column).astype(int, copy=False)


def _stats_pair(trans, rot, keep, known) -> dict:
    """The translation and rotation statistics of one drift-valid quantity (:func:`_valid_stats`)."""
    k = known if isinstance(known, dict) else {}
    return {
        "trans_m": _valid_stats(trans, keep, k.get("trans_m")),
        "rot_deg": _valid_stats(rot, keep, k.get("rot_deg")),
    }


def _empty_like(d):
    """``d`` with every statistic None and every count 0 (a metric without drift-valid samples)."""
    if isinstance(d, dict):
        return {k: (0 if k == "n" else _empty_like(v)) for k, v in d.items()}
    return None
