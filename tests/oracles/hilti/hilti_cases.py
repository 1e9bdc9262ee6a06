"""The real inputs of the Hilti oracle (shared by run_oracle.py, run under the challenge script's own
environment, and tests/test_hilti.py).

EuRoC MH_01 has no surveyed control points, so they are drawn from its reference: the first
reference pose at or after ``t_0 + k · EVERY_S`` for k = 0, 1, ... (``numpy.searchsorted``), written
as the challenge's files are (``t x y z 0 0 0 1``). ORB-SLAM3's stamps are ns: divided by 1e9.
"""

from pathlib import Path

import numpy as np

EVERY_S = 10.0
R = "uzh-rpg_rpg_trajectory_evaluation/results"
GT_BODY = "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
GT_CAM = "UZ-SLAMLab_ORB_SLAM3/evaluation/Ground_truth/EuRoC_left_cam/MH01_GT.txt"
CASES = {
    "mh01_vio_mono": (
        GT_BODY,
        f"{R}/euroc_mono_stereo/laptop/vio_mono/laptop_vio_mono_MH_01/stamped_traj_estimate.txt",
    ),
    "mh01_vio_stereo": (
        GT_BODY,
        f"{R}/euroc_mono_stereo/laptop/vio_stereo/laptop_vio_stereo_MH_01/stamped_traj_estimate.txt",
    ),
    "mh01_vislam_rp0": (
        GT_BODY,
        f"{R}/euroc_vislam_mono/laptop/vislam_rp/laptop_vislam_rp_MH_01/stamped_traj_estimate0.txt",
    ),
    "mh01_vislam_ba0": (
        GT_BODY,
        f"{R}/euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_MH_01/stamped_ba_estimate0.txt",
    ),
    "mh01_orbslam3_stereo": (GT_CAM, "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_stereo.txt"),
}


def reference(data: Path, name: str) -> np.ndarray:
    """(N, 8) ``t x y z qx qy qz qw`` of the case's dense reference."""
    path = CASES[name][0]
    if path == GT_CAM:
        gt = np.loadtxt(data / path, delimiter=",", comments="#")
        return np.column_stack([gt[:, 0] / 1e9, gt[:, 1:4], gt[:, 5:8], gt[:, 4]])
    return np.loadtxt(data / path)


def estimate(data: Path, name: str) -> np.ndarray:
    """(N, 8) ``t x y z qx qy qz qw`` of the case's estimate, stamps in seconds."""
    est = np.loadtxt(data / CASES[name][1])
    if "ORB_SLAM3" in CASES[name][1]:
        est[:, 0] /= 1e9
    return est


def control_points(ref: np.ndarray) -> np.ndarray:
    """(M, 8) control points drawn from a dense reference, orientation the identity."""
    t = ref[:, 0]
    wanted = t[0] + EVERY_S * np.arange(int((t[-1] - t[0]) // EVERY_S) + 1)
    idx = np.unique(np.searchsorted(t, wanted, side="left"))
    idx = idx[idx < len(t)]
    rows = np.zeros((len(idx), 8))
    rows[:, :4], rows[:, 7] = ref[idx, :4], 1.0
    return rows
