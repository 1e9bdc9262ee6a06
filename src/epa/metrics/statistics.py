"""Statistics over runs and datasets: the run-to-run spread of a table cell and the comparison of
two algorithms (wins, paired test over datasets, test over runs per dataset, median ratio).

Tests are two-sided at ALPHA, without correction for the number of pairs compared (said in the
report). Exact null distributions are used (few datasets, few runs): with n datasets the smallest
possible Wilcoxon p is 2 / 2^n, so fewer than 6 datasets can never reach 0.05, and that is said
rather than a p presented as evidence.
"""

from __future__ import annotations

from typing import Any

import numpy as np

ALPHA = 0.05
SPREAD_KINDS = ("none", "std", "ci")


def spread(values, kind: str) -> float:
    """The ± of a cell over its runs: the sample standard deviation (n - 1), or the half-width of
    the 95 % confidence interval of the mean (Student t, n - 1 degrees of freedom). nan with
    fewer than two values."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if kind == "none" or v.size < 2:
        return np.nan
    std = float(v.std(ddof=1))
    if kind == "std":
        return std
    # stdtrit is what scipy.stats.t.ppf evaluates, without scipy.stats' 0.9 s import
    from scipy import special

    return float(special.stdtrit(v.size - 1, 0.975) * std / np.sqrt(v.size))


def average_ranks(x) -> tuple[np.ndarray, np.ndarray]:
    """Ranks from 1, ties given the mean of the ranks they span (``scipy.stats.rankdata``'s
    "average"), and the size of each group of equal values."""
    x = np.asarray(x, float)
    order = np.argsort(x, kind="mergesort")
    ordered = x[order]
    first = np.r_[True, ordered[1:] != ordered[:-1]]  # where each group of equal values starts
    starts = np.flatnonzero(first)
    ends = np.r_[starts[1:], x.size]  # one past each group's last position
    group = np.cumsum(first) - 1
    ranks = np.empty(x.size)
    ranks[order] = 0.5 * (starts[group] + 1 + ends[group])
    return ranks, ends - starts


def wilcoxon_exact(diff) -> float:
    """Two-sided exact p of the Wilcoxon signed-rank test on paired differences (zeros dropped,
    ties given mid-ranks); 1.0 without non-zero differences."""
    d = np.asarray(diff, float)
    d = d[d != 0]
    n = d.size
    if n == 0:
        return 1.0
    ranks, ties = average_ranks(np.abs(d))
    observed = ranks[d > 0].sum()
    # every sign assignment is equally likely under the null: enumerate them (n is a few datasets);
    # beyond 16 the enumeration is too long
    if n > 16:
        return _wilcoxon_as_scipy(n, ties, observed)
    signs = (np.arange(2**n)[:, None] >> np.arange(n)) & 1
    sums = signs @ ranks
    centre = ranks.sum() / 2
    return float(np.mean(np.abs(sums - centre) >= abs(observed - centre) - 1e-9))


def _wilcoxon_as_scipy(n: int, ties: np.ndarray, r_plus: float) -> float:
    """``scipy.stats.wilcoxon(d).pvalue`` for more than 16 non-zero differences, the same floats
    (tests/test_confidence_tables.py compares them) without importing scipy.stats (1.1 s of the
    tables' serial tail on a grid of that many datasets): up to 50 differences without ties the
    exact null distribution of the rank sum, else the normal approximation with the tie correction,
    without a continuity correction. ``ties``: the sizes of |d|'s groups of equal values;
    ``r_plus``: the sum of the positive differences' mid-ranks."""
    if n <= 50 and not np.any(ties > 1):
        pmf = np.ones(1)  # P(rank sum = r) over r = 0..k(k+1)/2, one rank k at a time
        for k in range(1, n + 1):
            prev, pmf = pmf, np.zeros(k * (k + 1) // 2 + 1)
            pmf[: len(prev)] = prev * 0.5
            pmf[-len(prev) :] += prev * 0.5
        k, centre = int(r_plus), n * (n + 1) / 4  # an integer without ties
        cdf = pmf[: k + 1].sum() if k <= centre else 1 - pmf[k + 1 :].sum()
        sf = pmf[k:].sum() if k <= centre else 1 - pmf[:k].sum()
        return float(np.clip(2 * min(sf, cdf), 0, 1))
    count = float(n)
    centre = count * (count + 1.0) * 0.25
    var = count * (count + 1.0) * (2.0 * count + 1.0)
    ties = ties.astype(float)
    se = np.sqrt((var - np.sum(ties**3 - ties) / 2) / 24)
    from scipy import special  # ndtr, as scipy's normal; 0.4 s where scipy.stats takes 1.1

    return float(2 * special.ndtr(-abs((r_plus - centre) / se)))


def mann_whitney(a, b) -> float:
    """Two-sided p of the Mann-Whitney U test over two algorithms' runs on one dataset, as
    ``scipy.stats.mannwhitneyu(a, b)`` gives it (tests/test_statistics.py compares them): exact
    without ties when one side has at most 8 runs, else the normal approximation with the tie
    correction and a continuity correction. Here because importing scipy.stats takes 0.9 s, more
    than the tables it would serve."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n1, n2 = a.size, b.size
    ranks, ties = average_ranks(np.r_[a, b])
    u1 = ranks[:n1].sum() - n1 * (n1 + 1) / 2
    u = max(u1, n1 * n2 - u1)
    if (n1 > 8 and n2 > 8) or np.any(ties > 1):
        n = n1 + n2
        sigma = np.sqrt(n1 * n2 / 12 * ((n + 1) - np.sum(ties**3.0 - ties) / (n * (n - 1))))
        from scipy import special  # only here: its import is 0.4 s, most of a small grid's tables

        with np.errstate(divide="ignore", invalid="ignore"):  # every run equal: sigma 0, p 1
            p = special.ndtr(-(u - n1 * n2 / 2 - 0.5) / sigma)
    else:
        p = _u_at_most(int(n1 * n2 - u), min(n1, n2), max(n1, n2))
    return float(np.clip(2 * p, 0.0, 1.0))


def _u_at_most(k: int, n1: int, n2: int) -> float:
    """P(U <= k) under the null for samples of n1 <= n2 without ties (k <= n1 n2 / 2): the number of
    rank sets giving each U, by the recurrence u f(u) = sum_j f(j) s(u - j) of the generating
    function's logarithmic derivative (scipy's, in the same order of operations), over the
    C(n1 + n2, n1) sets."""
    sigma = np.zeros(k + 1, dtype=int)
    for d in range(1, n1 + 1):
        sigma[d::d] += d
    for d in range(n2 + 1, n1 + n2 + 1):
        sigma[d::d] -= d
    counts = np.zeros(k + 1, dtype=np.uint64)
    counts[0] = 1
    exact = True
    for u in range(1, k + 1):
        value = np.dot(counts[:u], sigma[u:0:-1]) / u
        if exact and value > np.iinfo(np.uint64).max:  # beyond uint64: floats from here on
            counts, exact = counts.astype(float), False
        counts[u] = value
    return float(np.cumsum(counts / _binom(n1 + n2, n1))[k])


def _binom(n: int, k: int) -> float:
    """C(n, k) as ``scipy.special.binom`` computes it for integers (its loop, the same roundings),
    without importing scipy.special (0.4 s)."""
    if k > n / 2 and n > 0:
        k = n - k
    if k >= 20:  # scipy switches to another formula (never here: one side has at most 8 runs)
        from scipy import special

        return float(special.binom(n, k))
    num = den = 1.0
    for i in range(1, k + 1):
        num *= i + n - k
        den *= i
        if abs(num) > 1e50:
            num /= den
            den = 1.0
    return num / den


def min_datasets_for(alpha: float = ALPHA) -> int:
    """The fewest paired datasets whose exact Wilcoxon test can reach p < alpha."""
    n = 1
    while 2.0 / 2**n >= alpha:
        n += 1
    return n


def compare(a: dict, b: dict, rpe_a: dict, rpe_b: dict) -> dict:
    """Algorithm A against B. ``a`` / ``b``: dataset -> the runs' ATE (lower is better);
    ``rpe_a`` / ``rpe_b``: dataset -> the runs' RPE. Only datasets where both have runs count."""
    shared = sorted(set(a) & set(b))
    mean_a = np.array([np.mean(a[d]) for d in shared])
    mean_b = np.array([np.mean(b[d]) for d in shared])
    out: dict[str, Any] = {
        "datasets": shared,
        "wins_a": int(np.sum(mean_a < mean_b)),
        "wins_b": int(np.sum(mean_b < mean_a)),
        "ties": int(np.sum(mean_a == mean_b)),
    }
    out["median_ratio_ate"] = float(np.median(mean_a / mean_b)) if shared else np.nan
    rpe = [d for d in shared if d in rpe_a and d in rpe_b]
    out["median_ratio_rpe"] = (
        float(np.median([np.mean(rpe_a[d]) / np.mean(rpe_b[d]) for d in rpe])) if rpe else np.nan
    )
    out["p_datasets"] = wilcoxon_exact(mean_a - mean_b) if shared else np.nan
    out["datasets_testable"] = len(shared) >= min_datasets_for()
    out["per_dataset"] = {}
    for d in shared:
        entry = {
            "runs_a": len(a[d]),
            "runs_b": len(b[d]),
            "mean_a": float(np.mean(a[d])),
            "mean_b": float(np.mean(b[d])),
        }
        if len(a[d]) >= 2 and len(b[d]) >= 2:
            entry["p_runs"] = mann_whitney(a[d], b[d])
        out["per_dataset"][d] = entry
    # the verdict: which is better over the datasets ("a" / "b", None when not shown), else on
    # which datasets their runs differ and which is better there; neither: they cannot be told apart
    out["better_over_datasets"] = (
        ("a" if np.median(mean_a - mean_b) < 0 else "b")
        if out["datasets_testable"] and out["p_datasets"] < ALPHA
        else None
    )
    out["better_on_dataset"] = {
        d: "a" if e["mean_a"] < e["mean_b"] else "b"
        for d, e in out["per_dataset"].items()
        if e.get("p_runs", 1.0) < ALPHA
    }
    return out
