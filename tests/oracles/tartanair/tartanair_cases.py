"""The real inputs of the TartanAir oracle and how they are made equal-length (shared by
run_oracle.py, run under the benchmark's own environment, and tests/test_tartanair.py).

TartanAir pairs poses by index, so each case is two arrays (N, 7) ``x y z qx qy qz qw`` of equal N:
- EuRoC MH_01: for every estimate pose, the reference pose with the nearest stamp
  (``numpy.searchsorted``, a tie to the earlier), kept when within ``MAX_DT_S``; estimate poses
  outside that are dropped. The reference is at 200 Hz, so the nearest is at most 2.5 ms away.
- KITTI 00: one pose per frame in both files already; the 3x4 blocks become quaternions by
  ``scipy.spatial.transform.Rotation.from_matrix(...).as_quat()``.
"""

from pathlib import Path

import numpy as np

MAX_DT_S = 0.005
R = "uzh-rpg_rpg_trajectory_evaluation/results"
GT_BODY = "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
GT_CAM = "UZ-SLAMLab_ORB_SLAM3/evaluation/Ground_truth/EuRoC_left_cam/MH01_GT.txt"
CASES = {
    # name: (reference, estimate, kind)
    "mh01_vio_mono": (
        GT_BODY,
        f"{R}/euroc_mono_stereo/laptop/vio_mono/laptop_vio_mono_MH_01/stamped_traj_estimate.txt",
        "tum",
    ),
    "mh01_vio_stereo": (
        GT_BODY,
        f"{R}/euroc_mono_stereo/laptop/vio_stereo/laptop_vio_stereo_MH_01/stamped_traj_estimate.txt",
        "tum",
    ),
    "mh01_vislam_rp0": (
        GT_BODY,
        f"{R}/euroc_vislam_mono/laptop/vislam_rp/laptop_vislam_rp_MH_01/stamped_traj_estimate0.txt",
        "tum",
    ),
    "mh01_vislam_ba0": (
        GT_BODY,
        f"{R}/euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_MH_01/stamped_ba_estimate0.txt",
        "tum",
    ),
    # the first 90 pairs: fewer than 100 poses, so RPE takes all N^2 pairs (no random draw)
    "mh01_vislam_ba0_first90": (
        GT_BODY,
        f"{R}/euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_MH_01/stamped_ba_estimate0.txt",
        "tum90",
    ),
    # ORB-SLAM3 monocular (camera frame, scale about 5) against the camera-frame reference
    "mh01_orbslam3_mono": (GT_CAM, "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_mono.txt", "orb"),
    "kitti00_orb": (
        "MichaelGrupp_evo/test/data/KITTI_00_gt.txt",
        "MichaelGrupp_evo/test/data/KITTI_00_ORB.txt",
        "kitti",
    ),
    "kitti00_sptam": (
        "MichaelGrupp_evo/test/data/KITTI_00_gt.txt",
        "MichaelGrupp_evo/test/data/KITTI_00_SPTAM.txt",
        "kitti",
    ),
}


def _kitti(path: Path) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    m = np.loadtxt(path).reshape(-1, 3, 4)
    return np.hstack([m[:, :, 3], Rotation.from_matrix(m[:, :, :3]).as_quat()])


def _nearest(t_ref: np.ndarray, t_est: np.ndarray):
    """(i_ref, i_est): each estimate stamp's nearest reference stamp within MAX_DT_S."""
    k = np.clip(np.searchsorted(t_ref, t_est), 1, len(t_ref) - 1)
    earlier = np.abs(t_est - t_ref[k - 1]) <= np.abs(t_ref[k] - t_est)
    k = np.where(earlier, k - 1, k)
    keep = np.abs(t_ref[k] - t_est) <= MAX_DT_S
    return k[keep], np.flatnonzero(keep)


def equal_length(data: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The case's (reference, estimate), each (N, 7)."""
    ref_path, est_path, kind = CASES[name]
    if kind == "kitti":
        return _kitti(data / ref_path), _kitti(data / est_path)
    if kind == "orb":
        gt = np.loadtxt(data / ref_path, delimiter=",", comments="#")
        ref = np.column_stack([gt[:, 0] / 1e9, gt[:, 1:4], gt[:, 5:8], gt[:, 4]])
        est = np.loadtxt(data / est_path)
        est[:, 0] /= 1e9
    else:
        ref, est = np.loadtxt(data / ref_path), np.loadtxt(data / est_path)
    i_ref, i_est = _nearest(ref[:, 0], est[:, 0])
    a, b = ref[i_ref, 1:], est[i_est, 1:]
    return (a[:90], b[:90]) if kind == "tum90" else (a, b)
