import glob

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from epa.core import geometry
from epa.metrics import accuracy
from epa.readers import text
from epa.steps import sync


def brute_segment_pairs(d, length, tol=0.5):
    """ov_eval ResultTrajectory::compute_comparison_indices_length, literally."""
    out = []
    for idx in range(len(d)):
        best, best_err = -1, tol
        for i in range(idx, len(d)):
            err = abs(d[i] - (d[idx] + length))
            if err < best_err:
                best, best_err = i, err
        if best != -1:
            out.append((idx, best))
    return out


def test_segment_pairs_match_brute_force_on_euroc_grid(data):
    gt = text.read_trajectory(data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt")
    files = sorted(
        glob.glob(
            str(data / "uzh-rpg_rpg_trajectory_evaluation/results/**/*MH_01*/*.txt"), recursive=True
        )
    )
    assert len(files) >= 12
    for f in files[:12]:
        est = text.read_trajectory(f)
        ir, _ = sync.associate(gt, est, max_diff=0.02)
        d = geometry.path_distances(gt.p[ir])
        for length in (8, 16, 48):
            i, j = accuracy.segment_pairs(d, length)
            assert list(zip(i.tolist(), j.tolist())) == brute_segment_pairs(d, length), (f, length)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0, 3), min_size=2, max_size=60), st.floats(0.5, 8))
def test_segment_pairs_random_with_plateaus(steps, length):
    steps = [0.0 if s < 0.7 else s for s in steps]  # many zero-motion steps: plateaus and ties
    d = np.concatenate([[0.0], np.cumsum(steps)])
    i, j = accuracy.segment_pairs(d, length)
    assert list(zip(i.tolist(), j.tolist())) == brute_segment_pairs(d, length)


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.floats(0.001, 0.08), min_size=1, max_size=80),
    st.lists(st.floats(0.001, 0.08), min_size=1, max_size=80),
    st.floats(0.005, 0.05),
)
@example(dr=[0.0625], de=[0.03125], max_diff=0.03125)  # exactly max_diff apart: no match in ov_eval
# ov_eval's walk stops at a first stamp exactly max_diff before the estimate's: no match, though
# the next stamp is 0.0225 s away
@example(dr=[0.04, 0.0625], de=[0.08], max_diff=0.04)
def test_ov_eval_association_matches_greedy(dr, de, max_diff):
    t_ref, t_est = np.cumsum(dr), np.cumsum(de)
    i_ref, i_est = sync.associate_ov_eval(t_ref, t_est, max_diff)
    # ov_eval's AlignUtils::perform_association, line by line (its greedy pointer, one-to-one)
    literal = sync._associate_ov_eval_literal(t_ref, t_est, max_diff)
    assert list(zip(i_ref.tolist(), i_est.tolist())) == list(zip(*(a.tolist() for a in literal)))
    assert len(set(i_ref.tolist())) == len(i_ref)


def test_step1_recovers_injected_shifts_on_real_euroc_estimates(data):
    gts = {
        s: text.read_trajectory(data / f"rpng_open_vins/ov_data/euroc_mav/{f}")
        for s, f in [
            ("MH_01", "MH_01_easy.txt"),
            ("MH_03", "MH_03_medium.txt"),
            ("MH_04", "MH_04_difficult.txt"),
            ("MH_05", "MH_05_difficult.txt"),
        ]
    }
    files = [
        (next(s for s in gts if s in f), f, {})
        for f in glob.glob(
            str(data / "uzh-rpg_rpg_trajectory_evaluation/results/**/*.txt"), recursive=True
        )
    ]
    files += [
        (
            "MH_01",
            data / "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv",
            {},
        ),
        ("MH_01", data / "Gaiyh14_ORBSLAM3-EVO/f_dataset-MH01_monoi.txt", {}),
        (
            "MH_01",
            data / "SidSong01_modifiedOKVIS-for-benchmarking/trajectory_01.txt",
            {"time_unit": "sec_nsec"},
        ),
        ("MH_04", data / "qmy0519_open_vins-master/traj_estimate.txt", {}),
    ]
    assert len(files) == 54
    rng = np.random.default_rng(3)
    errors, z, uncertain = [], [], []
    for seq, f, kw in files:
        est = text.read_trajectory(f, **kw)
        base = sync.estimate_offset(gts[seq], est)
        shift = rng.uniform(-1, 1)
        moved = sync.estimate_offset(gts[seq], est.shifted(-shift))
        if not (base.used and moved.used):
            # rpg's bundle-adjusted keyframes (a few Hz) pin the offset only to 5-70 ms: said, not used
            assert "vislam_ba" in str(f) and "uncertain" in (base.status, moved.status), (
                f,
                base.reason,
                moved.reason,
            )
            uncertain.append(f)
            continue
        errors.append(abs(moved.offset - base.offset - shift))
        z.append(errors[-1] / np.hypot(base.std, moved.std))
    assert len(errors) >= 20 and len(uncertain) <= 40
    assert np.median(errors) <= 0.002 and np.max(errors) <= 0.005 and np.max(z) <= 3


