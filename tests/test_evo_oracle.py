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

REL = 1e-6


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


def check(eref, eest, ref, est, scale=False):
    s = ours(ref, est, SPECS, scale)
    for rel, key in (
        (em.PoseRelation.translation_part, "trans_m"),
        (em.PoseRelation.rotation_angle_deg, "rot_deg"),
    ):
        ev = evo_stats(eref, eest, rel, scale=scale)
        for stat in ("rmse", "mean", "median", "max"):
            assert s["ate"][key][stat] == pytest.approx(ev[stat], rel=REL)
        for spec, (d, u, ap) in zip(s["rpe"], EVO_SPECS):
            ev = evo_stats(eref, eest, rel, d, u, ap, scale=scale)
            assert spec[key]["n"] > 0
            assert spec[key]["rmse"] == pytest.approx(ev["rmse"], rel=REL)
            assert spec[key]["mean"] == pytest.approx(ev["mean"], rel=REL)


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
    keep = np.concatenate(
        [[True], np.diff(eest.timestamps) > 0]
    )  # the same rows our sort mode keeps
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
    check(
        eref,
        eest,
        text.read_trajectory(d / "KITTI_00_gt.txt", kitti_times=times_file),
        text.read_trajectory(d / name, kitti_times=times_file),
    )
