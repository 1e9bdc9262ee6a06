"""Order statistics of large samples without sorting or partitioning them whole: one body for the
medians of Step 2's outlier rounds and of the metrics' statistics (np.median's value each time)."""

from __future__ import annotations

import numpy as np

SELECT_SAMPLE = 4096  # sample size of order_statistics: a bracket of about 5 % of the values


def order_statistics(x: np.ndarray, ranks: list[int]) -> np.ndarray:
    """The values of ranks ``ranks`` (0-based, ascending) of a sample without NaN, as
    ``np.partition(x, ranks)[ranks]`` gives them, in a few passes: an evenly spaced sample brackets
    them, and only the values within the bracket are partitioned (0.3 ms instead of 0.9 ms for
    100,000). The values of given ranks are the same whatever finds them; a bracket that misses
    them (a sample unlike the whole) falls back to the whole partition."""
    n = x.size
    if n <= 4 * SELECT_SAMPLE:
        return np.partition(x, ranks)[ranks]
    sample = np.sort(x[:: n // SELECT_SAMPLE])
    m = len(sample)
    margin = 4 * int(np.sqrt(m)) + 2  # some 8 standard deviations of a sample rank
    lo = sample[max(ranks[0] * m // n - margin, 0)]
    hi = sample[min(ranks[-1] * m // n + margin, m - 1)]
    within = x >= lo
    below = n - int(np.count_nonzero(within))  # no NaN: x < lo is not x >= lo
    # np.compress: the same values as x[mask], 3-4x faster on a 1,000,000-value mask
    inside = np.compress(np.logical_and(within, x <= hi, out=within), x)
    if below <= ranks[0] and ranks[-1] < below + inside.size:
        at = [r - below for r in ranks]
        return np.partition(inside, at)[at]
    return np.partition(x, ranks)[ranks]


def median(x: np.ndarray) -> float:
    """np.median of a non-empty sample without NaN: the mean of its middle value or two (numpy's
    arithmetic, which also makes a zero of either sign +0), found by :func:`order_statistics`;
    without np.median's import of numpy.ma on first use."""
    h = x.size // 2
    return float(np.mean(order_statistics(x, [h] if x.size % 2 else [h - 1, h])))
