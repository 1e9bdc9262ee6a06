"""How sure Steps 1 and 2 are: honest standard deviations (simulated with known truth), unobservable
directions flagged and not applied, ambiguous or out-of-window offsets refused, noisy gentle motion."""

import numpy as np
import pytest

from epa import simulate
from epa.artifacts import files
from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.steps import calibrate as calibration
from epa.steps import sync
from epa.workflow import chain, settings


def simulated_trials(n: int):
    """Estimates of the simulated drone and handheld motion with a random offset, extrinsic, scale,
    white noise and random walks; Steps 1 and 2 as the pipeline runs them (Step 1's deviation
    carried into Step 2's). Yields the truth and the results."""
    t = np.arange(0, 90, 1 / 200)
    refs = [
        Trajectory.from_rp(t, *simulate.truth_pose(s, t))
        for s in ("handheld_office", "drone_figure8")
    ]
    for seed in range(n):
        rng = np.random.default_rng(seed)
        ref = refs[seed % 2]
        truth = {
            "offset": rng.uniform(-0.5, 0.5),
            "rotation": geometry.so3_exp(rng.normal(0, 1.0, 3)),
            "translation": rng.normal(0, 0.1, 3),
            "scale": rng.uniform(0.5, 4) if seed % 3 == 0 else 1.0,
        }
        est = simulate.observe(
            ref,
            rng,
            **truth,
            rate=20,
            noise_rot_deg=rng.uniform(0, 0.5),
            noise_pos_m=rng.uniform(0, 0.01),
            walk_rot_deg=rng.uniform(0, 0.05),
            walk_pos_m=rng.uniform(0, 0.01),
            margin=1.0,
        )
        step1 = sync.estimate_offset(ref, est)
        offset = step1.offset if step1.used else truth["offset"]
        _, i_est = sync.associate(ref, est, offset=offset)
        matched = est.select(i_est)
        step2 = calibration.solve(
            ref.at(matched.t + offset),
            matched,
            scale=truth["scale"] != 1.0,
            offset_std=step1.std if step1.used else 0.0,
        )
        yield truth, step1, step2


def test_reported_deviations_cover_the_true_error_in_95_percent_of_trials():
    z = {"offset": [], "rotation": [], "translation": [], "scale": []}
    for truth, step1, step2 in simulated_trials(48):
        assert step1.used and step2.status in ("trusted", "uncertain"), (step1.reason, step2.reason)
        z["offset"].append((step1.offset - truth["offset"]) / step1.std)
        # rotation error on the left (body axes), as the deviations are reported
        rot_err = np.degrees(geometry.so3_log(step2.R @ truth["rotation"].T))
        z["rotation"] += list(rot_err / step2.info["rotation_std_deg"])
        z["translation"] += list((step2.t - truth["translation"]) / step2.info["translation_std_m"])
        if truth["scale"] != 1.0:
            z["scale"].append((step2.scale - truth["scale"]) / step2.info["scale_std"])
    for name, values in z.items():
        inside = np.mean(np.abs(values) <= 3)
        # the scale is shrunk a little by the estimate's own position noise (errors in variables,
        # mean z -0.6 here), which its deviation does not hold: 15 of 16 inside (stated in docs)
        assert inside >= (0.9 if name == "scale" else 0.95), (name, inside)
        # and not inflated to get there: about two thirds inside 1 sigma, as for a normal error
        assert 0.5 <= np.mean(np.abs(values) <= 1) <= 0.9, name


def _rig(t, r, p, rx, tx, offset=0.0):
    """The reference body poses and a sensor estimate of them (sensor = body * X, in another world)."""
    ref = Trajectory.from_rp(t, r, p)
    world = geometry.so3_exp(np.array([0.1, -0.2, 0.9]))
    est = Trajectory.from_rp(
        t - offset, world @ r @ rx, (p + np.einsum("nab,b->na", r, tx)) @ world.T + [4, 1, -2]
    )
    return ref, est


def _run(tmp_path, ref, est):
    files.write_tum(tmp_path / "ref.txt", ref.shifted(1e9))
    files.write_tum(tmp_path / "est.txt", est.shifted(1e9))
    cfg = settings.resolve({"truth_dir": ".", "algorithms_dir": "."})
    return chain.run_case(tmp_path / "ref.txt", tmp_path / "est.txt", tmp_path / "out", cfg)[
        "metrics"
    ]


@pytest.mark.parametrize("motion", ["planar", "single axis"])
def test_unobservable_extrinsic_is_flagged_and_not_applied(tmp_path, motion):
    t = np.arange(0, 120, 0.05)
    if motion == "planar":  # a ground vehicle: yaw only, moving in the plane
        axis = np.array([0.0, 0.0, 1.0])
        p = np.c_[20 * np.cos(t / 10), 15 * np.sin(t / 7), 0 * t]
    else:  # a pendulum-like rig: rotation about one tilted body axis, moving in 3-D
        axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
        p = np.c_[3 * np.sin(t / 5), 2 * np.cos(t / 3), np.sin(t / 4)]
    angle = 0.8 * np.sin(t / 2) + 0.3 * np.sin(1.3 * t)
    r = geometry.so3_exp(angle[:, None] * axis)
    rx, tx = geometry.so3_exp(np.array([0.3, -0.4, 1.2])), np.array([0.2, 0.1, 0.3])
    m = _run(tmp_path, *_rig(t, r, p, rx, tx, offset=0.12))
    ext = m["calibrate"]["extrinsic"]
    assert m["calibrate"]["step2_status"] == ext["status"] == "unobservable" and not ext["trusted"]
    # the axis the motion turns about is the one whose rotation is unknown
    assert np.allclose(np.abs(ext["rotation_unobservable_axes"]), [np.abs(axis)], atol=1e-3)
    assert ext["reason"].startswith("unobservable: rotation about")
    # not evaluated with it: no extrinsic applied, the ov_eval way (configured offset 0, SE3)
    assert (
        m["eval_source"] == "ov_eval"
        and m["extrinsic_rot_deg"] is None
        and m["extrinsic_trans_m"] is None
    )