def test_step1_with_a_spare_core_gives_the_same_bits():
    """`epa eval` runs Step 1's transforms and energies two at a time (runtime.both)."""
    from epa.core import runtime
    from epa.core.trajectory import Trajectory

    rng = np.random.default_rng(5)
    t = np.arange(0, 120, 0.005)
    yaw = np.cumsum(rng.normal(0, 0.01, len(t)))
    q = np.c_[0 * t, 0 * t, np.sin(yaw / 2), np.cos(yaw / 2)]
    traj = Trajectory(t, np.zeros((len(t), 3)), q)
    est = traj.select(np.arange(0, len(t), 4)).shifted(-0.137)
    one = sync.estimate_offset(traj, est)
    runtime.use_spare_thread()
    try:
        two = sync.estimate_offset(traj, est)
    finally:
        runtime.reset()
    assert one.used and one.to_dict() == two.to_dict()
    assert np.array_equal(one.curve_corr, two.curve_corr)


def test_step1_falls_back_without_motion():
    from epa.core.trajectory import Trajectory

    t = np.arange(0, 60, 0.05)
    still = Trajectory(t, np.c_[t, 0 * t, 0 * t], np.tile([0, 0, 0, 1.0], (len(t), 1)))
    out = sync.estimate_offset(still, still.shifted(0.3), fallback=0.01)
    assert not out.used and out.offset == 0.01 and "too little rotational motion" in out.reason


def test_step1_falls_back_on_repeated_stamps():
    """Every pose written twice (a file read with its order kept): the median stamp interval is 0,
    so there is no grid to correlate on: the fallback and why, not a division by zero."""
    from epa.core.trajectory import Trajectory

    t = np.repeat(np.arange(200) * 0.05, 2)
    yaw = np.repeat(np.cumsum(np.random.default_rng(0).normal(0, 0.3, 200)), 2)
    q = np.c_[0 * t, 0 * t, np.sin(yaw / 2), np.cos(yaw / 2)]
    twice = Trajectory(t, np.zeros((len(t), 3)), q)
    once = twice.select(np.arange(0, len(t), 2))
    out = sync.estimate_offset(twice, once.shifted(0.2), fallback=0.01)
    assert not out.used and out.offset == 0.01 and out.status == sync.Step1Status.TOO_LITTLE_MOTION
    assert out.reason.startswith(
        "the reference's median interval between consecutive stamps is 0 s"
    )
    out = sync.estimate_offset(once, twice.shifted(0.2))
    assert not out.used and out.reason.startswith("the estimate's median interval")


def test_step1_falls_back_where_a_side_spans_no_speed_interval():
    """A 4-pose reference 5 ms apart against an estimate 0.3 s apart: the reference's angular speed
    over the estimate's 0.3 s has no sample. The fallback and why, not an IndexError."""
    from epa.core.trajectory import Trajectory

    def turning(t):
        yaw = 0.5 * t
        return Trajectory(t, np.zeros((len(t), 3)), np.c_[0 * t, 0 * t, np.sin(yaw), np.cos(yaw)])

    short, sparse = turning(np.arange(4) * 0.005), turning(np.arange(40) * 0.3)
    out = sync.estimate_offset(short, sparse, fallback=0.02)
    assert not out.used and out.offset == 0.02 and out.status == sync.Step1Status.TOO_LITTLE_MOTION
    assert out.reason == "too few poses for a correlation: the reference's poses span no 0.3 s"
    assert "the estimate's poses span no 0.3 s" in sync.estimate_offset(sparse, short).reason


def test_step1_refuses_an_ambiguous_periodic_peak():
    from epa.core import geometry
    from epa.core.trajectory import Trajectory

    t = np.arange(0, 60, 0.005)
    yaw = 0.5 * np.sin(2 * np.pi * t / 0.8)  # every 0.8 s the motion repeats exactly
    traj = Trajectory.from_rp(t, np.stack([geometry.rot_z(y) for y in yaw]), np.zeros((len(t), 3)))
    est = traj.select(np.arange(0, len(t), 10)).shifted(-0.3)
    out = sync.estimate_offset(traj, est, fallback=0.0)
    assert not out.used and out.offset == 0.0 and "ambiguous" in out.reason


