"""Steps 1-3 on simulated motion with known offset, extrinsic and scale, including degenerate motion."""

import numpy as np
import pytest

from epa import simulate
from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.steps import align as alignment
from epa.steps import calibrate as calibration
from epa.steps import sync


def case(
    seq="handheld_office",
    offset=0.037,
    rot=(0.3, -1.1, 0.7),
    trans=(0.1, -0.05, 0.03),
    scale=1.0,
    rate=20.0,
    noise=0.0,
    seed=0,
):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 100, 1 / 200)
    r, p = simulate.truth_pose(seq, t)
    ref = Trajectory.from_rp(t, r, p)
    te = np.arange(1, 99, 1 / rate)
    re, pe = simulate.truth_pose(seq, te + offset)
    rx, tx = geometry.so3_exp(np.array(rot)), np.array(trans)
    rc = re @ rx
    pc = pe + np.einsum("nab,b->na", re, tx) + rng.normal(0, noise, (len(te), 3))
    world = geometry.rot_z(0.8)
    est = Trajectory.from_rp(te, world @ rc, (pc @ world.T + [3, -2, 1]) / scale)
    return ref, est, rx, tx


def test_step1_absolute_offset_on_20hz_simulation():
    errors = []
    for seq in simulate.SEQUENCES:  # drone, slow yaw-dominated vehicle, handheld
        for offset in (-0.9, -0.42, 0.037, 0.25, 0.8):
            ref, est, _, _ = case(seq, offset)
            out = sync.estimate_offset(ref, est)
            assert out.used, out.reason
            errors.append(abs(out.offset - offset))
    assert np.median(errors) <= 0.002 and np.max(errors) <= 0.005, errors


def test_step2_recovers_extrinsic_and_scale():
    ref, est, rx, tx = case(scale=3.7, noise=0.002)
    ir, ie = sync.associate(ref, est, offset=0.037)
    ext = calibration.solve(ref.select(ir), est.select(ie), scale=True)
    assert ext.trusted
    assert np.degrees(geometry.rotation_angle(ext.R.T @ rx)) < 0.05
    assert np.linalg.norm(ext.t - tx) < 0.005 and abs(ext.scale - 3.7) / 3.7 < 1e-3


def _planar(yaw_only=True, rotate=True):
    t = np.arange(0, 100, 0.05)
    yaw = 0.8 * np.sin(t / 3) if rotate else 0 * t
    r = np.stack([geometry.rot_z(y) for y in yaw])
    p = np.c_[np.cos(t / 10) * 20, np.sin(t / 7) * 15, 0 * t]
    return Trajectory.from_rp(t, r, p)


def test_step2_planar_motion_reports_unobservable_z():
    ref = _planar()
    rx, tx = geometry.so3_exp(np.array([0.0, 0.0, 0.4])), np.array([0.2, 0.1, 0.3])
    est = Trajectory.from_rp(ref.t, ref.r @ rx, ref.p + np.einsum("nab,b->na", ref.r, tx))
    ext = calibration.solve(ref, est)
    dirs = np.array(ext.info["translation_unobservable_directions"])
    assert len(dirs) == 1 and abs(abs(dirs[0][2]) - 1) < 1e-6
    assert ext.t[2] == pytest.approx(0, abs=1e-9)  # reported and left at zero, not fitted to noise
    # one rotation axis only: the rotation about it and the translation along it are unobservable
    assert ext.status == "unobservable" and not ext.trusted
    assert np.allclose(np.abs(ext.info["rotation_unobservable_axes"]), [[0, 0, 1]], atol=1e-6)
    assert ext.info["rotation_std_deg"][2] is None and ext.info["translation_std_m"][2] is None


def test_step2_pure_translation_is_untrusted():
    ref = _planar(rotate=False)
    ext = calibration.solve(ref, ref)
    assert not ext.trusted and "too little rotation" in ext.reason


def test_umeyama_recovers_random_sim3(rng):
    src = rng.normal(size=(50, 3)) * 10
    r = geometry.so3_exp(rng.normal(size=3))
    dst = 2.5 * src @ r.T + [1, 2, 3]
    fit = alignment.umeyama(src, dst, with_scale=True)
    assert (
        np.allclose(fit.R, r, atol=1e-12)
        and abs(fit.s - 2.5) < 1e-12
        and np.allclose(fit.t, [1, 2, 3], atol=1e-10)
    )


def test_posyaw_leaves_roll_and_pitch_alone():
    ref, est, _, _ = case(rot=(0, 0, 0), trans=(0, 0, 0), offset=0.0)
    ir, ie = sync.associate(ref, est)
    r, e = ref.select(ir), est.select(ie)
    fit = alignment.fit(r, e, method="posyaw")
    assert np.allclose(fit.R[2], [0, 0, 1]) and np.degrees(
        np.arctan2(fit.R[1, 0], fit.R[0, 0])
    ) == pytest.approx(-np.degrees(0.8), abs=1e-6)
    a = fit.apply(e)
    assert np.allclose(a.p, r.p, atol=1e-6)


