"""ov_eval's ATE 2D (yaw error and planar position error) against a literal transcription of
ResultTrajectory::calculate_ate_2d on the rpg data, and mode ov_eval's error_comparison.txt in
ov_eval's own layout."""

import glob
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from epa.metrics import ate_2d
from epa.readers import text
from epa.steps import align as alignment
from epa.steps import sync

# |epa - ov_eval| per pose, absolute in its unit, on the same aligned poses. Measured worst, default /
# restricted CPU path (NPY_DISABLE_CPU_FEATURES, OPENBLAS_CORETYPE):
TOL = {
    "yaw_deg": 1e-11,  # deg; 1.5e-14 / 1.5e-14: scipy's rotation vector against epica's (values < 5 deg)
    "trans_xy_m": 1e-12,  # m; 5.6e-17 / 0: the same planar differences, another norm
}


def assert_near(ours: np.ndarray, theirs: np.ndarray, qty: str, where: str = ""):
    assert ours.shape == theirs.shape, (where, qty)
    diff = np.abs(ours - theirs).max()
    assert diff <= TOL[qty], (where, qty, diff, TOL[qty])


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
    files = sorted(
        glob.glob(str(root / "**/*MH_0[1-5]*/stamped_traj_estimate*.txt"), recursive=True)
    )[:6]
    assert files, "no rpg estimates found"
    for f in files:  # the ground truth: OpenVINS's copy of EuRoC's (SOURCES.md)
        seq = re.search(r"MH_0\d", f).group(0)
        gt = sorted((data / "rpng_open_vins/ov_data/euroc_mav").glob(f"{seq}_*.txt"))[0]
        yield text.read_trajectory(gt), text.read_trajectory(f)


def test_ate_2d_matches_a_transcription_of_ov_eval(data):
    checked = 0
    for k, (ref, est) in enumerate(rpg_pairs(data)):
        i_ref, i_est = sync.associate(ref, est, policy="ov_eval")
        r, e = ref.select(i_ref), est.select(i_est)
        aligned = alignment.fit(r, e, method="posyaw").apply(e)
        yaw, xy = ate_2d.errors(r, aligned)
        want_yaw, want_xy = ov_eval_ate_2d(r, aligned)
        assert_near(yaw, want_yaw, "yaw_deg", str(k))
        assert_near(xy, want_xy, "trans_xy_m", str(k))
        # the frame matters: the body-frame error R_ref^T R_est has another z component
        body = Rotation.from_matrix(np.transpose(r.r, (0, 2, 1)) @ aligned.r).as_rotvec()[:, 2]
        assert np.sqrt(np.mean(np.degrees(body) ** 2)) != pytest.approx(
            np.sqrt(np.mean(yaw**2)), rel=1e-3
        )
        checked += 1
    assert checked >= 3


def test_ate_2d_of_a_pure_yaw_error_is_that_yaw_signed():
    from epa.core import geometry
    from epa.core.trajectory import Trajectory

    t = np.arange(4.0)
    r = geometry.so3_exp(
        np.array([[0.3, 0.1, 0.0], [0.0, 0.5, 1.0], [0.2, 0.0, -2.0], [1.0, 1.0, 1.0]])
    )
    ref = Trajectory.from_rp(t, r, np.zeros((4, 3)))
    est = Trajectory.from_rp(
        t, geometry.rot_z(np.radians(-3.0)) @ r, np.array([[3.0, 4.0, 12.0]] * 4)
    )
    yaw, xy = ate_2d.errors(ref, est)
    assert np.allclose(yaw, -3.0) and np.allclose(xy, 5.0)


def test_mode_ov_eval_writes_ov_evals_layout(tmp_path):
    from conftest import run_stages

    from epa import simulate
    from epa.outputs import tables
    from epa.workflow import settings

    simulate.simulate(tmp_path / "sim")
    cases = [
        {
            "key": f"{alg}/drone_figure8/{run}",
            "truth": str(tmp_path / "sim/truth/drone_figure8.txt"),
            "estimate": str(tmp_path / f"sim/algorithms/{alg}/drone_figure8/{run}.txt"),
        }
        for alg in ("vio_body", "vo_drifty")
        for run in ("run1", "run2")
    ]
    cfg = settings.resolve({"truth_dir": "x", "algorithms_dir": "y", "mode": "ov_eval"})
    out = tmp_path / "out"
    from epa import readers

    for c in cases:
        c["truth_source"] = readers.options(cfg, "reference", dataset="drone_figure8")
        c["estimate_source"] = readers.options(cfg, "estimate", algorithm=c["key"].split("/")[0])
    run_stages(cases, out, cfg)
    # a reference no case uses: ov_eval lists it too
    idle = tmp_path / "sim/truth/handheld_office.txt"
    tables.make([c["key"] for c in cases], out, cfg, {"handheld_office": str(idle)})
    text = (out / "error_comparison.txt").read_text()
    lines = text.splitlines()
    n_idle = sum(
        1 for line in idle.read_text().splitlines() if line.strip() and not line.startswith("#")
    )
    assert re.fullmatch(
        rf"\[COMP\]: {n_idle} poses in handheld_office\.txt => length of \d+\.\d\d meters", lines[2]
    )
    assert (
        "\033[31m[COMP]: vo_drifty dataset does not have any runs for handheld_office!!!!!" in text
    )
    lines = lines[:2] + [line for line in lines[2:] if "handheld_office" not in line]
    # error_comparison fixes its print level at INFO: its first line says so, then the reference
    # lines, the warnings, and the tables; none of its DEBUG lines (per-dataset means, medians)
    assert lines[0] == "Setting printing level to: INFO"
    assert re.fullmatch(
        r"\[COMP\]: \d+ poses in drone_figure8\.txt => length of \d+\.\d\d meters", lines[1]
    )
    # the error's RESET follows its newline
    assert lines[2] == "\033[0m" + "=" * 44 and lines[3] == "ATE LATEX TABLE"
    assert "processing" not in text and "median" not in text and "\t" not in text
    k = lines.index("ATE 2D LATEX TABLE")
    assert lines[k - 1] == lines[k + 1] == "=" * 44
    assert (
        lines[k + 2]
        == r" & \textbf{drone\_figure8} & \textbf{handheld\_office} & \textbf{Average} \\\hline"
    )
    import json

    runs = [
        json.loads((out / f"cases/vio_body/drone_figure8/{r}/06_metrics/metrics.json").read_text())[
            "ate_2d"
        ]
        for r in ("run1", "run2")
    ]
    yaw, xy = (
        np.mean([m["yaw_deg"]["rmse"] for m in runs]),
        np.mean([m["trans_xy_m"]["rmse"] for m in runs]),
    )
    assert lines[k + 3] == rf"vio\_body & {yaw:.3f} / {xy:.3f} & - / - & {yaw:.3f} / {xy:.3f} \\"
    assert "RPE LATEX TABLE" in lines and lines[-1] == "=" * 44
    assert text.count("=" * 44) == 9 and "=" * 45 not in text
    assert lines[lines.index("RPE LATEX TABLE") + 2].endswith(r"\textbf{48m} \\\hline")


