"""Step 1: time offset by cross-correlating angular speed; association of poses by timestamp.

Sign convention everywhere: ``offset`` is added to the estimate's stamps to bring them onto the
reference clock (``t_ref = t_est + offset``), as evo's ``offset_2``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from epa import geometry
from epa.errors import EpaError
from epa.trajectory import Trajectory

POLICIES = {"ov_eval": 0.02, "evo": 0.01}  # default max_diff (s) of each association policy


# ----------------------------------------------------------------------------- association
def nearest_from(stamps: np.ndarray, x: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """Index of the stamp nearest to each x among stamps[lo:], ties to the earlier one."""
    n = len(stamps)
    k = np.maximum(np.searchsorted(stamps, x, side="left"), lo)
    upper = np.minimum(k, n - 1)
    lower = np.maximum(k - 1, lo)
    d_up = np.where(k < n, np.abs(stamps[upper] - x), np.inf)
    d_lo = np.where(k - 1 >= lo, np.abs(x - stamps[lower]), np.inf)
    return np.where(d_lo <= d_up, lower, upper)


def associate_ov_eval(t_ref: np.ndarray, t_est: np.ndarray, max_diff: float, offset: float = 0.0):
    """ov_eval's greedy one-to-one association (AlignUtils::perform_association).

    For each estimate stamp in order: the nearest reference stamp not before the last match,
    kept when within max_diff. Vectorised: nearest over all, then re-resolve the estimates that
    collide with an earlier match until no collision is left.
    """
    x = t_est + offset
    n_est = len(x)
    lo = np.zeros(n_est, dtype=np.int64)
    while True:
        j = nearest_from(t_ref, x, lo)
        ok = np.abs(t_ref[j] - x) <= max_diff
        jm = np.where(ok, j, -1)
        prev = np.maximum.accumulate(np.concatenate([[-1], jm[:-1]]))
        clash = ok & (j <= prev)
        if not clash.any():
            break
        lo = np.where(clash, prev + 1, lo)
        beyond = lo >= len(t_ref)
        if beyond.any():
            lo = np.minimum(lo, len(t_ref) - 1)
            x = np.where(beyond, np.inf, x)  # nothing left to match these against
    i_est = np.flatnonzero(ok)
    return j[ok], i_est


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


def associate(ref: Trajectory, est: Trajectory, *, policy: str = "ov_eval", max_diff: float | None = None,
              offset: float = 0.0):
    """Indices (i_ref, i_est) of matched poses under the chosen policy."""
    if policy not in POLICIES:
        raise EpaError(f"unknown sync policy {policy!r}; choose one of {', '.join(POLICIES)}")
    max_diff = POLICIES[policy] if max_diff is None else max_diff
    fn = associate_ov_eval if policy == "ov_eval" else associate_evo
    return fn(ref.t, est.t, max_diff, offset)


# ----------------------------------------------------------------------------- Step 1
def angular_speed(traj: Trajectory, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """|log(R_i^T R_{i+step})| / dt, stamped at the midpoints (seed 004; step 1 = consecutive poses)."""
    i = np.arange(len(traj) - step)
    dt = traj.t[i + step] - traj.t[i]
    rel, _ = geometry.relative_motions(traj.q, traj.p, i, i + step)
    return traj.t[i] + dt / 2, geometry.quat_angle(rel) / dt


@dataclass
class OffsetEstimate:
    offset: float  # the offset used (estimated, or the configured fallback)
    estimated: float | None  # what the correlation found (None when it could not run)
    used: bool  # whether the estimate was trusted and used
    reason: str  # why it was (not) used
    peak_corr: float = float("nan")
    peak_ratio: float = float("nan")
    ref_motion_rad_s: float = float("nan")
    est_motion_rad_s: float = float("nan")
    dt: float = float("nan")
    curve_lag: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    curve_corr: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def to_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if not k.startswith("curve_")}


def _span(mask: np.ndarray) -> tuple[int, int]:
    idx = np.flatnonzero(mask)
    return int(idx[0]), int(idx[-1])


def _window_sums(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """sum(x[lo:hi + 1]) for every (lo, hi), clipped to the array."""
    c = np.concatenate([[0.0], np.cumsum(x)])
    n = len(x)
    return c[np.clip(hi + 1, 0, n)] - c[np.clip(lo, 0, n)]


def _clip_spikes(w: np.ndarray) -> np.ndarray:
    # Initialisation jumps (identity placeholder poses, resets) give one huge sample that would
    # dominate the correlation; cap at a robust multiple of the typical speed.
    med = np.median(w)
    mad = np.median(np.abs(w - med)) + 1e-12
    return np.minimum(w, med + 20 * mad)


def estimate_offset(ref: Trajectory, est: Trajectory, *, window: float = 2.0, resample_dt: float = 0.001,
                    min_motion: float = 0.05, min_corr: float = 0.3, min_peak_ratio: float = 1.05,
                    fallback: float = 0.0, max_samples: int = 2_000_000) -> OffsetEstimate:
    """Time offset by cross-correlating angular-speed signals on a uniform timeline (FFT).

    The peak is refined below one sample with a parabola through its neighbours. When the motion
    is too weak or the peak weak or ambiguous, the fallback offset is returned with the reason.
    """
    def fail(reason, **kw):
        return OffsetEstimate(offset=fallback, estimated=None, used=False, reason=reason, **kw)

    if len(ref) < 4 or len(est) < 4:
        return fail("too few poses for a correlation")
    # The coarser trajectory only sees chord rates over its own sample interval: measure the finer
    # one over the same interval (the magnitude of a mean rate is not the mean of magnitudes).
    dt_ref, dt_est = np.median(np.diff(ref.t)), np.median(np.diff(est.t))
    t_a, w_a = angular_speed(ref, max(1, int(round(dt_est / dt_ref))))
    t_b, w_b = angular_speed(est, max(1, int(round(dt_ref / dt_est))))
    motion_a, motion_b = float(np.std(w_a)), float(np.std(w_b))
    if min(motion_a, motion_b) < min_motion:
        return fail(f"too little rotational motion (std of angular speed {min(motion_a, motion_b):.3g}"
                    f" rad/s < {min_motion})", ref_motion_rad_s=motion_a, est_motion_rad_s=motion_b)
    if t_b[0] > t_a[-1] + window or t_b[-1] < t_a[0] - window:
        return fail(f"the stamps do not overlap within the ±{window} s search window",
                    ref_motion_rad_s=motion_a, est_motion_rad_s=motion_b)
    w_a, w_b = _clip_spikes(w_a), _clip_spikes(w_b)
    start = min(t_a[0], t_b[0]) - window
    end = max(t_a[-1], t_b[-1]) + window
    dt = max(resample_dt, (end - start) / max_samples)
    grid = start + dt * np.arange(int(np.ceil((end - start) / dt)) + 1)

    def on_grid(ts, w):
        inside = (grid >= ts[0]) & (grid <= ts[-1])
        s = np.interp(grid, ts, w)
        s = np.where(inside, s - w.mean(), 0.0)
        return s / (np.sqrt(np.sum(s * s)) + 1e-300), inside

    a, in_a = on_grid(t_a, w_a)
    b, in_b = on_grid(t_b, w_b)
    if in_a.sum() < 4 or in_b.sum() < 4:
        return fail(f"too few samples on the {dt:.3g} s correlation grid", ref_motion_rad_s=motion_a,
                    est_motion_rad_s=motion_b)
    n = len(grid)
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    # corr[k] = sum_m a[m + k] b[m]: the estimate signal shifted later by k samples matches the reference.
    spec = np.fft.rfft(a, nfft) * np.conj(np.fft.rfft(b, nfft))
    full = np.fft.irfft(spec, nfft)
    kmax = int(round(window / dt))
    lags = np.arange(-kmax, kmax + 1)
    corr = full[lags % nfft]
    # Normalised cross-correlation: divide each lag by the energy of both signals under the overlap.
    # The estimate usually covers only part of the reference, so that slice's energy changes with
    # the lag and, for slow motion, would tilt the peak by tens of ms. Supports are index intervals:
    # the energies are prefix-sum differences.
    (a0, a1), (b0, b1) = _span(in_a), _span(in_b)
    energy_a = _window_sums(a * a, b0 + lags, b1 + lags)  # a under the shifted support of b
    energy_b = _window_sums(b * b, a0 - lags, a1 - lags)  # b under the shifted support of a
    overlap = np.minimum(b1, a1 - lags) - np.maximum(b0, a0 - lags) + 1
    enough = overlap >= 0.5 * (min(a1 - a0, b1 - b0) + 1)  # at least half the shorter signal overlaps
    corr = np.where(enough, corr / np.sqrt(np.maximum(energy_a * energy_b, 1e-300)), -1.0)
    k = int(np.argmax(corr))
    peak = float(corr[k])
    frac = 0.0
    if 0 < k < len(corr) - 1:
        y0, y1, y2 = corr[k - 1], corr[k], corr[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5))
    estimated = float((lags[k] + frac) * dt)
    # Second-best peak: the highest local maximum of the whole curve outside the main lobe, the lobe
    # reaching from the nearest local minimum on the left of the peak to the nearest on the right.
    inner = corr[1:-1]
    minima = np.flatnonzero((inner <= corr[:-2]) & (inner <= corr[2:])) + 1
    maxima = np.flatnonzero((inner >= corr[:-2]) & (inner >= corr[2:])) + 1
    left = minima[minima < k].max(initial=0)
    right = minima[minima > k].min(initial=len(corr) - 1)
    outside = maxima[(maxima < left) | (maxima > right)]
    second = float(corr[outside].max()) if len(outside) else 0.0
    ratio = peak / second if second > 0 else float("inf")
    curve = dict(curve_lag=lags * dt, curve_corr=corr, peak_corr=peak, peak_ratio=ratio,
                 ref_motion_rad_s=motion_a, est_motion_rad_s=motion_b, dt=dt)
    at_edge = abs(lags[k]) >= kmax - 1
    if at_edge:
        return fail(f"correlation peak at the edge of the ±{window} s search window", **curve)
    if peak < min_corr:
        return fail(f"correlation peak {peak:.3f} below {min_corr}", **curve)
    if ratio < min_peak_ratio:
        return fail(f"ambiguous peak: best/second = {ratio:.3f} < {min_peak_ratio}", **curve)
    out = OffsetEstimate(offset=estimated, estimated=estimated, used=True, reason="estimated", **curve)
    return out
