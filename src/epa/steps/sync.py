"""Step 1: time offset by cross-correlating angular speed; association of poses by timestamp.

Sign convention everywhere: ``offset`` is added to the estimate's stamps to bring them onto the
reference clock (``t_ref = t_est + offset``), as evo's ``offset_2``.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from epa.core import geometry, ranks, runtime
from epa.core.errors import EpaError
from epa.core.records import Step1Record
from epa.core.stamps import nearest_from
from epa.core.trajectory import Trajectory
from epa.steps import rpg


# ----------------------------------------------------------------------------- association
def associate_ov_eval(t_ref: np.ndarray, t_est: np.ndarray, max_diff: float, offset: float = 0.0):
    """ov_eval's greedy one-to-one association (AlignUtils::perform_association).

    For each estimate stamp in order: the nearest reference stamp not before the last match,
    kept when within max_diff. Vectorised: nearest over all, then re-resolve the estimates that
    collide with an earlier match until no collision is left. Where ov_eval's walk stops at a first
    stamp exactly max_diff away (:func:`_stops_at_the_edge`), the estimate is left unmatched and
    the rest resolved again (exact stamps only: never on the real data measured).
    """
    x = t_est + offset
    blocked = np.zeros(len(x), dtype=bool)
    for _ in range(EDGE_ROUNDS):
        j, ok = _greedy(t_ref, x, max_diff, blocked)
        edge = _stops_at_the_edge(t_ref, x, _last_before(np.where(ok, j, -1)) + 1, max_diff)
        if np.array_equal(edge, blocked):
            return j[ok], np.flatnonzero(ok)
        blocked = edge
    return _associate_ov_eval_literal(t_ref, x, max_diff)


# rounds of re-resolving after ov_eval's edge stops before its literal loop answers instead
EDGE_ROUNDS = 8


def _greedy(t_ref: np.ndarray, x: np.ndarray, max_diff: float, blocked: np.ndarray):
    """The nearest stamp of each estimate not before the last match, one-to-one; ``blocked``
    estimates are left unmatched. Returns (index, matched) per estimate."""
    lo = np.zeros(len(x), dtype=np.int64)
    while True:
        j = nearest_from(t_ref, x, lo)
        # strictly within: ov_eval starts its best difference at max_difference and keeps only a
        # smaller one, so a stamp exactly max_difference away is no match
        ok = (np.abs(t_ref[j] - x) < max_diff) & ~blocked
        prev = _last_before(np.where(ok, j, -1))
        clash = ok & (j <= prev)
        if not clash.any():
            return j, ok
        lo = np.where(clash, prev + 1, lo)
        beyond = lo >= len(t_ref)
        if beyond.any():
            lo = np.minimum(lo, len(t_ref) - 1)
            x = np.where(beyond, np.inf, x)  # nothing left to match these against


def _associate_ov_eval_literal(t_ref: np.ndarray, x: np.ndarray, max_diff: float):
    """AlignUtils::perform_association, line by line (a pointer over the reference stamps)."""
    ptr, i_ref, i_est = 0, [], []
    for i, te in enumerate(x.tolist()):
        best, best_idx = max_diff, -1
        while ptr < len(t_ref) and t_ref[ptr] < te and abs(t_ref[ptr] - te) > max_diff:
            ptr += 1
        while ptr < len(t_ref) and abs(t_ref[ptr] - te) <= max_diff:
            if abs(t_ref[ptr] - te) >= best:
                break
            best, best_idx = abs(t_ref[ptr] - te), ptr
            ptr += 1
        if best_idx != -1:
            i_ref.append(best_idx)
            i_est.append(i)
    return np.array(i_ref, dtype=np.int64), np.array(i_est, dtype=np.int64)


def _last_before(jm: np.ndarray) -> np.ndarray:
    """The last match before each estimate (-1 before the first; jm >= -1, so no concatenated -1)."""
    prev = np.empty_like(jm)
    prev[:1] = -1
    np.maximum.accumulate(jm[:-1], out=prev[1:])
    return prev


def _stops_at_the_edge(t_ref: np.ndarray, x: np.ndarray, lo: np.ndarray, max_diff: float):
    """Where ov_eval's walk ends before it starts: its pointer skips the reference stamps before x
    farther than max_diff, then walks while each is nearer than the best so far, which starts at
    max_diff; a first stamp exactly max_diff away is no improvement, so the estimate is left
    unmatched even where a nearer stamp follows (a reference stamp exactly max_diff before the
    estimate's, as on a synthetic 50 Hz grid under 0.02 s)."""
    n = len(t_ref)

    def skipped(k):  # ov_eval's skip condition, in its arithmetic
        at = t_ref[np.clip(k, 0, n - 1)]
        return (k < n) & (at < x) & (np.abs(at - x) > max_diff)

    # the first stamp from lo it does not skip: near x - max_diff, settled on the computed differences
    k = np.maximum(np.searchsorted(t_ref, x - max_diff, side="left"), lo)
    k = np.where((k - 1 >= lo) & ~skipped(k - 1), k - 1, k)
    k = np.where(skipped(k), k + 1, k)
    return (k < n) & (np.abs(t_ref[np.minimum(k, n - 1)] - x) == max_diff)


def associate_evo(t_ref: np.ndarray, t_est: np.ndarray, max_diff: float, offset: float = 0.0):
    """evo's association (sync.associate_trajectories, nearest_time): iterate over the shorter
    trajectory, take the nearest stamp of the longer within max_diff; poses of the longer may be reused."""
    est_longer = len(t_est) > len(t_ref)
    # the offset moves the longer side, in the same floating-point operations as evo
    short, long_ = (t_ref, t_est + offset) if est_longer else (t_est, t_ref - offset)
    k = np.searchsorted(long_, short, side="right")
    k = np.minimum(k, len(long_) - 1)
    d_ub = long_[k] - short
    d_lb = np.where(k > 0, short - long_[np.maximum(k - 1, 0)], np.inf)
    use_ub = (d_ub <= max_diff) & (d_ub < d_lb)
    use_lb = ~use_ub & (d_lb <= max_diff) & (d_lb <= d_ub)
    inside = (short >= long_[0] - max_diff) & (short <= long_[-1] + max_diff)
    keep = inside & (use_ub | use_lb)
    i_short = np.flatnonzero(keep)
    i_long = np.where(use_ub, k, k - 1)[keep]
    return (i_short, i_long) if est_longer else (i_long, i_short)


def associate_rpg(t_ref: np.ndarray, t_est: np.ndarray, max_diff: float, offset: float = 0.0):
    """rpg_trajectory_evaluation's association (:func:`epa.steps.rpg.associate`): every pair closer
    than max_diff (strictly) is a candidate, taken greedily closest first, each pose at most once;
    sorted by estimate. rpg adds its offset to the reference stamps, so ``t_ref = t_est + offset`` is
    its offset ``-offset`` (with 0, rpg's own bits)."""
    matches = rpg.associate(t_est, t_ref, -offset, max_diff)
    if not matches:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    i_est, i_ref = np.array(matches, dtype=np.int64).T
    return i_ref, i_est


def associate(
    ref: Trajectory,
    est: Trajectory,
    *,
    policy: str = "ov_eval",
    max_diff: float | None = None,
    offset: float = 0.0,
):
    """Indices (i_ref, i_est) of matched poses under the chosen policy."""
    if policy not in POLICIES:
        raise EpaError(f"unknown sync policy {policy!r}; choose one of {', '.join(POLICIES)}")
    max_diff = POLICIES[Policy(policy)] if max_diff is None else max_diff
    fn = {"ov_eval": associate_ov_eval, "evo": associate_evo, "rpg": associate_rpg}[policy]
    return fn(ref.t, est.t, max_diff, offset)


# ----------------------------------------------------------------------------- Step 1
def angular_speed(traj: Trajectory, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """|log(R_i^T R_{i+step})| / dt, stamped at the midpoints (EPA's angular rate; step 1 = consecutive poses)."""
    t = traj.t
    dt = t[step:] - t[:-step]
    return t[:-step] + dt / 2, geometry.relative_angles(traj.q, step) / dt


def linear_speed(traj: Trajectory, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """|p_{i+step} - p_i| / dt, stamped at the midpoints: Step 1's signal for a position-only
    estimate (a world rotation leaves it unchanged; a scale changes its size, not its shape)."""
    t, p = traj.t, traj.p
    dt = t[step:] - t[:-step]
    return t[:-step] + dt / 2, geometry.norms(p[step:] - p[:-step]) / dt


@dataclass
class OffsetEstimate:
    offset: float  # the offset used (estimated, or the configured fallback)
    estimated: float | None  # what the correlation found (None when it could not run)
    used: bool  # whether the estimate was trusted and used
    reason: str  # why it was (not) used
    status: str = "trusted"  # a Step1Status
    std: float | None = None  # standard deviation of the estimate (s), delete-one-block jackknife
    peak_corr: float = float("nan")
    peak_ratio: float = float("nan")
    # the best local maximum of the correlation beyond ±window
    beyond_window_corr: float = float("nan")
    ref_motion_rad_s: float = float("nan")
    est_motion_rad_s: float = float("nan")
    dt: float = float("nan")
    curve_lag: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    curve_corr: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def to_dict(self) -> Step1Record:
        """sync.json's ``step1`` (the stage turns a NaN figure into None)."""
        return Step1Record(
            offset=self.offset,
            estimated=self.estimated,
            used=self.used,
            reason=self.reason,
            status=self.status,
            std=self.std,
            peak_corr=self.peak_corr,
            peak_ratio=self.peak_ratio,
            beyond_window_corr=self.beyond_window_corr,
            ref_motion_rad_s=self.ref_motion_rad_s,
            est_motion_rad_s=self.est_motion_rad_s,
            dt=self.dt,
        )


class Step1Status(StrEnum):
    """What Step 1 concluded; anything but trusted means the estimate was not used. The values are
    the strings sync.json and summary.csv hold."""

    TRUSTED = "trusted"
    DISABLED = "disabled"
    TOO_LITTLE_MOTION = "too little motion"
    NO_OVERLAP = "no overlap"
    AT_WINDOW_EDGE = "at window edge"
    OUTSIDE_WINDOW = "outside window"
    WEAK_PEAK = "weak peak"
    AMBIGUOUS = "ambiguous"
    UNCERTAIN = "uncertain"


class Policy(StrEnum):
    """How poses are associated by stamp: ov_eval's greedy one-to-one in estimate order, evo's
    nearest with reuse, or rpg's greedy one-to-one closest pairs first."""

    OV_EVAL = "ov_eval"
    EVO = "evo"
    RPG = "rpg"


POLICIES = {Policy.OV_EVAL: 0.02, Policy.EVO: 0.01, Policy.RPG: 0.02}  # default max_diff (s)
JACKKNIFE_BLOCKS = 10


def _window_sums(
    x: np.ndarray, lo: int, width: int, count: int, *, in_place: bool = False
) -> np.ndarray:
    """sum(x[lo + j : lo + j + width]) for j in range(count), x taken as zero outside itself:
    differences of one prefix sum P (P(k) = sum(x[:k]), 0 before x, its total after it). The lags
    fall into at most five runs where each end of the window is either a slice of the prefix sum or
    one of those two constants: each run is one subtraction into the result, without a padded copy
    of the prefix sum (the same differences, so the same bits). ``in_place``: x's buffer becomes
    its prefix sum."""
    n = len(x)
    c = np.cumsum(x, out=x if in_place else None)
    total = c[-1] if n else 0.0
    out = np.empty(count)
    # where the ends k = lo + j and lo + j + width reach 1 and n (the zones' edges)
    edges = (1 - lo, n - lo, 1 - lo - width, n - lo - width)
    cuts = sorted({0, count, *(min(max(e, 0), count) for e in edges)})
    for j0, j1 in zip(cuts[:-1], cuts[1:], strict=True):
        upper = _prefix_run(c, total, lo + width + j0, j1 - j0)
        np.subtract(upper, _prefix_run(c, total, lo + j0, j1 - j0), out=out[j0:j1])
    return out


def _prefix_run(c: np.ndarray, total, k: int, count: int):
    """P(k + j) for j in range(count), a run within one zone: the constant 0.0 (k <= 0), a slice of
    the prefix sum c (P(k) = c[k - 1]), or the total (k >= len(c))."""
    if k + count - 1 <= 0:
        return 0.0
    if k >= len(c):
        return total
    return c[k - 1 : k - 1 + count]


def _clip_spikes(w: np.ndarray) -> np.ndarray:
    # Initialisation jumps (identity placeholder poses, resets) give one huge sample that would
    # dominate the correlation; cap at a robust multiple of the typical speed.
    med = ranks.median(w)
    mad = ranks.median(np.abs(w - med)) + 1e-12
    return np.minimum(w, med + 20 * mad)


def _local_maxima(curve: np.ndarray) -> np.ndarray:
    """Indices of the interior local maxima (the last sample of a flat top)."""
    inner = curve[1:-1]
    return np.flatnonzero((inner >= curve[:-2]) & (inner > curve[2:])) + 1


def _peak(curve: np.ndarray) -> tuple[int, float]:
    """Index of the maximum and its sub-sample refinement (a parabola through the neighbours)."""
    k = int(np.argmax(curve))
    frac = 0.0
    if 0 < k < len(curve) - 1:
        y0, y1, y2 = curve[k - 1], curve[k], curve[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5))
    return k, frac


def _block_sums(
    a: tuple[np.ndarray, np.ndarray, np.ndarray],
    bb: tuple[np.ndarray, np.ndarray, np.ndarray],
    starts: np.ndarray,
    lo: int,
) -> np.ndarray:
    """Over each block of b's support, at one lag: the correlation's products a[m + lag] b[m] and the
    two energies under the overlap, a[m + lag]^2 and b[m]^2 where a is defined. (3, blocks).

    ``a`` is (a, a^2, a defined) zero-padded so that every lag's shifted support is the slice from
    ``lo``; ``bb`` is (b, b^2, the block sums of b^2) over b's support: made once for every lag, and
    the last is b's energy wherever a is defined under all of it (most lags: the same sums)."""
    seg, seg2, defined = (x[lo : lo + len(bb[0])] for x in a)
    energy_b = bb[2] if defined.all() else np.add.reduceat(np.where(defined, bb[1], 0.0), starts)
    return np.stack([np.add.reduceat(seg * bb[0], starts), np.add.reduceat(seg2, starts), energy_b])


def _coarse(x: np.ndarray, q: int) -> np.ndarray:
    """Sums of q consecutive samples (the last incomplete group dropped), added in their order as
    x.reshape(-1, q).sum(axis=1) does, on strided columns (6x faster than that short-axis sum)."""
    n = len(x) // q * q
    total = x[0:n:q].copy()
    for k in range(1, q):
        total += x[k:n:q]
    return total


def _jackknife_std(
    a: np.ndarray,
    b: np.ndarray,
    span: tuple[int, int],
    peak_lag: int,
    reach: int,
    dt: float,
    blocks: int = JACKKNIFE_BLOCKS,
) -> float:
    """Standard deviation of the correlation peak's lag by the delete-one-block jackknife.

    The estimate signal's support is cut into ``blocks`` consecutive blocks; each replicate is the
    normalised correlation without one block and finds its peak near ``peak_lag``. Blocks span
    seconds, longer than the signals' correlation time, so the replicates see correlated noise as it
    is. The replicates are computed on a 5 ms grid (sums of the 1 ms samples; the main lobe of
    signals measured over >= 0.1 s is hundreds of ms wide, so a parabola still finds its top to a
    small fraction of the grid). The search starts at 16 grid steps and widens while a replicate
    peak sits on its edge; one still on the edge at ``reach`` samples (the main lobe) means the
    offset is not pinned down: infinite. The quantisation of the full grid (dt^2/12) is added."""
    q = max(1, int(round(0.005 / dt)))
    a_c, b_c = _coarse(a, q), _coarse(b, q)
    b0, b1 = span[0] // q, min(span[1] // q, len(b_c) - 1)
    starts = np.linspace(0, b1 + 1 - b0, blocks + 1).astype(int)[:-1]
    centre, reach_c = int(round(peak_lag / q)), max(3, reach // q)
    # a padded with "not defined" (zeros) for every lag the search may reach
    pad = np.zeros(abs(centre) + reach_c + 1)
    a_c = np.concatenate([pad, a_c, pad])
    padded = (a_c, a_c * a_c, a_c != 0.0)  # on_grid leaves a exactly zero outside its support
    b_sq = b_c[b0 : b1 + 1] ** 2
    bb = (b_c[b0 : b1 + 1], b_sq, np.add.reduceat(b_sq, starts))
    columns: dict[np.integer, np.ndarray] = {}  # keyed by the lags as numpy gives them
    half = min(16, reach_c)
    while True:
        lags = np.arange(centre - half, centre + half + 1)
        for lag in lags:
            if lag not in columns:  # widening reuses what is computed
                columns[lag] = _block_sums(padded, bb, starts, len(pad) + b0 + int(lag))
        sums = np.stack([columns[lag] for lag in lags], axis=-1)  # (3, blocks, lags)
        num, energy_a, energy_b = sums.sum(axis=1, keepdims=True) - sums
        replicates = num / np.sqrt(np.maximum(energy_a * energy_b, 1e-300))
        peaks = [_peak(r) for r in replicates]
        if all(0 < i < len(lags) - 1 for i, _ in peaks):
            break
        if half >= reach_c:
            return float("inf")
        half = min(2 * half, reach_c)
    shifts = np.array([(lags[i] + frac) * q * dt for i, frac in peaks])
    jack = np.sqrt((blocks - 1) / blocks * np.sum((shifts - shifts.mean()) ** 2))
    return float(np.hypot(jack, dt / np.sqrt(12.0)))


def _speed_signals(ref: Trajectory, est: Trajectory, speed_interval: float, speed) -> tuple | str:
    """Each side's angular speed over the same interval (t_a, w_a, t_b, w_b), or why there is none
    to correlate: too few poses, a median interval between consecutive stamps that is not positive
    (stamps kept repeated or unsorted, e.g. every pose written twice), or a side whose poses span
    no speed interval (a short one at a much lower rate than the other).

    The coarser trajectory only sees chord rates over its own sample interval, so the finer one is
    measured over that interval too (the magnitude of a mean rate is not the mean of magnitudes),
    and over at least ``speed_interval``: differencing consecutive noisy orientations turns white
    orientation noise into speed noise that grows with the rate and biases a gentle motion's peak."""
    if len(ref) < 4 or len(est) < 4:
        return "too few poses for a correlation"
    sides = (("reference", ref), ("estimate", est))
    steps = [ranks.median(np.diff(traj.t)) for _, traj in sides]
    for (side, _), step in zip(sides, steps):
        if not step > 0:
            return (
                f"the {side}'s median interval between consecutive stamps is {step:g} s (repeated or"
                " unsorted stamps): no sample interval for a correlation"
            )
    interval = max(*steps, speed_interval)
    signals = []
    for (side, traj), step in zip(sides, steps):
        t, w = speed(traj, max(1, int(round(interval / step))))
        if not len(w):
            return f"too few poses for a correlation: the {side}'s poses span no {interval:g} s"
        signals += [t, w]
    return tuple(signals)


def _on_grid(grid: np.ndarray, ts: np.ndarray, w: np.ndarray):
    """A signal on the correlation grid, zero-mean inside its support, exactly zero outside it, of
    unit energy; and its support, the first and last grid index within [ts[0], ts[-1]] (the last
    before the first when none is)."""
    i0 = int(np.searchsorted(grid, ts[0], side="left"))
    i1 = int(np.searchsorted(grid, ts[-1], side="right")) - 1
    s = np.zeros(len(grid))
    np.subtract(np.interp(grid[i0 : i1 + 1], ts, w), w.mean(), out=s[i0 : i1 + 1])
    s /= np.sqrt(np.sum(s * s)) + 1e-300
    return s, (i0, i1)


def _normalised_correlation(a, span_a, b, span_b, smooth_fft: bool = True):
    """At every lag the FFT gives without wrapping (|lag| < n; index i holds lag i - (n - 1)), so a
    better match beyond the window is seen rather than a lesser one inside it reported, the
    correlation: corr[k] = sum_m a[m + k] b[m] (the estimate signal shifted later by k samples matches
    the reference), divided by the energy of both signals under the overlap. The estimate usually
    covers only part of the reference, so that slice's energy changes with the lag and, for slow
    motion, would tilt the peak by tens of ms. Supports are index intervals: the energies are
    prefix-sum differences. Lags where less than half the shorter signal overlaps get -1; the others
    are an interval (the overlap rises, stays and falls with the lag), and only they are computed."""
    n = len(a)
    (a0, a1), (b0, b1) = span_a, span_b
    need = math.ceil(0.5 * (min(a1 - a0, b1 - b0) + 1))  # the overlap is an integer
    # overlap = min(b1, a1 - k) - max(b0, a0 - k) + 1 >= need, term by term
    lo, hi = max(-(n - 1), a0 - b1 - 1 + need), min(n - 1, a1 - b0 + 1 - need)
    if lo > hi:
        return np.full(2 * n - 1, -1.0), (b0, b1)
    count = hi - lo + 1
    if smooth_fft:
        # The supports only, on a 5-smooth length just long enough that the lags computed do not
        # wrap onto others (lag k is index k + b0 - a0 of the supports' circular correlation, whose
        # products reach from -(b's length - 1) to a's length - 1), and at least 1.5 times a's
        # support, which covers every estimate within the reference's span: one length per
        # reference, whose spectrum is kept. About half the power of two of the whole arrays
        # (transforms 2x cheaper); the peak moves by rounding only (docs/reproducibility.md).
        shift = b0 - a0
        length_a, length_b = a1 - a0 + 1, b1 - b0 + 1
        least = max(length_a - (lo + shift), hi + shift + length_b, length_a + (length_a + 1) // 2)
        nfft, a_s, b_s = fft_length(least), a[a0 : a1 + 1], b[b0 : b1 + 1]
    else:  # evo's --step1: the power of two of the whole arrays, whose bits it prints
        shift, nfft, a_s, b_s = 0, 1 << int(np.ceil(np.log2(2 * n))), a, b
    kept = _kept_spectrum(a, span_a, nfft)
    if kept is None:
        # the two transforms at once where a core is spare (`epa eval`: 13 ms each at 100k poses),
        # then the inverse beside the energies
        spectrum_a, spectrum_b = runtime.both(
            lambda: np.fft.rfft(a_s, nfft), lambda: np.fft.rfft(b_s, nfft)
        )
        _keep_spectrum(a, span_a, nfft, spectrum_a)
    else:
        spectrum_a, spectrum_b = kept, np.fft.rfft(b_s, nfft)
    # into b's buffer (the reference's may be kept): the same products, in the same operand order
    spectrum = np.multiply(spectrum_a, np.conjugate(spectrum_b, out=spectrum_b), out=spectrum_b)

    def energies() -> np.ndarray:
        # the squares made in their own buffers, which become their prefix sums
        energy_a = _window_sums(
            np.square(a[a0 : a1 + 1]), b0 + lo - a0, b1 - b0 + 1, count, in_place=True
        )
        energy_b = _window_sums(
            np.square(b[b0 : b1 + 1]), a0 - hi - b0, a1 - a0 + 1, count, in_place=True
        )[::-1]
        energy_a *= energy_b  # in place: the same arithmetic, fewer 8-byte-per-lag temporaries
        return np.sqrt(np.maximum(energy_a, 1e-300, out=energy_a), out=energy_a)

    full, energy = runtime.both(lambda: np.fft.irfft(spectrum, nfft), energies)
    # -1 only where nothing is computed; each run of the circular result divided straight into place
    corr = np.empty(2 * n - 1)
    corr[: lo + n - 1] = -1.0
    corr[hi + n :] = -1.0
    done = 0
    for run in _circular_runs(full, lo + shift, count):
        start = lo + n - 1 + done
        np.divide(run, energy[done : done + len(run)], out=corr[start : start + len(run)])
        done += len(run)
    return corr, (b0, b1)


# The reference signal's spectrum, kept by a process that evaluates many cases (a workflow worker,
# the Python API): every case of a dataset whose estimate lies within the reference's span has the
# same grid and the same reference signal, so the same transform (a third of Step 1's time on the
# EuRoC grid). Reused only where the whole signal is equal, compared sample by sample: the same bits.
_SPECTRA: OrderedDict = runtime.register("steps.sync.spectra", OrderedDict())
_SPECTRA_LOCK = threading.Lock()  # a workflow on one core runs its jobs in threads
SPECTRA_MAX = 8  # entries (datasets); with SPECTRUM_BYTES, at most about 100 MB
SPECTRUM_BYTES = 12 << 20  # a larger one (a reference over about 5 minutes) is not kept


def _spectrum_key(a: np.ndarray, span_a: tuple[int, int], nfft: int) -> tuple | None:
    """Where a kept spectrum may be (a few samples tell most signals apart; equality decides); None
    where nothing is shared: one case in this process (`epa eval`), or a signal without support."""
    a0, a1 = span_a
    if runtime.spare_thread() or not 0 <= a0 <= a1 < len(a):
        return None
    return (nfft, len(a), a0, a1, float(a[a0]), float(a[(a0 + a1) // 2]), float(a[a1]))


def _kept_spectrum(a: np.ndarray, span_a: tuple[int, int], nfft: int) -> np.ndarray | None:
    """The kept np.fft.rfft(a, nfft) (not to be written to), or None."""
    key = _spectrum_key(a, span_a, nfft)
    if key is None:
        return None
    with _SPECTRA_LOCK:
        kept = _SPECTRA.get(key)
        if kept is None or not np.array_equal(kept[0], a):
            return None
        _SPECTRA.move_to_end(key)
        return kept[1]


def _keep_spectrum(a: np.ndarray, span_a: tuple[int, int], nfft: int, spectrum) -> None:
    """Keep ``spectrum`` (of ``a``) for the next case with the same reference signal."""
    key = _spectrum_key(a, span_a, nfft)
    if key is None or a.nbytes + spectrum.nbytes > SPECTRUM_BYTES:
        return
    spectrum.flags.writeable = False
    with _SPECTRA_LOCK:
        _SPECTRA[key] = (a.copy(), spectrum)
        _SPECTRA.move_to_end(key)
        while len(_SPECTRA) > SPECTRA_MAX:
            _SPECTRA.popitem(last=False)


def fft_length(least: int) -> int:
    """The smallest 2^i 3^j 5^k >= ``least``: among pocketfft's fastest lengths, and close above
    ``least``, where the next power of two may be nearly twice it."""
    best, fives = 1 << max(0, least - 1).bit_length(), 1
    while fives < best:
        threes = fives
        while threes < best:
            if (twos := max(1, -(-least // threes))) > 1:
                twos = 1 << (twos - 1).bit_length()
            best = min(best, twos * threes)
            threes *= 3
        fives *= 5
    return best


def _circular_runs(full: np.ndarray, first: int, count: int) -> tuple[np.ndarray, ...]:
    """full[(first + j) % len(full)] for j in range(count) (count <= len(full)) as one or two
    slices: a circular correlation holds its negative lags at its end."""
    start = first % len(full)
    end = start + count
    if end <= len(full):
        return (full[start:end],)
    return full[start:], full[: end - len(full)]


def _main_lobe(corr: np.ndarray, k: int) -> tuple[int, int, float]:
    """The main lobe around the peak ``k`` (from the nearest local minimum on its left to the nearest
    on its right) and the second-best peak: the highest local maximum outside it (0 when none)."""
    inner = corr[1:-1]
    minima = np.flatnonzero((inner <= corr[:-2]) & (inner <= corr[2:])) + 1
    maxima = _local_maxima(corr)
    left = minima[minima < k].max(initial=0)
    right = minima[minima > k].min(initial=len(corr) - 1)
    outside = maxima[(maxima < left) | (maxima > right)]
    return left, right, float(corr[outside].max()) if len(outside) else 0.0


def estimate_offset(
    ref: Trajectory,
    est: Trajectory,
    *,
    window: float = 2.0,
    resample_dt: float = 0.001,
    min_motion: float = 0.05,
    min_corr: float = 0.3,
    min_peak_ratio: float = 1.05,
    max_std: float = 0.01,
    speed_interval: float = 0.1,
    fallback: float = 0.0,
    max_samples: int = 2_000_000,
    speed=angular_speed,
    smooth_fft: bool = True,
) -> OffsetEstimate:
    """Time offset by cross-correlating angular-speed signals on a uniform timeline (FFT).

    The peak is refined below one sample with a parabola through its neighbours; its standard
    deviation comes from a delete-one-block jackknife (:func:`_jackknife_std`). When the motion is
    too weak, the peak weak, ambiguous, on the edge of the window or its deviation above
    ``max_std``, the fallback offset is returned with the status and the reason.

    Parameters
    ----------
    ref, est : Trajectory
        The reference and the estimate, each on its own clock.
    window : float
        Offsets searched, ±s; a clearly better match beyond it is named, never used.
    resample_dt, max_samples
        The correlation grid's step (s), coarsened so the grid has at most ``max_samples``.
    min_motion, min_corr, min_peak_ratio, max_std
        The thresholds of the statuses (rad/s, correlation, best/second peak, s).
    speed_interval : float
        Angular speed is measured over at least this interval (s).
    fallback : float
        The offset returned when the estimate is not trusted.
    speed : callable
        :func:`angular_speed` (rad/s), or :func:`linear_speed` (m/s, ``min_motion``'s unit then).
    smooth_fft : bool
        Transforms on a 5-smooth length over the supports; False: a power of two over the whole
        grid, as before 0.2 (evo's ``--step1`` keeps its bits). Returns an :class:`OffsetEstimate`.
    """

    signals = _speed_signals(ref, est, speed_interval, speed)
    if isinstance(signals, str):
        return _not_used(fallback, Step1Status.TOO_LITTLE_MOTION, signals)
    t_a, w_a, t_b, w_b = signals
    motion = dict(ref_motion_rad_s=float(np.std(w_a)), est_motion_rad_s=float(np.std(w_b)))
    refused = _signals_refused(t_a, t_b, motion, window, min_motion, speed is linear_speed)
    if refused is not None:
        return _not_used(fallback, *refused, **motion)
    w_a, w_b = _clip_spikes(w_a), _clip_spikes(w_b)
    dt, a, span_a, b, span_b = _correlation_grid(
        t_a, w_a, t_b, w_b, window, resample_dt, max_samples
    )
    if min(span_a[1] - span_a[0], span_b[1] - span_b[0]) + 1 < 4:
        reason = f"too few samples on the {dt:.3g} s correlation grid"
        return _not_used(fallback, Step1Status.NO_OVERLAP, reason, **motion)
    peak = _windowed_peak(a, span_a, b, span_b, window, dt, smooth_fft)
    found = peak.found(motion, dt)  # what sync.json records, trusted or not
    refused = _peak_refused(peak, window, min_corr, min_peak_ratio)
    if refused is not None:
        return _not_used(fallback, *refused, **found)
    # the jackknife looks for replicate peaks within the main lobe, at most 0.25 s either side
    reach = max(3, min(peak.k - peak.left, peak.right - peak.k, int(round(0.25 / dt))))
    found["std"] = std = _jackknife_std(a, b, peak.span_b, int(peak.lags[peak.k]), reach, dt)
    if not std <= max_std:
        return _not_used(
            fallback,
            Step1Status.UNCERTAIN,
            f"offset {peak.estimated * 1000:.1f} ms too uncertain: std {std * 1000:.3g} ms >"
            f" {max_std * 1000:.3g} ms",
            **found,
        )
    found.pop("estimated")
    return OffsetEstimate(
        offset=peak.estimated, estimated=peak.estimated, used=True, reason="estimated", **found
    )


def _signals_refused(t_a, t_b, motion: dict, window: float, min_motion: float, linear=False):
    """Why the speed signals cannot give an offset (a status and the reason), or None."""
    weakest = min(motion.values())
    if weakest < min_motion:
        what = (
            "linear motion (std of speed" if linear else "rotational motion (std of angular speed"
        )
        return (
            Step1Status.TOO_LITTLE_MOTION,
            f"too little {what} {weakest:.3g} {'m/s' if linear else 'rad/s'} < {min_motion})",
        )
    if t_b[0] > t_a[-1] + window or t_b[-1] < t_a[0] - window:
        return (
            Step1Status.NO_OVERLAP,
            f"the stamps do not overlap within the ±{window} s search window",
        )
    return None


def _not_used(fallback: float, status: Step1Status, reason: str, /, **kw) -> OffsetEstimate:
    """The fallback offset, with why the estimate (``estimated``, when there is one) is not used."""
    return OffsetEstimate(
        offset=fallback,
        estimated=kw.pop("estimated", None),
        used=False,
        reason=reason,
        status=status,
        **kw,
    )


def _correlation_grid(t_a, w_a, t_b, w_b, window: float, resample_dt: float, max_samples: int):
    """The uniform grid both signals are correlated on (the span of both, ±window) and its step
    ``dt``, coarsened to at most ``max_samples``; each signal on it with its support."""
    start = min(t_a[0], t_b[0]) - window
    end = max(t_a[-1], t_b[-1]) + window
    dt = max(resample_dt, (end - start) / max_samples)
    grid = start + dt * np.arange(int(np.ceil((end - start) / dt)) + 1)
    a, span_a = _on_grid(grid, t_a, w_a)
    b, span_b = _on_grid(grid, t_b, w_b)
    return dt, a, span_a, b, span_b


@dataclass
class _Peak:
    """The correlation's peak within the search window, and what the statuses judge it by."""

    lags: np.ndarray  # the lags within the window (grid steps) and the correlation at each
    corr: np.ndarray
    kmax: int  # the window's half-width (grid steps)
    k: int  # the peak's index in lags
    value: float
    estimated: float  # the peak's offset (s), refined below one grid step
    left: int  # the main lobe around the peak (indices in lags)
    right: int
    ratio: float  # the peak over the highest local maximum outside its main lobe
    best_beyond: float  # the best local maximum beyond the window (-1 when none)
    lag_beyond: float | None  # and its offset (s)
    span_b: tuple[int, int]  # the estimate signal's support on the grid

    def found(self, motion: dict, dt: float) -> dict:
        """The fields of :class:`OffsetEstimate` the peak gives, with the motion and the grid step."""
        return dict(
            curve_lag=self.lags * dt,
            curve_corr=self.corr,
            peak_corr=self.value,
            peak_ratio=self.ratio,
            beyond_window_corr=self.best_beyond,
            **motion,
            dt=dt,
            estimated=self.estimated,
        )


def _windowed_peak(a, span_a, b, span_b, window: float, dt: float, smooth_fft=True) -> _Peak:
    """The normalised correlation's peak within ±window, and the best match beyond it."""
    corr_all, span_b = _normalised_correlation(a, span_a, b, span_b, smooth_fft)
    zero = len(a) - 1  # the index of lag 0
    kmax = int(round(window / dt))
    maxima_all = _local_maxima(corr_all)
    beyond = maxima_all[np.abs(maxima_all - zero) > kmax]
    best_beyond = float(corr_all[beyond].max()) if len(beyond) else -1.0
    lag_beyond = float((beyond[np.argmax(corr_all[beyond])] - zero) * dt) if len(beyond) else None
    first, end = max(0, zero - kmax), min(len(corr_all), zero + kmax + 1)
    lags, corr = np.arange(first, end) - zero, corr_all[first:end]
    k, frac = _peak(corr)
    value = float(corr[k])
    left, right, second = _main_lobe(corr, k)
    return _Peak(
        lags=lags,
        corr=corr,
        kmax=kmax,
        k=k,
        value=value,
        estimated=float((lags[k] + frac) * dt),
        left=left,
        right=right,
        ratio=value / second if second > 0 else float("inf"),
        best_beyond=best_beyond,
        lag_beyond=lag_beyond,
        span_b=span_b,
    )


def _peak_refused(
    peak: _Peak, window: float, min_corr: float, min_peak_ratio: float
) -> tuple[Step1Status, str] | None:
    """Why the peak is not trusted as the offset (a status and the reason), or None."""
    if abs(peak.lags[peak.k]) >= peak.kmax - 1:  # never clamped: the offset may lie beyond
        return (
            Step1Status.AT_WINDOW_EDGE,
            f"correlation peak at the edge of the ±{window} s search window"
            " (the offset may lie outside it: widen sync.window)",
        )
    # Beyond the window only a clearly better and itself strong match counts: quasi-periodic motion (a
    # figure-8, a pendulum) repeats itself tens of seconds later almost as well, and that is not this
    # offset; nor is a weak bump of a run that diverged.
    if peak.best_beyond > max(peak.value * min_peak_ratio, min_corr):
        return (
            Step1Status.OUTSIDE_WINDOW,
            f"a better match ({peak.best_beyond:.3f} at {peak.lag_beyond:+.3f} s) lies outside the"
            f" ±{window} s search window than inside it ({peak.value:.3f}): widen sync.window",
        )
    if peak.value < min_corr:
        return Step1Status.WEAK_PEAK, f"correlation peak {peak.value:.3f} below {min_corr}"
    if peak.ratio < min_peak_ratio:
        return (
            Step1Status.AMBIGUOUS,
            f"ambiguous peak: best/second = {peak.ratio:.3f} < {min_peak_ratio}",
        )
    return None