def _signal_on(n, span, rng):
    """A random signal zero outside its support (as _on_grid leaves it)."""
    x = np.zeros(n)
    x[span[0] : span[1] + 1] = rng.normal(size=span[1] - span[0] + 1)
    return x


@settings(max_examples=60, deadline=None)
@given(st.integers(8, 120), st.data())
def test_normalised_correlation_is_the_direct_formula(n, data):
    """Every lag's normalised correlation, the lags with too little overlap -1, against the sums
    written out (the FFT's rounding: 1e-12 of the signals' energy)."""
    spans = [
        tuple(sorted(data.draw(st.lists(st.integers(0, n - 1), min_size=2, max_size=2))))
        for _ in range(2)
    ]
    rng = np.random.default_rng(n)
    a, b = _signal_on(n, spans[0], rng), _signal_on(n, spans[1], rng)
    corr, span_b = sync._normalised_correlation(a, spans[0], b, spans[1])
    (a0, a1), (b0, b1) = spans
    shortest = min(a1 - a0, b1 - b0) + 1
    assert span_b == spans[1] and len(corr) == 2 * n - 1
    for i, k in enumerate(range(-(n - 1), n)):
        m = np.arange(max(0, -k), min(n, n - k))  # a[m + k] and b[m] both on the grid
        overlap = min(b1, a1 - k) - max(b0, a0 - k) + 1
        if overlap < 0.5 * shortest:
            assert corr[i] == -1.0
            continue
        in_a = (m + k >= a0) & (m + k <= a1)
        in_b = (m >= b0) & (m <= b1)
        num = np.sum(a[m + k] * b[m])
        ea, eb = np.sum(a[m + k] ** 2 * in_b), np.sum(b[m] ** 2 * in_a)
        whole_a, whole_b = np.sum(a**2), np.sum(b**2)
        # the FFT's rounding is relative to the whole signals' energies, not the overlap's; the
        # overlap's energies are prefix-sum differences, each off by up to about n eps of its
        # signal's whole energy (a 1e-8 tail of an 84 energy: 1e-6 of itself, found on the
        # restricted CPU path), which moves the correlation by half that, relatively
        drift = n * np.finfo(float).eps * (whole_a / ea + whole_b / eb) if ea * eb > 0 else 0.0
        tol = 1e-12 * np.sqrt(whole_a * whole_b) + abs(num) * drift
        assert abs(corr[i] * np.sqrt(ea * eb) - num) <= tol


def test_kept_reference_spectrum_gives_the_same_bits():
    """A process evaluating many cases keeps the reference signal's spectrum: a case with the same
    reference signal gets the bits a fresh transform gives, one with another signal (the same
    length, span and sampled values) is never given it, and the kept spectrum stays unwritten."""
    from epa.core import runtime

    runtime.reset()
    rng = np.random.default_rng(7)
    n, span_a, span_b = 400, (20, 380), (100, 300)
    a, b1, b2 = (_signal_on(n, s, rng) for s in (span_a, span_b, span_b))
    fresh = [sync._normalised_correlation(a, span_a, b, span_b)[0] for b in (b1, b2)]
    runtime.reset()
    for b, expected in zip((b1, b2, b1), (*fresh, fresh[0])):
        assert np.array_equal(sync._normalised_correlation(a, span_a, b, span_b)[0], expected)
    assert len(sync._SPECTRA) == 1
    ((nfft, *_),) = sync._SPECTRA.keys()
    ((kept_a, kept_spectrum),) = sync._SPECTRA.values()
    # the transform of a's support, on a 5-smooth length at least 1.5 times it
    assert nfft == sync.fft_length(int(1.5 * (span_a[1] - span_a[0] + 1)) + 1)
    support = a[span_a[0] : span_a[1] + 1]
    assert np.array_equal(kept_spectrum, np.fft.rfft(support, nfft))
    other = a.copy()
    other[span_a[0] + 1] += 1.0  # not one of the samples the key looks at
    got = sync._normalised_correlation(other, span_a, b1, span_b)[0]
    runtime.reset()
    assert np.array_equal(got, sync._normalised_correlation(other, span_a, b1, span_b)[0])
    runtime.reset()
    runtime.use_spare_thread()  # one case in the process (`epa eval`): nothing kept
    try:
        sync._normalised_correlation(a, span_a, b1, span_b)
        assert not sync._SPECTRA
    finally:
        runtime.reset()


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 40), st.integers(-50, 50), st.integers(0, 45), st.integers(1, 60))
def test_window_sums_and_circular_runs_by_slices(n, lo, width, count):
    x = np.random.default_rng(n).normal(size=n)
    want = [x[max(lo + j, 0) : max(lo + j + width, 0)].sum() for j in range(count)]
    got = sync._window_sums(x.copy(), lo, width, count)
    assert np.allclose(got, want, rtol=0, atol=1e-12)
    # bit for bit the differences of the padded prefix sum the runs replaced
    before, after = max(1, 1 - lo), max(0, lo + width + count - 1 - n)
    c = np.cumsum(x)
    prefix = np.concatenate([np.zeros(before), c, np.full(after, c[-1])])
    start = lo - 1 + before
    padded = prefix[start + width : start + width + count] - prefix[start : start + count]
    assert np.array_equal(got, padded)
    assert np.array_equal(sync._window_sums(x.copy(), lo, width, count, in_place=True), padded)
    full = np.arange(n, dtype=float)
    if count <= n:
        runs = np.concatenate(sync._circular_runs(full, lo, count))
        assert runs.tolist() == [(lo + j) % n for j in range(count)]