def test_quaternion_helpers_match_matrix_algebra(rng):
    a, b = (
        geometry.normalize_quat(rng.normal(size=(200, 4))),
        geometry.normalize_quat(rng.normal(size=(200, 4))),
    )
    v = rng.normal(size=(200, 3))
    ra, rb = geometry.quat_to_rot(a), geometry.quat_to_rot(b)
    assert np.allclose(geometry.quat_to_rot(geometry.quat_mul(a, b)), ra @ rb, atol=1e-12)
    assert np.allclose(geometry.quat_rotate(a, v), np.einsum("nab,nb->na", ra, v), atol=1e-12)
    assert np.allclose(geometry.quat_angle(a), geometry.rotation_angle(ra), atol=1e-12)


def test_step2_interpolator_of_a_single_pose_is_trajectory_at():
    """One reference pose has no interval to set up: every stamp gets that pose, as Trajectory.at."""
    ref = Trajectory.from_rp(np.array([5.0]), geometry.rot_z(0.3)[None], np.array([[1.0, 2, 3]]))
    stamps = np.array([4.0, 5.0, 6.5])
    got, want = calibration.interpolator(ref)(stamps), ref.at(stamps)
    assert np.array_equal(got.t, want.t)
    assert np.array_equal(got.p, want.p) and np.array_equal(got.q, want.q)


def test_interpolator_is_interpolate_bit_for_bit(rng):
    """Stamps one per interval (the slices' path), with repeats, outside the poses, unsorted and
    across blocks: the same bits as interpolate's search at every stamp."""
    t = np.cumsum(rng.uniform(0.5, 1.5, 3000))
    p, q = rng.normal(size=(3000, 3)), geometry.normalize_quat(rng.normal(size=(3000, 4)))
    at = geometry.interpolator(t, geometry.component_rows(p), geometry.component_rows(q))
    mid = (t[:-1] + t[1:]) / 2
    for stamps in (
        mid,  # one per interval
        mid[5:] + 1e-9,
        t[1:],  # on the poses
        np.r_[t[0] - 1, mid],  # one before the first
        np.r_[mid, t[-1] + 3],
        np.repeat(mid[:50], 2),
        rng.uniform(t[0] - 2, t[-1] + 2, 2000),
        np.tile(mid[:100], 700),  # blocks of both kinds
    ):
        (pa, qa), (pb, qb) = at(stamps), geometry.interpolate(t, p, q, stamps)
        assert np.array_equal(pa.T, pb) and np.array_equal(qa.T, qb)


def test_step2_median_is_numpy_median(rng):
    """The bracketed selection gives np.median's value: ties, sorted and skewed values, sizes
    either side of the sample's threshold, and samples whose bounds miss (the whole partitioned)."""
    cases = [rng.integers(0, 5, n).astype(float) for n in (1, 2, 4095, 4096, 70001)]
    cases += [np.abs(rng.standard_t(3, n)) for n in (4097, 100000, 100001)]
    x = rng.normal(size=200000)
    cases += [np.sort(x), np.sort(x)[::-1], np.r_[np.zeros(100000), np.ones(100001)]]
    skewed = np.zeros(200000)
    skewed[::64] = 1.0  # the sample sees only ones: its bounds miss the median
    cases.append(skewed)
    for x in cases:
        assert calibration._median(x) == np.median(x)
    assert np.isnan(calibration._median(np.r_[x, np.nan])) and np.isnan(calibration._median(x[:0]))


def test_step2_takes_the_kept_estimate_motions_only_for_the_same_pairs():
    """The +-offset_std re-solves find their pairs again; one whose i are the same but a j moved (a
    tie broken the other way) must not take the estimate's motions of the other pairs."""
    ref, est, _, _ = case(noise=0.002)
    ir, ie = sync.associate(ref, est, offset=0.037)
    ref, est = ref.select(ir), est.select(ie)
    fit = dict(
        pair_step=1.0,
        min_rotation_deg=2.0,
        scale=False,
        max_condition=100.0,
        min_pairs=20,
        outlier_iterations=3,
        solution_only=True,
    )
    motions: dict = {}
    fresh = calibration._fit(ref, est, **fit, motions=motions)[0]
    (i, j), kept = motions["estimate"]
    moved = j.copy()
    moved[0] += 1
    motions["estimate"] = ((i, moved), tuple(np.zeros_like(a) for a in kept))
    again = calibration._fit(ref, est, **fit, motions=motions)[0]
    assert np.array_equal(again.R, fresh.R) and np.array_equal(again.t, fresh.t)
