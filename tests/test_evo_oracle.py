"""APE and RPE agree with evo 1.38.1 (test oracle) on its own sample data, same options."""

import copy

import numpy as np
import pytest

evo_sync = pytest.importorskip("evo.core.sync")
from evo.core import metrics as em  # noqa: E402
from evo.tools import file_interface  # noqa: E402

from epa.metrics import accuracy  # noqa: E402
from epa.readers import text  # noqa: E402
from epa.steps import align as alignment  # noqa: E402
from epa.steps import sync  # noqa: E402

# |epa - evo| per quantity, absolute in its unit, for each statistic compared (ATE rmse, mean, median,
# max; RPE rmse, mean). Measured worst, default / restricted CPU path (NPY_DISABLE_CPU_FEATURES,
# OPENBLAS_CORETYPE), when both compute on the same rotations:
TOL = {
    "trans_m": 1e-11,  # m; 5.2e-14 / 7.6e-14: the alignment's rounding (values 0.005 - 8 m)
    "rot_deg": 1e-11,  # deg; 1.6e-13 / 1.6e-13: angles from quaternions, no arccos near 1
}
# evo computes on KITTI's rotation blocks as printed (the ground truth to 7 digits, ORB-SLAM's from
# float32: orthonormal to 2e-7 and 8e-7), epica's metrics on their nearest rotations: each relative
# translation moves by that defect times the segment. Measured 7.7e-8 m (SPTAM, 10-frame RPE mean) on
# both CPU paths: set by the files' digits, not by rounding. test_kitti_00 also runs evo on epica's
# rotations, to TOL.
KITTI_PRINTED = {**TOL, "trans_m": 3e-7}  # m


def assert_near(ours: float, theirs: float, qty: str, where: str = "", tol: dict = TOL):
    assert abs(ours - theirs) <= tol[qty], (where, qty, ours, theirs, tol[qty])


def evo_stats(ref, est, rel, delta=None, unit=None, all_pairs=False, max_diff=0.01, scale=False):
    r, e = evo_sync.associate_trajectories(ref, est, max_diff=max_diff)
    e = copy.deepcopy(e)
    e.align(r, correct_scale=scale)
    m = em.APE(rel) if delta is None else em.RPE(rel, delta, unit, all_pairs=all_pairs)
    m.process_data((r, e))
    return m.get_all_statistics()


def ours(ref, est, specs, scale=False):
    ir, ie = sync.associate(ref, est, policy="evo")
    r, e = ref.select(ir), est.select(ie)
    a = alignment.fit(r, e, method="sim3" if scale else "se3").apply(e)
    s, _ = accuracy.evaluate(r, a, rpe=specs)
    return s


SPECS = [
    dict(delta=1, unit="frames"),
    dict(delta=10, unit="frames", all_pairs=True),
    dict(delta=1, unit="m"),
    dict(delta=8, unit="m", all_pairs=True),
]
EVO_SPECS = [
    (1, em.Unit.frames, False),
    (10, em.Unit.frames, True),
    (1, em.Unit.meters, False),
    (8, em.Unit.meters, True),
]


RELATIONS = {
    "trans_m": em.PoseRelation.translation_part,
    "rot_deg": em.PoseRelation.rotation_angle_deg,
}


def check(eref, eest, ref, est, scale=False, tol=TOL, keys=tuple(RELATIONS)):
    s = ours(ref, est, SPECS, scale)
    for key in keys:
        rel = RELATIONS[key]
        ev = evo_stats(eref, eest, rel, scale=scale)
        for stat in ("rmse", "mean", "median", "max"):
            assert_near(s["ate"][key][stat], ev[stat], key, f"ate {stat}", tol)
        for spec, (d, u, ap) in zip(s["rpe"], EVO_SPECS):
            ev = evo_stats(eref, eest, rel, d, u, ap, scale=scale)
            assert spec[key]["n"] > 0
            for stat in ("rmse", "mean"):
                assert_near(spec[key][stat], ev[stat], key, f"rpe {d} {u.value} {ap} {stat}", tol)


def test_tum_fr1_xyz(data):
    d = data / "MichaelGrupp_evo/test/data"
    check(
        file_interface.read_tum_trajectory_file(d / "freiburg1_xyz-groundtruth.txt"),
        file_interface.read_tum_trajectory_file(d / "freiburg1_xyz-rgbdslam.txt"),
        text.read_trajectory(d / "freiburg1_xyz-groundtruth.txt"),
        text.read_trajectory(d / "freiburg1_xyz-rgbdslam.txt"),
    )


def test_v102_sim3_with_duplicates_dropped_on_both_sides(data):
    d = data / "MichaelGrupp_evo/test/data"
    est = text.read_trajectory(d / "V102.txt", on_unsorted="sort")
    eest = file_interface.read_tum_trajectory_file(d / "V102.txt")
    # the same rows our sort mode keeps
    keep = np.concatenate([[True], np.diff(eest.timestamps) > 0])
    eest.reduce_to_ids(np.flatnonzero(keep))
    assert len(est) == eest.num_poses == 803
    check(
        file_interface.read_euroc_csv_trajectory(d / "V102_groundtruth.csv"),
        eest,
        text.read_trajectory(d / "V102_groundtruth.csv"),
        est,
        scale=True,
    )


@pytest.mark.parametrize("name", ["KITTI_00_ORB.txt", "KITTI_00_SPTAM.txt"])
def test_kitti_00(data, name):
    from evo.core.trajectory import PoseTrajectory3D

    d = data / "MichaelGrupp_evo/test/data"
    times = np.loadtxt(d / "KITTI_00_gt_times.txt")
    eref = file_interface.read_kitti_poses_file(d / "KITTI_00_gt.txt")
    eest = file_interface.read_kitti_poses_file(d / name)
    eref = PoseTrajectory3D(poses_se3=eref.poses_se3, timestamps=times)
    eest = PoseTrajectory3D(poses_se3=eest.poses_se3, timestamps=times)
    times_file = d / "KITTI_00_gt_times.txt"
    ref = text.read_trajectory(d / "KITTI_00_gt.txt", kitti_times=times_file)
    est = text.read_trajectory(d / name, kitti_times=times_file)
    check(eref, eest, ref, est, tol=KITTI_PRINTED)
    # the translations again, evo on the rotations epica computes on (the nearest ones): rounding only
    ref_q, est_q = (
        PoseTrajectory3D(
            positions_xyz=t.p, orientations_quat_wxyz=t.q[:, [3, 0, 1, 2]], timestamps=t.t
        )
        for t in (ref, est)
    )
    check(ref_q, est_q, ref, est, keys=("trans_m",))
