"""Property tests: readers never raise anything but the documented error, and write -> read round trips."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st

from epa.artifacts import files
from epa.core import geometry, ranks, stamps
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import accuracy
from epa.readers import text
from epa.steps import align as alignment
from epa.steps import sync

FUZZ = hsettings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
ROW = "1.5 0 0 0 0 0 0 1\n"

# bytes that look like trajectory files more often than random ones do
numberish = st.lists(
    st.sampled_from(
        [
            "1",
            "2.5",
            "-3",
            "1e9",
            "1e300",
            "nan",
            "inf",
            "0",
            ",",
            " ",
            "\t",
            "\n",
            "#",
            "%",
            "t",
            "x",
            "qw",
            ";",
            "\ufeff",
            "\x00",
            ".",
            "e",
            "1403636592.96214",
        ]
    ),
    max_size=80,
).map(lambda toks: "".join(toks).encode())


@FUZZ
@given(
    content=st.one_of(st.binary(max_size=400), numberish),
    suffix=st.sampled_from([".txt", ".csv", ".tum"]),
    fmt=st.sampled_from(text.FORMATS),
    time_unit=st.sampled_from(text.TIME_UNITS),
)
def test_no_byte_string_makes_a_reader_raise_anything_but_epa_error(
    tmp_path, content, suffix, fmt, time_unit
):
    path = tmp_path / f"f{suffix}"
    path.write_bytes(content)
    try:
        traj = text.read_trajectory(path, fmt, time_unit=time_unit)
    except EpaError as exc:
        assert "\n" not in exc.one_line() and exc.one_line().startswith(str(path))
        return
    # what reads must be a usable trajectory: unit quaternions, or none at all (position only)
    assert len(traj) >= 2 and np.all(np.diff(traj.t) > 0) and np.isfinite(traj.p).all()
    if traj.position_only:
        assert np.isnan(traj.q).all()
    else:
        np.testing.assert_allclose(np.linalg.norm(traj.q, axis=1), 1.0, atol=1e-9)


finite = st.floats(-1e4, 1e4, allow_nan=False)


@hsettings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(n=st.integers(2, 40), seed=st.integers(0, 2**32 - 1))
def test_tum_write_read_round_trip_is_exact(tmp_path, n, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(1e-3, 1.0, n)) + rng.uniform(0, 2e9)
    q = rng.normal(size=(n, 4))
    traj = Trajectory(
        t, rng.uniform(-1e4, 1e4, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)
    )
    files.write_tum(tmp_path / "a.tum", traj)
    back = text.read_trajectory(tmp_path / "a.tum")
    np.testing.assert_array_equal(back.t, traj.t if t.max() < text.NS_THRESHOLD else back.t)
    np.testing.assert_array_equal(back.p, traj.p)
    np.testing.assert_allclose(back.q, traj.q, rtol=0, atol=1e-15)


token = st.sampled_from(
    ["1", "2.5", "-3", "1e9", "1e13", "1e300", "nan", "inf", "0", "", "x", "1.2.3", "1403636592.5"]
)


@FUZZ
@given(
    rows=st.lists(st.lists(token, min_size=1, max_size=21), min_size=0, max_size=12),
    sep=st.sampled_from([" ", ",", "\t", ";"]),
    header=st.sampled_from(
        ["", "# t x y z qx qy qz qw\n", "t,x,y,z,qw,qx,qy,qz\n", "#timestamp [ns],a\n"]
    ),
    suffix=st.sampled_from([".txt", ".csv"]),
    fmt=st.sampled_from(text.FORMATS),
    time_unit=st.sampled_from(text.TIME_UNITS),
    unsorted=st.sampled_from(["error", "sort"]),
)
def test_table_shaped_garbage_is_read_or_refused_cleanly(
    tmp_path, rows, sep, header, suffix, fmt, time_unit, unsorted
):
    path = tmp_path / f"f{suffix}"
    path.write_text(header + "".join(sep.join(r) + "\n" for r in rows))
    try:
        traj = text.read_trajectory(path, fmt, time_unit=time_unit, on_unsorted=unsorted)
    except EpaError as exc:
        assert "\n" not in exc.one_line() and exc.one_line().startswith(str(path))
        return
    assert len(traj) >= 2 and np.all(np.diff(traj.t) > 0) and np.isfinite(traj.p).all()


# ----------------------------------------------------------------------------- every format round trips
def random_trajectory(rng, n, with_cov=False, ns_exact=False):
    t = np.cumsum(rng.uniform(1e-3, 1.0, n)) + rng.uniform(0, 2e9)
    if ns_exact:  # EuRoC stores integer nanoseconds
        t = np.round(t * 1e9) / 1e9
    q = rng.normal(size=(n, 4))
    cov = {}
    if with_cov:
        a, b = rng.normal(size=(n, 3, 3)), rng.normal(size=(n, 3, 3))
        cov = {
            "cov_rot": a @ a.transpose(0, 2, 1) * 1e-4,
            "cov_pos": b @ b.transpose(0, 2, 1) * 1e-2,
        }
    return Trajectory(
        t, rng.uniform(-1e4, 1e4, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True), **cov
    )


@hsettings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    n=st.integers(2, 30),
    seed=st.integers(0, 2**32 - 1),
    fmt=st.sampled_from(["tum", "kitti", "euroc", "openvins", "csv", "position"]),
    with_cov=st.booleans(),
)
def test_every_format_round_trips(tmp_path, n, seed, fmt, with_cov):
    traj = random_trajectory(
        np.random.default_rng(seed),
        n,
        with_cov=with_cov or fmt == "openvins",
        ns_exact=fmt == "euroc",
    )
    path = tmp_path / ("a.csv" if fmt in ("euroc", "csv") else "a.txt")
    files.write_trajectory(path, traj, fmt)
    back = text.read_trajectory(path)
    if fmt == "position":  # the positions, and no orientation
        assert back.position_only and np.array_equal(back.t, traj.t)
        np.testing.assert_array_equal(back.p, traj.p)
        files.write_trajectory(tmp_path / "b.csv", back, "csv")
        again = text.read_trajectory(tmp_path / "b.csv")
        assert again.position_only and np.array_equal(again.p, traj.p)
        return
    # ns in float64
    np.testing.assert_allclose(back.t, traj.t, rtol=0, atol=3e-7 if fmt == "euroc" else 0)
    np.testing.assert_array_equal(back.p, traj.p)
    # same rotation (q and -q are one rotation; KITTI stores the matrix)
    np.testing.assert_allclose(np.abs(np.sum(back.q * traj.q, axis=1)), 1.0, rtol=0, atol=1e-12)
    if traj.cov_rot is not None and fmt in ("openvins", "csv"):
        np.testing.assert_array_equal(back.cov_rot, traj.cov_rot)
        np.testing.assert_array_equal(back.cov_pos, traj.cov_pos)


# ----------------------------------------------------------------------------- invariances and recoveries
def smooth_motion(rng, t):
    """Random smooth 3-D motion: a few sinusoids per axis, for position and rotation vector."""

    def signal(scale):
        f = rng.uniform(0.05, 0.6, (3, 4))
        a = rng.normal(0, scale, (3, 4))
        ph = rng.uniform(0, 2 * np.pi, (3, 4))
        return np.einsum(
            "ck,ckn->nc", a, np.sin(2 * np.pi * f[:, :, None] * t[None, None, :] + ph[:, :, None])
        )

    return geometry.so3_exp(signal(0.6)), signal(4.0) + np.outer(t, rng.normal(0, 0.3, 3))


def random_rigid(rng, scale=False):
    return alignment.Similarity(
        geometry.so3_exp(rng.normal(0, 1.5, 3)),
        rng.normal(0, 50, 3),
        float(rng.uniform(0.2, 5)) if scale else 1.0,
    )


PROPS = hsettings(max_examples=25, deadline=None)


@PROPS
@given(seed=st.integers(0, 2**32 - 1))
def test_metrics_are_invariant_under_a_common_rigid_transform(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 0.1)
    r, p = smooth_motion(rng, t)
    ref = Trajectory.from_rp(t, r, p)
    noisy = Trajectory.from_rp(
        t, r @ geometry.so3_exp(rng.normal(0, 0.02, (len(t), 3))), p + rng.normal(0, 0.1, p.shape)
    )
    est = random_rigid(rng).apply(noisy)  # the estimate in its own world frame
    g = random_rigid(rng)  # moved together: nothing the metrics report may change

    def evaluate(ref, est):
        aligned = alignment.fit(ref, est, method="se3").apply(est)
        return accuracy.evaluate(ref, aligned, segments=(8, 16))[0]

    a, b = evaluate(ref, est), evaluate(g.apply(ref), g.apply(est))
    for key in ("ate", "rpe_time_1s"):
        for part in ("trans_m", "rot_deg"):
            assert np.isclose(a[key][part]["rmse"], b[key][part]["rmse"], rtol=1e-7, atol=1e-9)
    for seg in ("8", "16"):
        assert a["rpe_distance"][seg]["trans_m"]["n"] == b["rpe_distance"][seg]["trans_m"]["n"]
        assert np.isclose(
            a["rpe_distance"][seg]["trans_m"]["mean"],
            b["rpe_distance"][seg]["trans_m"]["mean"],
            rtol=1e-7,
            atol=1e-9,
            equal_nan=True,
        )


@PROPS
@given(seed=st.integers(0, 2**32 - 1), method=st.sampled_from(["se3", "sim3"]))
def test_alignment_recovers_a_random_transform(seed, method):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 30, 0.1)
    r, p = smooth_motion(rng, t)
    ref = Trajectory.from_rp(t, r, p)
    g = random_rigid(rng, scale=method == "sim3")
    inverse = alignment.Similarity(g.R.T, -g.R.T @ g.t / g.s, 1 / g.s)
    fit = alignment.fit(ref, inverse.apply(ref), method=method)
    np.testing.assert_allclose(fit.R, g.R, atol=1e-9)
    np.testing.assert_allclose(fit.t, g.t, atol=1e-7)
    assert np.isclose(fit.s, g.s, rtol=1e-9)


@hsettings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), offset=st.floats(-1.5, 1.5))
def test_step1_recovers_a_random_offset_on_random_smooth_motion(seed, offset):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 1 / 100)
    r, p = smooth_motion(rng, t)
    ref = Trajectory.from_rp(t, r, p)
    te = np.arange(2, 58, 1 / 20)
    # same motion, read offset later
    re, pe = smooth_motion(np.random.default_rng(seed), te + offset)
    est = Trajectory.from_rp(te, re, pe)
    out = sync.estimate_offset(ref, est, window=2.0)
    if not out.used:  # a few sinusoids can repeat within the window (seed 576: two peaks 3 % apart)
        assert out.status == "ambiguous" and out.peak_ratio < 1.05, out.reason
        return
    assert abs(out.offset - offset) < 2e-3


def test_geometry_fast_paths_give_numpys_bits():
    """geometry's row-wise helpers and the contiguous-component paths of quat_mul and quat_rotate
    are written to compute the same operations in the same order as the numpy expressions they
    replace (issue 34): equal bit for bit, signs of zero included, on random and edge values."""
    rng = np.random.default_rng(34)
    n = 20_000
    v = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-8, 4, size=(n, 1))
    v[:3] = [[0.0, -0.0, 0.0], [-0.0, 0.0, -0.0], [1e-300, 0.0, -1e-300]]
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[3], q[4] = [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, -1.0]
    p = q[::-1].copy()

    def same(a, b):
        return (
            a.shape == b.shape
            and np.array_equal(a, b)
            and np.array_equal(np.signbit(a), np.signbit(b))
        )

    assert same(geometry.norms(v), np.linalg.norm(v, axis=-1))
    assert same(geometry.norms(q), np.linalg.norm(q, axis=-1))
    assert same(geometry.dots(q, p), np.sum(q * p, axis=-1))
    assert same(geometry.cross(v, v[::-1]), np.cross(v, v[::-1]))
    # the contiguous path (rows matched) against the general path (a broadcast row at a time)
    assert same(geometry.quat_mul(q, p), geometry.quat_mul(q[:, None, :], p[:, None, :])[:, 0])
    assert same(
        geometry.quat_rotate(q, v), geometry.quat_rotate(q[:, None, :], v[:, None, :])[:, 0]
    )
    assert same(geometry.quat_log(q), geometry.quat_log(q[:, None, :])[:, 0])


def _relative_errors_before(d, p_ref, p_est, i, j):
    """relative_errors as it was written before pair_rows (issue 34): numpy's row gathers."""
    di = d[i]
    angle = geometry.quat_angle(geometry.quat_mul(di, geometry.quat_conj(d[j])))
    t_err = geometry.quat_rotate(di, p_est[j] - p_est[i]) - (p_ref[j] - p_ref[i])
    return np.degrees(angle), np.linalg.norm(t_err, axis=-1)