def test_coarse_sums_are_the_reshaped_sums_bit_for_bit():
    x = np.random.default_rng(3).normal(size=10_007)
    for q in (1, 2, 5, 7):
        n = len(x) // q * q
        assert np.array_equal(sync._coarse(x, q), x[:n].reshape(-1, q).sum(axis=1))


def test_jackknife_is_the_delete_one_block_replicates_written_out():
    """The jackknife's replicate peaks from sums written out per block and lag (1e-12 s)."""
    rng = np.random.default_rng(7)
    t = np.arange(6000) * 0.001
    wave = np.convolve(rng.normal(size=len(t) + 400), np.hanning(400), "valid")[: len(t)]
    a = np.where((t > 0.3) & (t < 5.7), wave, 0.0)
    b = np.where((t > 1.0) & (t < 5.0), np.roll(wave, 20) + 0.3 * rng.normal(size=len(t)), 0.0)
    span = (int(np.flatnonzero(b)[0]), int(np.flatnonzero(b)[-1]))
    got = sync._jackknife_std(a, b, span, peak_lag=-20, reach=250, dt=0.001)
    q = 5
    a_c, b_c = sync._coarse(a, q), sync._coarse(b, q)
    b0, b1 = span[0] // q, span[1] // q
    edges = np.linspace(0, b1 + 1 - b0, sync.JACKKNIFE_BLOCKS + 1).astype(int) + b0
    lags = np.arange(-4 - 16, -4 + 17)
    shifts = []
    for drop in range(sync.JACKKNIFE_BLOCKS):
        m = np.r_[b0 : edges[drop], edges[drop + 1] : b1 + 1]
        curve = []
        for lag in lags:
            seg = np.where(
                (m + lag >= 0) & (m + lag < len(a_c)), a_c[np.clip(m + lag, 0, len(a_c) - 1)], 0.0
            )
            energy = np.sum(seg**2) * np.sum(np.where(seg != 0.0, b_c[m] ** 2, 0.0))
            curve.append(np.sum(seg * b_c[m]) / np.sqrt(energy))
        k, frac = sync._peak(np.array(curve))
        assert 0 < k < len(lags) - 1
        shifts.append((lags[k] + frac) * q * 0.001)
    jack = np.sqrt(
        (sync.JACKKNIFE_BLOCKS - 1)
        / sync.JACKKNIFE_BLOCKS
        * np.sum((shifts - np.mean(shifts)) ** 2)
    )
    assert abs(got - np.hypot(jack, 0.001 / np.sqrt(12.0))) <= 1e-12


def test_angular_and_linear_speed_are_the_relative_motions():
    from epa.core.trajectory import Trajectory

    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.004, 0.006, 500))
    q = geometry.normalize_quat(rng.normal(size=(500, 4)))
    traj = Trajectory(t, rng.normal(size=(500, 3)), q)
    for step in (1, 7):
        i = np.arange(len(t) - step)
        dt = t[i + step] - t[i]
        rel, _ = geometry.relative_motions(q, traj.p, i, i + step)
        mid, w = sync.angular_speed(traj, step)
        assert np.array_equal(mid, t[i] + dt / 2)
        assert np.array_equal(w, geometry.quat_angle(rel) / dt)
        _, v = sync.linear_speed(traj, step)
        assert np.array_equal(v, np.linalg.norm(traj.p[i + step] - traj.p[i], axis=1) / dt)


