"""Efficiency: per-frame processing time, and the Efficiency-Aware Drift rate (EA-Drift, EPA's definition).

EA-Drift = sqrt(sum_i w_i |e_i|^2) / L, w_i = exp((t_i - T) / T), where e_i is the translation error
of pose i after the rigid alignment, t_i the processing time of frame i and T = 1/f the sensor
period, both in seconds (EPA's text writes (t_i - 1/f)/f with t_i in ms; only t_i and T in one unit
and the difference divided by T make the weight dimensionless and exactly 1 when a frame takes one
period), and L the estimate's path length. Reported in % like the drift rate.

Three variants:
- ``ea_drift_seed``: the formula above. It grows with sqrt(n): at 200 Hz it is ~3x the 20 Hz value
  for the same accuracy, so it cannot compare algorithms that output at different rates.
- ``ea_drift`` (printed in the tables): per-frame normalised, sqrt(sum w e^2 / n) / L; with every
  frame on time (w = 1) it is ATE rmse / L.
- ``ea_drift_m2ud``: the M2UD EA-evo patch as its code does it, for comparison with its numbers:
  the weight multiplies the error before squaring (so enters squared), timing is matched to each
  reference stamp by the first entry within ±0.15 s, L is the estimate's path length.
"""

from __future__ import annotations

import logging

import numpy as np

from epa.core.stamps import nearest_from
from epa.metrics.spec import Metric, Table

SUMMARY_COLUMNS = ("ea_drift", "frame_time_mean_ms")


def enabled(cfg: dict) -> bool:
    return True


def summary(record: dict) -> dict:
    """Empty without timing."""
    return {k: record[k] for k in SUMMARY_COLUMNS} if record.get("available") else {}


def pooled_runtime(records: list[dict]) -> tuple[float, float, float, float]:
    """Frame times pooled over runs (each run's statistics, frame-weighted): mean, p95, max (ms) and
    the share of frames over the sensor period (%)."""
    frames = np.array([e["frames"] for e in records], float)
    w = frames / frames.sum()
    return (
        float(np.sum(w * [e["frame_time_mean_ms"] for e in records])),
        float(np.sum(w * [e["frame_time_p95_ms"] for e in records])),
        float(max(e["frame_time_max_ms"] for e in records)),
        float(np.sum(w * [e["frames_over_period_pct"] for e in records])),
    )