def test_pair_errors_give_the_previous_bits():
    """The relative errors from pair_rows (gathered rows, runs of starts as views, blocks) are the
    previous formula's bit for bit: on random, repeated, reversed and run-like index sets longer
    than a block, with the identity, its negative and equal orientations among the poses."""
    rng = np.random.default_rng(341)
    n = geometry.ROW_BLOCK + 3 * geometry.PAIR_BLOCK + 17  # pair_rows in two blocks too
    q_ref, q_est = (rng.normal(size=(n, 4)) for _ in range(2))
    q_ref /= np.linalg.norm(q_ref, axis=1, keepdims=True)
    q_est /= np.linalg.norm(q_est, axis=1, keepdims=True)
    q_est[: n // 3] = q_ref[: n // 3]
    q_ref[5], q_est[5] = [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, -1.0]
    p_ref = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-6, 4, size=(n, 1))
    p_est = p_ref + rng.normal(size=(n, 3)) * 1e-3
    d = geometry.pose_discrepancy(q_ref, q_est)
    rows = geometry.pair_rows(None, p_ref, p_est, q=(q_ref, q_est))
    assert np.array_equal(rows, geometry.pair_rows(d, p_ref, p_est))
    run = np.arange(n - 40)
    sets = [
        (rng.integers(0, n, 2 * n), rng.integers(0, n, 2 * n)),
        (run, run + 40),
        (np.r_[run[:500], run], np.r_[run[:500] + 3, run + 1]),
        (run[::-1].copy(), run),
        (np.arange(0), np.arange(0)),
    ]
    for i, j in sets:
        before = _relative_errors_before(d, p_ref, p_est, i, j)
        for after in (
            geometry.pair_errors(rows, i, j),
            geometry.relative_errors(d, p_ref, p_est, i, j),
        ):
            assert all(np.array_equal(a, b) for a, b in zip(before, after))


