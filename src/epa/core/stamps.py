"""Index arithmetic on sorted stamps or path distances: nearest stamps and pairs a distance apart.
Used by Step 1's association, Step 2's motion pairs, the RPE pairs and the timing match."""

from __future__ import annotations

import numpy as np


def nearest_from(stamps: np.ndarray, x: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """Index of the stamp nearest to each x among stamps[lo:], ties to the earlier one."""
    n = len(stamps)
    k = np.maximum(np.searchsorted(stamps, x, side="left"), lo)
    upper = np.minimum(k, n - 1)
    lower = np.maximum(k - 1, lo)
    d_up = np.where(k < n, np.abs(stamps[upper] - x), np.inf)
    d_lo = np.where(k - 1 >= lo, np.abs(x - stamps[lower]), np.inf)
    return np.where(d_lo <= d_up, lower, upper)


def run_starts(d: np.ndarray) -> np.ndarray:
    """For each k of a non-decreasing ``d``, the first index holding d[k]'s value: what
    ``np.searchsorted(d, d, side="left")`` finds, in one pass instead of a search per element (2.5 ms
    for 100,000). NaN, which sorts last and equals nothing, is left to the search."""
    n = len(d)
    if n == 0 or np.isnan(d).any():
        return np.searchsorted(d, d, side="left")
    new = np.empty(n, bool)
    new[0] = True
    np.not_equal(d[1:], d[:-1], out=new[1:])
    return np.maximum.accumulate(np.where(new, np.arange(n), 0))


def closest_pairs(
    d: np.ndarray, delta: float, tol: float, *, strict: bool, skip: int, starts=None
) -> tuple[np.ndarray, np.ndarray]:
    """For every start i, the first j >= i + skip whose d[j] is closest to d[i] + delta.

    ``d`` must be non-decreasing (cumulative path length or time), ``delta`` finite (the settings
    refuse a non-finite number). Kept when the gap is < tol
    (strict, ov_eval) or <= tol (evo). Equivalent to the nested scans of ov_eval's
    compute_comparison_indices_length and evo's filter_pairs_by_path(all_pairs=True), in O(N log N).
    ``starts``: :func:`run_starts` of ``d``, made once for several deltas.
    """
    n = len(d)
    target = d + delta
    first = np.arange(skip, n + skip)  # the first partner each start may take
    if skip > 1:
        np.minimum(first, n, out=first)
    # the first index with d >= target (no upper candidate: n, whose d is +inf below)
    k = np.maximum(np.searchsorted(d, target, side="left"), first)
    padded = np.append(d, np.inf)
    lo = k - 1
    # the earliest index holding the same value as the lower candidate (scans keep the first best);
    # where there is no lower candidate (lo < first) its error is inf
    starts = run_starts(d) if starts is None else starts
    lo_first = np.minimum(np.maximum(starts[np.maximum(lo, 0)], first), n - 1)
    err_up = np.abs(padded[k] - target)
    err_lo = np.where(lo >= first, np.abs(padded[lo_first] - target), np.inf)
    take_lo = err_lo <= err_up
    err = np.where(take_lo, err_lo, err_up)
    ok = err < tol if strict else err <= tol
    return np.flatnonzero(ok), np.where(take_lo, lo_first, np.minimum(k, n - 1))[ok]