def in_order(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stable order of the stamps ``t`` and the stamps in it (np.argsort(t, kind="stable") and
    t at it): 0, 1, ... and ``t`` itself where they are in order already, as a timing file's are (a
    stable sort of them is that permutation; 10 ms a case of 100,000 frames spared)."""
    t = np.asarray(t)
    if t.ndim == 1 and bool(np.all(t[1:] >= t[:-1])):  # (NaN compares false: sorted)
        return np.arange(len(t)), t
    order = np.argsort(t, kind="stable")
    return order, t[order]


def match_nearest(t_pose: np.ndarray, t_timing: np.ndarray, max_diff: float) -> np.ndarray:
    """Index of the timing entry nearest each pose stamp, -1 where none is within ``max_diff``."""
    order, ts = in_order(t_timing)
    pick = nearest_from(ts, t_pose, np.zeros(len(t_pose), dtype=np.int64))
    ok = np.abs(ts[pick] - t_pose) <= max_diff
    return np.where(ok, order[pick], -1)


def match_m2ud(t_ref: np.ndarray, t_timing: np.ndarray, window: float = 0.15) -> np.ndarray:
    """The M2UD patch's matching: for each reference stamp, the *first* timing entry (in file order)
    strictly within ±window (``|t_timing - t_ref| < window``); -1 where none.

    Linear in the stamps (the patch compares every pair: 0.9 s for a 7,500-pose case): the entries
    within a window are a contiguous run of the stamp-sorted timing, found by binary search and its
    edges settled by the exact test; the first in file order is a range minimum of their file
    indices (a sparse table)."""
    order, ts = in_order(t_timing)
    n = len(t_timing)
    out = np.full(len(t_ref), -1, dtype=np.int64)
    if n == 0 or len(t_ref) == 0:
        return out
    t_ref = np.asarray(t_ref, dtype=float)

    def inside(j):
        return (j >= 0) & (j < n) & (np.abs(ts[np.clip(j, 0, n - 1)] - t_ref) < window)

    margin = 1e-9 * max(window, 1.0)  # a superset of the run, then its edges by the exact test
    lo = np.searchsorted(ts, t_ref - window - margin, side="left")
    hi = np.searchsorted(ts, t_ref + window + margin, side="right")
    while True:
        shrink_lo, shrink_hi = (lo < hi) & ~inside(lo), (lo < hi) & ~inside(hi - 1)
        if not (shrink_lo.any() or shrink_hi.any()):
            break
        lo, hi = lo + shrink_lo, hi - shrink_hi
    some = lo < hi
    levels = [order.astype(np.int64)]  # levels[k][i] = min(order[i : i + 2**k])
    while 2 ** len(levels) <= n:
        prev, half = levels[-1], 2 ** (len(levels) - 1)
        levels.append(np.minimum(prev[:-half], prev[half:]))
    length = np.where(some, hi - lo, 1)
    k = np.floor(np.log2(length)).astype(int)
    for level in np.unique(k[some]):
        q = some & (k == level)
        span = 2**level
        out[q] = np.minimum(levels[level][lo[q]], levels[level][hi[q] - span])
    return out


def weights(frame_ms: np.ndarray, rate_hz: float) -> np.ndarray:
    period_s = 1.0 / rate_hz
    with np.errstate(over="ignore"):  # a frame of ~700 periods: inf, which evaluate() reports
        return np.exp((frame_ms / 1000.0 - period_s) / period_s)


# exp(x) overflows a double above this: a frame that long has no finite EA-Drift weight
MAX_WEIGHT_EXPONENT = float(np.log(np.finfo(float).max))


def _overflowing_frame(frame_ms: np.ndarray, rate_hz: float) -> int | None:
    """The index of the first frame whose EA-Drift weight is not a finite number, else None."""
    period_ms = 1000.0 / rate_hz
    exponent = (frame_ms - period_ms) / period_ms
    over = exponent >= MAX_WEIGHT_EXPONENT / 2  # squared in the M2UD variant
    return int(np.argmax(over)) if over.any() else None


def ea_drift(err_m: np.ndarray, frame_ms: np.ndarray, rate_hz: float, path_length_m: float) -> dict:
    """EPA's EA-Drift and the per-frame normalised variant, in %."""
    w = weights(frame_ms, rate_hz)
    s = float(np.sum(w * err_m**2))
    n = len(err_m)
    return {
        "ea_drift_seed": 100 * np.sqrt(s) / path_length_m,
        "ea_drift": 100 * np.sqrt(s / n) / path_length_m if n else None,
    }


def ea_drift_m2ud(
    err_m: np.ndarray, frame_ms: np.ndarray, rate_hz: float, path_length_m: float
) -> float:
    frame_time_ms = 1000.0 / rate_hz
    with np.errstate(over="ignore"):
        w = np.exp((frame_ms - frame_time_ms) / frame_time_ms)
    return float(100 * np.sqrt(np.sum((w * err_m) ** 2)) / path_length_m)


def runtime(frame_ms: np.ndarray, rate_hz: float) -> dict:
    period_ms = 1000.0 / rate_hz
    over = frame_ms > period_ms
    return {
        "frames": int(len(frame_ms)),
        "frame_time_mean_ms": float(np.mean(frame_ms)),
        "frame_time_p95_ms": float(np.percentile(frame_ms, 95)),
        "frame_time_max_ms": float(np.max(frame_ms)),
        "frames_over_period": int(over.sum()),
        "frames_over_period_pct": float(100 * over.mean()),
        "sensor_period_ms": period_ms,
    }