def _unit_quaternion_pairs(rng, n: int):
    """n random unit quaternions on each side, the first 100 equal (zero error)."""
    q_ref, q_est = (rng.normal(size=(n, 4)) for _ in range(2))
    q_ref /= np.linalg.norm(q_ref, axis=1, keepdims=True)
    q_est /= np.linalg.norm(q_est, axis=1, keepdims=True)
    q_est[:100] = q_ref[:100]
    return q_ref, q_est


def test_ate_2d_gives_the_previous_bits():
    """ATE 2D's yaw in blocks, only the z of the log, is the whole arrays' quat_mul, quat_conj and
    quat_log_rows' bit for bit (more poses than a block; the identity and its negative among them)."""
    from epa.core.trajectory import Trajectory
    from epa.metrics import ate_2d

    rng = np.random.default_rng(343)
    n = geometry.ROW_BLOCK + 17
    q_ref, q_est = _unit_quaternion_pairs(rng, n)
    q_ref[5], q_est[5] = [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, -1.0]
    t = np.arange(n) * 0.01
    ref, est = (
        Trajectory(t, rng.normal(size=(n, 3)), q_ref),
        Trajectory(t, rng.normal(size=(n, 3)), q_est),
    )
    before = np.degrees(
        geometry.quat_log_rows(geometry.quat_mul(est.q, geometry.quat_conj(ref.q)))[2]
    )
    assert np.array_equal(ate_2d.errors(ref, est)[0], before)