def test_mode_ov_eval_prints_ov_evals_warnings_and_errors(tmp_path):
    """ResultTrajectory's warnings (length ratio outside 0.9-1.1, a reference coarser than 0.5 m per
    pose) and error_comparison's missing-dataset error, with ov_eval's colour codes as it prints them."""
    import copy

    from epa.artifacts.case import Case
    from epa.outputs import tables

    ok = tables.CaseResult(
        Case("vio_body", "MH_01", "run1"),
        load={
            "n_ref": 10,
            "ref_file": "MH_01.txt",
            "ref_length_m": 80.0,
            "est_path": "algorithms/vio_body/MH_01/run1.txt",
        },
        sync={"n_matched": 200, "matched_length_m": {"ref": 80.0, "est": 70.0}},
        metrics={
            "ate": {"rot_deg": {"rmse": 1.0}, "trans_m": {"rmse": 0.1}},
            "ate_2d": {"yaw_deg": {"rmse": 0.5}, "trans_xy_m": {"rmse": 0.05}},
        },
        segments={
            "length_m": np.array([8.0]),
            "rot_deg": np.array([0.3]),
            "trans_m": np.array([0.2]),
        },
    )
    coarse = copy.deepcopy(ok)
    coarse.case, coarse.sync = (
        Case("vio_body", "MH_01", "run2"),
        {"n_matched": 100, "matched_length_m": {"ref": 60.0, "est": 84.0}},  # 0.6 m/pose
    )
    coarse.load["est_path"] = "algorithms/vio_body/MH_01/run2.txt"
    other = copy.deepcopy(ok)
    other.case, other.load = Case("vo", "V1_01", "run1"), {**ok.load, "ref_file": "V1_01.txt"}
    other.sync = {"n_matched": 100, "matched_length_m": {"ref": 50.0, "est": 50.0}}
    # a reference without runs
    idle = {"V2_01": {"ref_file": "V2_01.txt", "n_ref": 7, "ref_length_m": 3.0}}
    text = tables.ov_eval_text([ok, coarse, other], [8.0], idle)
    y, r, x = "\033[33m", "\033[31m", "\033[0m"
    assert text.startswith(
        "Setting printing level to: INFO\n[COMP]: 10 poses in MH_01.txt => length of 80.00 meters\n"
        "[COMP]: 10 poses in V1_01.txt => length of 80.00 meters\n"
        "[COMP]: 7 poses in V2_01.txt => length of 3.00 meters\n"
        f"{y}[TRAJ]: Trajectory is a bad ratio of 0.88 length (est 70.00, gt 80.00)\n"
        f"{y}[TRAJ]: algorithms/vio_body/MH_01/run1.txt\n"
        f"{y}[TRAJ]: Trajectory is a bad ratio of 1.40 length (est 84.00, gt 60.00)\n"
        f"{y}[TRAJ]: algorithms/vio_body/MH_01/run2.txt\n"
        f"{y}[COMP]: average groundtruth position difference 0.60 > 0.50 is too large\n{x}"
        f"{y}[COMP]: this will prevent the RPE from finding valid trajectory segments!!!\n{x}"
        f"{y}[COMP]: the recommendation is to use a higher frequency groundtruth, or relax this "
        f"trajectory segment logic...\n{x}"
        f"{r}[COMP]: vio_body dataset does not have any runs for V1_01!!!!!\n{x}"
        f"{r}[COMP]: vio_body dataset does not have any runs for V2_01!!!!!\n{x}"
        f"{r}[COMP]: vo dataset does not have any runs for MH_01!!!!!\n{x}"
        f"{r}[COMP]: vo dataset does not have any runs for V2_01!!!!!\n{x}"
        "============================================\nATE LATEX TABLE\n"
    )
    assert "vio\\_body & 1.000 / 0.100 & - / - & - / - & 1.000 / 0.100 \\\\" in text.splitlines()
