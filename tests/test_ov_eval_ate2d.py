"""ov_eval's ATE 2D (yaw error and planar position error) against a literal transcription of
ResultTrajectory::calculate_ate_2d on the rpg data, and mode ov_eval's error_comparison.txt in
ov_eval's own layout."""
import glob
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from epa import alignment, sync
from epa.metrics import accuracy
from epa.readers import text


def jpl_quat_2_rot(q_xyzw):
    """ov_core::quat_2_Rot: a JPL quaternion's matrix, the transpose of the Hamilton one (x, y, z, w)."""
    return Rotation.from_quat(q_xyzw).as_matrix().T


def ov_eval_ate_2d(gt, est_aligned):
    """calculate_ate_2d, pose by pose, as written: e_R = quat_2_Rot(q_est)^T quat_2_Rot(q_gt)."""
    ori, pos = [], []
    for k in range(len(gt)):
        e_r = jpl_quat_2_rot(est_aligned.q[k]).T @ jpl_quat_2_rot(gt.q[k])
        ori.append(np.degrees(Rotation.from_matrix(e_r).as_rotvec()[2]))
        pos.append(np.linalg.norm(gt.p[k, :2] - est_aligned.p[k, :2]))
    return np.array(ori), np.array(pos)


def rpg_pairs(data):
    root = data / "uzh-rpg_rpg_trajectory_evaluation/results"
    files = sorted(glob.glob(str(root / "**/*MH_0[1-5]*/stamped_traj_estimate*.txt"), recursive=True))[:6]
    assert files, "no rpg estimates found"
    for f in files:  # the ground truth: OpenVINS's copy of EuRoC's (SOURCES.md)
        seq = re.search(r"MH_0\d", f).group(0)
        gt = sorted((data / "rpng_open_vins/ov_data/euroc_mav").glob(f"{seq}_*.txt"))[0]
        yield text.read_trajectory(gt), text.read_trajectory(f)


def test_ate_2d_matches_a_transcription_of_ov_eval(data):
    checked = 0
    for ref, est in rpg_pairs(data):
        i_ref, i_est = sync.associate(ref, est, policy="ov_eval")
        r, e = ref.select(i_ref), est.select(i_est)
        aligned = alignment.fit(r, e, method="posyaw").apply(e)
        yaw, xy = accuracy.ate_2d(r, aligned)
        want_yaw, want_xy = ov_eval_ate_2d(r, aligned)
        assert np.allclose(yaw, want_yaw, atol=1e-9) and np.allclose(xy, want_xy, atol=1e-12)
        # the frame matters: the body-frame error R_ref^T R_est has another z component
        body = Rotation.from_matrix(np.transpose(r.r, (0, 2, 1)) @ aligned.r).as_rotvec()[:, 2]
        assert np.sqrt(np.mean(np.degrees(body) ** 2)) != pytest.approx(np.sqrt(np.mean(yaw ** 2)), rel=1e-3)
        checked += 1
    assert checked >= 3


def test_ate_2d_of_a_pure_yaw_error_is_that_yaw_signed():
    from epa import geometry
    from epa.trajectory import Trajectory

    t = np.arange(4.0)
    r = geometry.so3_exp(np.array([[0.3, 0.1, 0.0], [0.0, 0.5, 1.0], [0.2, 0.0, -2.0], [1.0, 1.0, 1.0]]))
    ref = Trajectory.from_rp(t, r, np.zeros((4, 3)))
    est = Trajectory.from_rp(t, geometry.rot_z(np.radians(-3.0)) @ r, np.array([[3.0, 4.0, 12.0]] * 4))
    yaw, xy = accuracy.ate_2d(ref, est)
    assert np.allclose(yaw, -3.0) and np.allclose(xy, 5.0)


def test_mode_ov_eval_writes_ov_evals_layout(tmp_path):
    from conftest import run_stages
    from epa import settings, simulate
    from epa.outputs import tables

    simulate.simulate(tmp_path / "sim")
    cases = [{"key": f"{alg}/drone_figure8/{run}", "truth": str(tmp_path / "sim/truth/drone_figure8.txt"),
              "estimate": str(tmp_path / f"sim/algorithms/{alg}/drone_figure8/{run}.txt")}
             for alg in ("vio_body", "vo_drifty") for run in ("run1", "run2")]
    cfg = settings.resolve({"truth_dir": "x", "algorithms_dir": "y", "mode": "ov_eval"})
    out = tmp_path / "out"
    from epa import readers

    for c in cases:
        c["truth_source"] = readers.options(cfg, "reference", dataset="drone_figure8")
        c["estimate_source"] = readers.options(cfg, "estimate", algorithm=c["key"].split("/")[0])
    run_stages(cases, out, cfg)
    tables.make([c["key"] for c in cases], out, cfg)
    lines = (out / "error_comparison.txt").read_text().splitlines()
    patterns = [r"\[COMP\]: \d+ poses in drone_figure8\.txt => length of \d+\.\d\d meters", "=" * 38,
                r"\[COMP\]: processing vio_body algorithm", r"\[COMP\]: processing vio_body algorithm => drone_figure8 dataset",
                r"\tATE: mean_ori = \d+\.\d{3} \| mean_pos = \d+\.\d{3} \(2 runs\)",
                r"\tATE: std_ori  = \d+\.\d{3} \| std_pos  = \d+\.\d{3}",
                r"\tATE 2D: mean_ori = \d+\.\d{3} \| mean_pos = \d+\.\d{3} \(2 runs\)",
                r"\tATE 2D: std_ori  = \d+\.\d{5} \| std_pos  = \d+\.\d{5}",
                r"\tRPE: seg 8 - median_ori = \d+\.\d{4} \| median_pos = \d+\.\d{4} \(\d+ samples\)"]
    for line, pattern in zip(lines, patterns):
        assert re.fullmatch(pattern, line), (pattern, line)
    k = lines.index("ATE 2D LATEX TABLE")
    assert lines[k - 1] == lines[k + 1] == "=" * 44
    assert lines[k + 2] == r" & \textbf{drone\_figure8} & \textbf{Average} \\\hline"
    import json

    runs = [json.loads((out / f"cases/vio_body/drone_figure8/{r}/06_metrics/metrics.json").read_text())["ate_2d"]
            for r in ("run1", "run2")]
    yaw, xy = np.mean([m["yaw_deg"]["rmse"] for m in runs]), np.mean([m["trans_xy_m"]["rmse"] for m in runs])
    assert lines[k + 3] == rf"vio\_body & {yaw:.3f} / {xy:.3f} & {yaw:.3f} / {xy:.3f} \\"
    assert "RPE LATEX TABLE" in lines and lines[-1] == "=" * 44
    assert lines[lines.index("RPE LATEX TABLE") + 2].endswith(r"\textbf{48m} \\\hline")