def test_ate_2d_from_pair_rows_gives_its_own_bits():
    """ATE 2D's yaw and planar error from the metrics stage's pair_rows (D the conjugate of its
    quaternion) are its own product's bit for bit: signed zeros (equal and axis-aligned
    orientations), NaN and infinite components, more poses than a block."""
    from epa.core.trajectory import Trajectory
    from epa.metrics import ate_2d

    rng = np.random.default_rng(344)
    n = geometry.ROW_BLOCK + 517
    q_ref, q_est = _unit_quaternion_pairs(rng, n)
    signs = [0.0, -0.0, 1.0, -1.0]
    q_ref[100:300], q_est[100:300] = (rng.choice(signs, size=(200, 4)) for _ in range(2))
    q_est[300:310], q_ref[310:315, 2] = np.nan, np.inf
    p_ref, p_est = (rng.normal(size=(n, 3)) for _ in range(2))
    p_est[:50], p_est[50:55] = p_ref[:50], np.nan
    t = np.arange(n) * 0.01
    ref, est = Trajectory(t, p_ref, q_ref), Trajectory(t, p_est, q_est)
    rows = geometry.pair_rows(None, p_ref, p_est, q=(q_ref, q_est))
    with np.errstate(invalid="ignore"):
        for own, shared in zip(ate_2d.errors(ref, est), ate_2d.errors(ref, est, rows)):
            assert np.array_equal(own.view(np.int64), shared.view(np.int64))