def _signal_case(yaw, t, offset, rate=20.0):
    ref = Trajectory.from_rp(
        t, geometry.so3_exp(yaw[:, None] * [0.0, 0.0, 1.0]), np.zeros((len(t), 3))
    )
    return ref, simulate.observe(
        ref, np.random.default_rng(0), offset=offset, rate=rate, margin=0.5
    )


def test_an_offset_outside_the_search_window_is_flagged_not_clamped():
    t = np.arange(0, 90, 0.005)
    yaw = 0.6 * np.sin(t / 1.7) + 0.4 * np.sin(t / 0.9 + 1) + 0.2 * np.sin(t / 0.43)
    for true, status in (
        (2.1, "at window edge"),
        (3.2, "outside window"),
        (12.0, "outside window"),
    ):
        ref, est = _signal_case(yaw, t, offset=true)
        out = sync.estimate_offset(ref, est, window=2.0, fallback=0.0)
        assert not out.used and out.offset == 0.0 and out.status == status, (true, out.reason)
        # what was found is on record, at the edge, never used as the offset
        if status == "at window edge":
            assert abs(out.estimated) >= 1.99
        else:  # and where the better match is
            assert f"at +{true:.3f} s" in out.reason
        wide = sync.estimate_offset(ref, est, window=true + 2.0)
        assert wide.used and abs(wide.offset - true) < 3 * wide.std


def test_periodic_motion_with_two_near_equal_peaks_is_ambiguous():
    t = np.arange(0, 90, 0.005)
    yaw = 0.5 * np.sin(2 * np.pi * t / 0.8)  # the motion repeats every 0.8 s
    ref, est = _signal_case(yaw, t, offset=0.3)
    out = sync.estimate_offset(ref, est)
    assert not out.used and out.status == "ambiguous" and out.peak_ratio < 1.05


@pytest.mark.parametrize("rate, noise_deg", [(20, 0.1), (30, 0.1), (30, 0.3), (100, 0.3)])
def test_gentle_motion_with_orientation_noise_finds_zero_or_says_so(rate, noise_deg):
    """White orientation noise at the sensor rate and no clock offset: before speed_interval, Step 1
    trusted offsets of 10-30 ms here (at 30 Hz, 0.1 deg: -16 ms with a 4 ms deviation)."""
    t = np.arange(0, 120, 1 / 200)
    w = np.stack(
        [
            0.1 * np.sin(1.3 * t),
            0.08 * np.sin(0.9 * t + 1),
            0.3 * np.sin(0.5 * t) + 0.1 * np.sin(1.7 * t),
        ],
        -1,
    )
    ref = Trajectory.from_rp(
        t, geometry.so3_exp(w), np.c_[np.sin(0.05 * t), np.cos(0.04 * t), 0 * t]
    )
    found, z = [], []
    for seed in range(16):
        est = simulate.observe(
            ref, np.random.default_rng(seed), rate=rate, noise_rot_deg=noise_deg, margin=1
        )
        out = sync.estimate_offset(ref, est)
        if out.used:
            found.append(out.offset)
            z.append(out.offset / out.std)
        else:
            assert out.status in ("uncertain", "weak peak", "ambiguous"), out.reason
    # what it trusts is zero within its stated deviation (at most sync.max_offset_std, 10 ms)
    assert len(found) >= 8 and np.mean(np.abs(z) <= 3) >= 0.9 and np.max(np.abs(z)) < 4
    assert np.sqrt(np.mean(np.square(found))) < 0.006


def test_a_step2_deviation_that_is_not_a_number_is_never_read_as_within_its_limit():
    """max() over [nan, 0.1] is nan and nan > limit is False: the verdict must not call it trusted."""
    import math

    from epa.steps import calibrate as calibration

    for rotation_std in ([math.nan, 0.01, 0.01], [0.01, math.nan, None], [math.inf, 0.01, 0.01]):
        info = {
            "rotation_residual_rms_deg": 0.1,
            "translation_residual_rms_m": 0.001,
            "rotation_unobservable_axes": [],
            "translation_unobservable_directions": [],
            "scale_unobservable": False,
            "scale_std": None,
            "rotation_std_deg": rotation_std,
            "translation_std_m": [0.001, 0.001, 0.001],
        }
        ext = calibration._verdict(
            calibration.Extrinsic(info=info), False, 1.0, 0.1, 0.5, 0.05, 0.05
        )
        assert ext.status == calibration.Step2Status.UNCERTAIN and not ext.trusted
        assert ext.reason == (
            "rotation std not finite"
            if math.inf in rotation_std
            else "rotation std undefined (motion pairs in one time block)"
        )
