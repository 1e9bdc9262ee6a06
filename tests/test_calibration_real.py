"""Step 2 on real EuRoC MH_01: ORB-SLAM3 stereo (rectified cam0) and mono (raw cam0, scale) vs Kalibr."""

import numpy as np
import pytest
import yaml

from epa.core import geometry
from epa.readers import text
from epa.steps import calibrate as calibration
from epa.steps import sync


@pytest.fixture(scope="module")
def euroc(data):
    kalibr = (
        (data / "rpng_open_vins/config/euroc_mav/kalibr_imucam_chain.yaml")
        .read_text()
        .split("\n", 1)[1]
    )
    chain = yaml.safe_load(kalibr)
    t0, t1 = np.array(chain["cam0"]["T_imu_cam"]), np.array(chain["cam1"]["T_imu_cam"])
    gt = text.read_trajectory(data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt")
    return gt, t0, t1


def solve(data, gt, name, **kw):
    est = text.read_trajectory(data / "spsingh37_ORB_SLAM3_ubuntu22" / name)
    off = sync.estimate_offset(gt, est)
    ir, ie = sync.associate(gt, est, offset=off.offset)
    return calibration.solve(gt.select(ir), est.select(ie), **kw)


def rectification(t0, t1):
    """Bouguet's rectifying rotation of cam0 (OpenCV stereoRectify R1), from the Kalibr chain."""
    x = np.linalg.inv(t1) @ t0
    r_r = geometry.so3_exp(-0.5 * geometry.so3_log(x[:3, :3]))
    t = r_r @ x[:3, 3]
    uu = np.array([np.sign(t[0]), 0, 0])
    ww = np.cross(t, uu)
    ww *= np.arccos(abs(t[0]) / np.linalg.norm(t)) / np.linalg.norm(ww)
    return geometry.so3_exp(ww) @ r_r.T


def test_stereo_recovers_extrinsic(data, euroc):
    gt, t0, t1 = euroc
    ext = solve(data, gt, "f_dataset-MH01_stereo.txt")
    assert ext.trusted
    rot_vs_raw = np.degrees(geometry.rotation_angle(ext.R.T @ t0[:3, :3]))
    rot_vs_rect = np.degrees(
        geometry.rotation_angle(ext.R.T @ t0[:3, :3] @ rectification(t0, t1).T)
    )
    trans_cm = 100 * np.linalg.norm(ext.t - t0[:3, 3])
    # ORB-SLAM3 stereo reports the rectified left camera, 0.62 deg from raw cam0: against that frame
    # the solve is within 0.25 deg; against raw Kalibr cam0 it is bounded by that rectification.
    assert rot_vs_rect < 0.25 and rot_vs_raw < 0.70 and trans_cm < 1.0


def test_mono_recovers_extrinsic_and_scale(data, euroc):
    gt, t0, _ = euroc
    ext = solve(data, gt, "f_dataset-MH01_mono.txt", scale=True)
    assert ext.trusted
    assert np.degrees(geometry.rotation_angle(ext.R.T @ t0[:3, :3])) < 0.25
    assert 100 * np.linalg.norm(ext.t - t0[:3, 3]) < 1.0
    # unit-less; a band for the solve's accuracy, not for rounding: measured 5.17381 on both CPU paths
    # (default and restricted differ by 2e-15)
    assert ext.scale == pytest.approx(5.171, abs=0.026)


def test_body_frame_estimate_gives_near_identity(data, euroc):
    gt, _, _ = euroc
    est = text.read_trajectory(
        data / "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv"
    )
    ir, ie = sync.associate(gt, est, offset=sync.estimate_offset(gt, est).offset)
    ext = calibration.solve(gt.select(ir), est.select(ie))
    assert (
        ext.trusted
        and np.degrees(geometry.rotation_angle(ext.R)) < 1.0
        and np.linalg.norm(ext.t) < 0.03
    )