def test_run_starts_and_order_statistics_are_the_searches_they_replace():
    """run_starts is searchsorted(d, d, 'left') on non-decreasing d (ties, NaN); the median from
    order_statistics is np.median bit for bit (ties, zeros of both signs, inf, sorted and periodic
    samples either side of the sample size that switches to the bracket)."""
    rng = np.random.default_rng(342)
    for n in (1, 2, 7, 1000):
        steps = np.where(rng.random(n) < 0.4, 0.0, rng.random(n))
        for d in (np.cumsum(steps), np.zeros(n), np.r_[np.cumsum(steps)[:-1], np.nan]):
            assert np.array_equal(stamps.run_starts(d), np.searchsorted(d, d, side="left"))
    size = 4 * ranks.SELECT_SAMPLE
    for n in (1, 2, 3, size, size + 1, size + 2, 50_001, 100_000):
        x = rng.normal(size=n)
        for sample in (
            x,
            np.abs(x),
            np.sort(x),
            np.round(x, 1),
            np.where(x < 0, -0.0, 0.0),
            np.sin(np.arange(n) / 7.0),
            np.where(np.arange(n) % 97 == 0, np.inf, x),
        ):
            with np.errstate(invalid="ignore"):  # the std of a sample with inf
                got = accuracy.stats(sample)
                want = {
                    "median": np.median(sample),
                    "mean": np.mean(sample),
                    "rmse": np.sqrt(np.mean(sample * sample)),
                    "std": np.std(sample),
                }
            for key, a in want.items():  # numpy's statistics bit for bit
                b = got[key]
                assert str(a) == str(b) and np.signbit(a) == np.signbit(b), (n, key, a, b)


def test_pair_errors_refuses_a_pair_index_out_of_range():
    """Its gathers clip (for speed), so a bad index must fail before them, not pair a pose with
    the last or the first one."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(3, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rows = geometry.pair_rows(q, rng.normal(size=(3, 3)), rng.normal(size=(3, 3)))
    assert len(geometry.pair_errors(rows, [0, 1], [1, 2])[0]) == 2
    for i, j in (([0, 2], [1, 7]), ([0, 2], [-1, 2]), ([3], [0])):
        with pytest.raises(IndexError, match="out of range for 3 poses"):
            geometry.pair_errors(rows, i, j)


def test_path_distances_in_blocks_gives_the_whole_arrays_bits():
    """path_distances in blocks of poses, each carried on from the one before, is the whole
    difference's norms and cumsum bit for bit: over block edges, from strided and Fortran-ordered
    positions, with zero steps, a NaN and scales from 1e-3 to 1e3; an empty and a one-pose path."""
    rng = np.random.default_rng(345)
    n = 2 * geometry.ROW_BLOCK + 3
    p = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, (n, 1))
    p[100:110] = p[100]  # standing still
    p[geometry.ROW_BLOCK + 1, 2] = np.nan
    table = np.zeros((n, 8))
    table[:, 1:4] = p
    for positions in (p, np.asfortranarray(p), table[:, 1:4]):
        whole = np.concatenate(
            [[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))]
        )
        got = geometry.path_distances(positions)
        assert np.array_equal(got.view(np.int64), whole.view(np.int64))
    assert geometry.path_distances(np.zeros((0, 3))).shape == (0,)
    assert geometry.path_distances(np.ones((1, 3))).tolist() == [0.0]
    assert geometry.path_distances(np.array([[0.0, 0, 0], [3, 4, 0], [3, 4, 12]])).tolist() == [
        0.0,
        5.0,
        17.0,
    ]