def test_relative_angles_are_the_conjugate_products_angles_bit_for_bit():
    """relative_angles folds the conjugate's signs into its differences: the same bits as the
    product of the negated rows, also for repeated and axis-aligned orientations (zero terms)."""
    rng = np.random.default_rng(5)
    q = geometry.normalize_quat(rng.normal(size=(400, 4)))
    q[100:140] = q[100]  # repeated poses: zero relative rotation
    q[200:240] = [0.0, 0.0, np.sin(0.1), np.cos(0.1)]
    q[300:340, :3] *= 1e-9  # tiny angles
    q = geometry.normalize_quat(q)
    x, y, z, w = geometry.component_rows(q)
    for step in (1, 3, 17):
        conj = (-x[:-step], -y[:-step], -z[:-step], w[:-step])
        want = geometry.rows_angle(*geometry._mul_rows(conj, (c[step:] for c in (x, y, z, w))))
        assert np.array_equal(geometry.relative_angles(q, step), want)


def test_selecting_every_pose_gives_c_ordered_arrays_as_the_gather_does():
    """Every pose matched (0, 1, ..., n - 1) gives the same values in the same C-ordered arrays as
    the gather gives for any other index array: a strided column of the source is copied, never a
    view of it; an array C-ordered already is the source's own (a million poses' t and p are not
    held twice)."""
    from epa.core.trajectory import Trajectory

    rng = np.random.default_rng(2)
    table = rng.normal(size=(50, 8))  # columns of one table: strided, as a parsed file gives them
    cov = rng.normal(size=(50, 3, 3))  # C-ordered
    traj = Trajectory(table[:, 0], table[:, 1:4], table[:, 4:8], cov_rot=cov, cov_pos=2 * cov)
    for idx in (np.arange(50), np.arange(50, dtype=np.int32), np.r_[0:25, 26:50, 49]):
        got = traj.select(idx)
        every = len(idx) == 50 and (idx == np.arange(50)).all()
        for name in ("t", "p", "q", "cov_rot", "cov_pos"):
            x, source = getattr(got, name), getattr(traj, name)
            assert x.flags.c_contiguous and np.array_equal(x, source[idx])
            own = every and source.flags.c_contiguous
            assert (x is source) if own else not np.shares_memory(x, source)
        assert every == (got.cov_rot is cov)  # the one C-ordered source array here


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.floats(0, 3), min_size=1, max_size=50),
    st.floats(0.5, 8),
    st.booleans(),
    st.integers(0, 2),
    st.sampled_from([None, 1, 3, 7]),
)
def test_closest_pairs_is_the_first_closest_by_scan(steps, delta, strict, skip, block):
    """closest_pairs against the nested scan it replaces, with plateaus (equal distances) and both
    tolerance rules: the first closest j >= i + skip; also in small blocks of starts (each searched
    on its own stretch of d), whose edges the usual block of 32,768 starts never shows here."""
    from unittest import mock

    from epa.core import stamps

    d = np.concatenate([[0.0], np.cumsum([0.0 if s < 1.0 else s for s in steps])])
    tol = 0.3 * delta
    want = []
    for i in range(len(d)):
        best, err = -1, np.inf
        for j in range(i + skip, len(d)):
            e = abs(d[j] - (d[i] + delta))
            if e < err:
                best, err = j, e
        if best >= 0 and (err < tol if strict else err <= tol):
            want.append((i, best))
    with mock.patch.object(stamps, "STARTS_PER_BLOCK", block or stamps.STARTS_PER_BLOCK):
        i, j = stamps.closest_pairs(d, delta, tol, strict=strict, skip=skip)
    assert list(zip(i.tolist(), j.tolist())) == want


def test_smooth_and_power_of_two_transforms_agree_up_to_rounding():
    """The 5-smooth transform over the supports and the power of two over the whole grid (evo's
    --step1) give the same correlation at every lag, -1 where nothing is computed, up to the FFT's
    rounding (relative to the whole signals' unit energy)."""
    rng = np.random.default_rng(11)
    for n, span_a, span_b in ((400, (20, 380), (100, 300)), (301, (150, 300), (0, 280))):
        a, b = _signal_on(n, span_a, rng), _signal_on(n, span_b, rng)
        smooth = sync._normalised_correlation(a, span_a, b, span_b, smooth_fft=True)[0]
        power = sync._normalised_correlation(a, span_a, b, span_b, smooth_fft=False)[0]
        assert np.array_equal(smooth == -1.0, power == -1.0)
        assert np.abs(smooth - power).max() < 1e-12