def evaluate(
    t_est: np.ndarray,
    t_ref: np.ndarray,
    err_m: np.ndarray,
    est_path_length_m: float,
    timing: tuple[np.ndarray, np.ndarray],
    rate_hz: float,
    max_diff: float,
) -> tuple[dict, dict]:
    """Efficiency of one case. ``t_est``/``t_ref``: matched stamps; ``err_m``: APE per matched pose."""
    t_tim, ms = timing
    idx = match_nearest(t_est, t_tim, max_diff)
    have = idx >= 0
    n_missing = int((~have).sum())
    summary = {
        "sensor_rate_hz": rate_hz,
        "timing_max_diff_s": max_diff,
        "n_poses": int(len(t_est)),
        "n_without_timing": n_missing,
        **runtime(ms, rate_hz),
    }
    if not have.any():
        summary.update(available=False, reason=f"no pose has a timing entry within {max_diff} s")
        return summary, {}
    summary["available"] = True
    k = _overflowing_frame(ms, rate_hz)
    # never inf as a result: the frame times stand, EA-Drift is empty and says why
    if k is not None:
        summary.update(ea_drift_seed=None, ea_drift=None, ea_drift_m2ud=None)
        summary["ea_drift_reason"] = (
            f"timing entry {k + 1} (stamp {t_tim[k]:.6f} s) takes {ms[k]:g} ms, "
            f"{ms[k] * rate_hz / 1000:.0f} sensor periods: its EA-Drift weight overflows, "
            "so EA-Drift is left empty"
        )
        logging.getLogger(__name__).warning("%s", summary["ea_drift_reason"])
    else:
        summary.update(
            _finite_ea_drift(t_ref, t_tim, ms, idx, have, err_m, rate_hz, est_path_length_m)
        )
    table = {
        "t": t_est,
        "frame_ms": np.where(have, ms[np.maximum(idx, 0)], np.nan),
        "weight": np.where(have, weights(ms[np.maximum(idx, 0)], rate_hz), np.nan),
        "err_m": err_m,
    }
    return summary, table


def _finite_ea_drift(t_ref, t_tim, ms, idx, have, err_m, rate_hz, path_length_m) -> dict:
    """EA-Drift, its seed form and the M2UD variant; one whose weighted errors overflow a double
    (a weight below the overflowing frame's bound times a large error) is None with a reason."""
    with np.errstate(over="ignore"):  # an overflow is caught below, never reported as inf
        values: dict = ea_drift(err_m[have], ms[idx[have]], rate_hz, path_length_m)
        m2 = match_m2ud(t_ref, t_tim)
        # the patch stops when a pose has no timing
        values["ea_drift_m2ud"] = (
            ea_drift_m2ud(err_m, ms[m2], rate_hz, path_length_m) if (m2 >= 0).all() else None
        )
    why = "its frame-time weights times the errors overflow a double, so it is left empty"
    for key in ("ea_drift_seed", "ea_drift", "ea_drift_m2ud"):
        if values[key] is not None and not np.isfinite(values[key]):
            values[key] = None
            values[f"{key}_reason" if key != "ea_drift_seed" else "ea_drift_reason"] = why
    if values["ea_drift_seed"] is None and values["ea_drift"] is not None:
        values["ea_drift"] = None  # the two differ by sqrt(n): one overflowing, both go
    return values


_TABLES = (
    Table(
        "ea_drift",
        "EA-DRIFT LATEX TABLE (% PER-FRAME NORMALISED, SEE DOCS)",
        pair=False,
        per_run=lambda r: (r["ea_drift"],),
        has=lambda r: bool(r.get("available")) and r.get("ea_drift") is not None,
        missing=lambda records: (
            "EA-Drift overflows" if any(r.get("ea_drift_reason") for r in records) else "no timing"
        ),
    ),
    Table(
        "runtime",
        "RUNTIME LATEX TABLE (FRAME TIME MS: MEAN, P95, MAX; % FRAMES OVER SENSOR PERIOD)",
        pair=False,
        has=lambda r: bool(r.get("available")),
        per_algorithm=pooled_runtime,
        header=("mean", "p95", "max", "over period %"),
    ),
)


METRIC = Metric(
    key="efficiency",
    stage="efficiency",  # its own stage: records available false without timing
    enabled=enabled,
    summary=summary,
    settings=("efficiency",),
    arrays=("frames.csv",),
    summary_columns=SUMMARY_COLUMNS,
    tables=_TABLES,
)
