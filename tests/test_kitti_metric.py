"""The KITTI odometry devkit metric on KITTI 00 (ORB-SLAM and S-PTAM from evo's test data), against
a straight transcription of the devkit's evaluate_odometry.cpp, pose matrix by pose matrix. The
metric computes on KITTI's printed rotation blocks, as the devkit does; they travel through every
stage's trajectory artifact."""

import json
import math

import numpy as np
import pytest
from conftest import run_stages

from epa.cli import main as cli
from epa.outputs import tables
from epa.workflow import chain, settings


def devkit(gt_file, result_file):
    """evaluate_odometry.cpp, line by line: loadPoses, trajectoryDistances, calcSequenceErrors, means."""

    def load(path):
        poses = []
        for line in open(path):
            v = [float(x) for x in line.split()]
            m = np.eye(4)
            m[:3, :] = np.array(v).reshape(3, 4)
            poses.append(m)
        return poses

    gt, res = load(gt_file), load(result_file)
    dist = [0.0]
    for i in range(1, len(gt)):
        d = gt[i][:3, 3] - gt[i - 1][:3, 3]
        dist.append(dist[i - 1] + math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2))
    t_errs, r_errs = [], []
    for first in range(0, len(gt), 10):
        for length in (100, 200, 300, 400, 500, 600, 700, 800):
            last = next((i for i in range(first, len(dist)) if dist[i] > dist[first] + length), -1)
            if last == -1:
                continue
            delta_gt = np.linalg.inv(gt[first]) @ gt[last]
            delta_res = np.linalg.inv(res[first]) @ res[last]
            err = np.linalg.inv(delta_res) @ delta_gt
            d = 0.5 * (err[0, 0] + err[1, 1] + err[2, 2] - 1.0)
            r_errs.append(math.acos(max(min(d, 1.0), -1.0)) / length)
            t_errs.append(math.sqrt(err[0, 3] ** 2 + err[1, 3] ** 2 + err[2, 3] ** 2) / length)
    return len(t_errs), 100 * np.mean(t_errs), np.mean(r_errs) * 180 / math.pi * 100


@pytest.fixture(scope="module")
def kitti00(data):
    root = data / "MichaelGrupp_evo/test/data"
    return root / "KITTI_00_gt.txt", {
        name: root / f"KITTI_00_{name}.txt" for name in ("ORB", "SPTAM")
    }


# |epa - devkit| per quantity, absolute in its unit, over the whole sequence. Both compute on the
# printed matrices; they differ by the SE3 alignment's rounding and the order of operations. Measured
# worst, default / restricted CPU path (NPY_DISABLE_CPU_FEATURES, OPENBLAS_CORETYPE):
TOL = {
    "trans_pct": 1e-13,  # %; 2.2e-16 / 5.3e-16 (values 0.2 - 0.7 %)
    # the devkit's acos((trace - 1) / 2) cancels near 1: a last-bit difference grows as 1/angle
    "rot_deg_per_100m": 1e-11,  # deg/100 m; 1.7e-14 / 2.2e-14 (values 0.1 - 0.3)
}


def assert_near(ours: float, theirs: float, qty: str, tol: float | None = None):
    tol = TOL[qty] if tol is None else tol
    assert abs(ours - theirs) <= tol, (qty, ours, theirs, tol)


CONFIG = "metrics: {kitti: true}\nsync: {estimate_offset: false}\ncalibrate: {enabled: false}\n"


@pytest.mark.parametrize("name", ["ORB", "SPTAM"])
def test_kitti_metric_equals_the_devkit_on_kitti_00(kitti00, tmp_path, name):
    gt, estimates = kitti00
    (tmp_path / "cfg.yaml").write_text(CONFIG)
    assert (
        cli.main(
            [
                "eval",
                str(gt),
                str(estimates[name]),
                "--out",
                str(tmp_path / "out"),
                "--config",
                str(tmp_path / "cfg.yaml"),
                "--artifacts",
            ]
        )
        == 0
    )
    record = json.loads((tmp_path / "out/06_metrics/metrics.json").read_text())
    assert record["n_matched"] == 4541  # every frame: the devkit's frame k is pair k
    n, trans_pct, rot = devkit(gt, estimates[name])
    k = record["kitti"]
    assert k["n_segments"] == n
    # on the printed matrices, as the devkit: its numbers but for the SE3 alignment's rounding
    assert_near(k["trans_pct"], trans_pct, "trans_pct")
    assert_near(k["rot_deg_per_100m"], rot, "rot_deg_per_100m")
    assert sum(v["n"] for v in k["per_length"].values()) == n and set(k["per_length"]) == {
        "100",
        "200",
        "300",
        "400",
        "500",
        "600",
        "700",
        "800",
    }
    rows = (tmp_path / "out/06_metrics/kitti_segments.csv").read_text().splitlines()
    assert rows[0] == "first,last,length_m,trans_pct,rot_deg_per_100m" and len(rows) == n + 1
    # the printed blocks are what makes it exact: on the nearest rotations the rotation is off by
    # 3e-5 (ORB) and 5e-7 (S-PTAM) relative
    from epa.core.trajectory import Trajectory
    from epa.metrics import kitti
    from epa.readers import text

    nearest = [
        Trajectory(t.t, t.p, t.q) for t in (text.read_trajectory(f) for f in (gt, estimates[name]))
    ]
    off = kitti.odometry(*nearest)[0]["rot_deg_per_100m"] / rot - 1
    assert 1e-7 < abs(off) < 1e-4


def test_the_printed_rotation_blocks_travel_through_the_stage_artifacts(kitti00, tmp_path):
    """Every stage's trajectory artifact of a KITTI input carries the printed blocks (the aligned ones
    turned by the alignment's rotation); a TUM input's artifacts have none."""
    from epa.artifacts import files
    from epa.readers import text

    gt, estimates = kitti00
    (tmp_path / "cfg.yaml").write_text(CONFIG)
    out = tmp_path / "out"
    argv = ["eval", str(gt), str(estimates["ORB"]), "--out", str(out), "--artifacts"]
    assert cli.main(argv + ["--config", str(tmp_path / "cfg.yaml")]) == 0
    printed = text.read_trajectory(estimates["ORB"], kitti_printed=True).r_printed
    for name in ("01_load/est.tum", "02_crop/est.tum", "05_align/aligned.tum"):
        header = (out / name).read_text().splitlines()[0]
        assert header.endswith(" qw r11 r12 r13 r21 r22 r23 r31 r32 r33")
    assert np.array_equal(files.read_tum_file(out / "02_crop/est.tum").r_printed, printed)
    transform = json.loads((out / "05_align/transform.json").read_text())
    aligned = files.read_tum_file(out / "05_align/aligned.tum")
    # the same product on one machine: a rotation's entries to rounding (rtol 0: atol alone counts)
    want = np.asarray(transform["rotation"]) @ printed
    assert np.allclose(aligned.r_printed, want, rtol=0, atol=1e-15)
    assert np.allclose(aligned.r, aligned.r_printed, atol=1e-6)  # q: their nearest rotations
    tum = tmp_path / "est.tum"
    files.write_trajectory(tum, text.read_trajectory(estimates["ORB"]), "tum")
    assert cli.main(["eval", str(gt), str(tum), "--out", str(tmp_path / "tum"), "--artifacts"]) == 0
    assert (tmp_path / "tum/02_crop/est.tum").read_text().splitlines()[0] == "# t x y z qx qy qz qw"


@pytest.mark.parametrize("method", ["none", "se3"])
def test_kitti_metric_reaches_summary_and_its_table(kitti00, tmp_path, method):
    """The grid: each stage a job reading the previous stage's artifacts."""
    gt, estimates = kitti00
    cfg = settings.resolve(
        {
            "truth_dir": str(gt.parent),
            "algorithms_dir": str(gt.parent),
            "metrics": {"kitti": True},
            "sync": {"estimate_offset": False},
            "calibrate": {"enabled": False},
            "align": {"method": method},
        }
    )
    cases = [
        {"key": f"{name}/KITTI_00/run1", "truth": str(gt), "estimate": str(est)}
        for name, est in estimates.items()
    ]
    out = tmp_path / "results"
    run_stages(cases, out, cfg, chain.NAMES[:-1])  # every stage but the report
    assert tables.make([c["key"] for c in cases], out, cfg) == []
    summary = (out / "summary.csv").read_text().splitlines()
    header = summary[0].split(",")
    orb = dict(zip(header, next(r for r in summary if r.startswith("ORB,")).split(",")))
    for name, est in estimates.items():
        n, trans_pct, rot = devkit(gt, est)
        k = json.loads((out / f"cases/{name}/KITTI_00/run1/06_metrics/metrics.json").read_text())
        k = k["kitti"]
        assert k["n_segments"] == n
        # the devkit's arithmetic on its matrices, to the SE3 alignment's rounding with one
        assert_near(k["trans_pct"], trans_pct, "trans_pct")
        assert_near(k["rot_deg_per_100m"], rot, "rot_deg_per_100m")
    _, trans_pct, rot = devkit(gt, estimates["ORB"])
    # summary.csv prints 9 significant digits: half a unit in the 9th digit, beside TOL
    for col, qty, want in (
        ("kitti_trans_pct", "trans_pct", trans_pct),
        ("kitti_rot_deg_per_100m", "rot_deg_per_100m", rot),
    ):
        printed = 0.5 * 10.0 ** (math.floor(math.log10(abs(want))) - 8)
        assert_near(float(orb[col]), want, qty, printed + TOL[qty])
    tex = (out / "tables/kitti.tex").read_text()
    assert (
        "KITTI ODOMETRY" in tex
        and f"{float(orb['kitti_rot_deg_per_100m']):.3f} / {trans_pct:.3f}" in tex
    )
    assert "kitti" in tables.table_names(cfg) and "kitti" not in tables.table_names(
        settings.resolve({"truth_dir": "t", "algorithms_dir": "a"})
    )


def test_kitti_metric_equals_the_devkit_exactly_on_orthonormal_poses(tmp_path, rng):
    """A 1.5 km drive with a drifting estimate, written as KITTI files at 17 digits (rotations orthonormal
    to 1e-16): the devkit transcription and epa agree to TOL."""
    from epa.artifacts import files
    from epa.core.geometry import so3_exp
    from epa.core.trajectory import Trajectory
    from epa.metrics import kitti
    from epa.readers import text

    n = 1500
    yaw = np.cumsum(rng.normal(0, 0.01, n))
    step = np.column_stack([np.cos(yaw), np.sin(yaw), 0.02 * rng.normal(size=n)])
    p = np.cumsum(step, axis=0)
    r = np.array([so3_exp(np.array([0.0, 0.0, y])) for y in yaw])
    r_est = np.array([so3_exp(rng.normal(0, 0.002, 3)) for _ in range(n)]) @ r
    p_est = p + np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0)
    t = np.arange(n) * 0.1
    files.write_trajectory(tmp_path / "gt.txt", Trajectory.from_rp(t, r, p), "kitti")
    files.write_trajectory(tmp_path / "est.txt", Trajectory.from_rp(t, r_est, p_est), "kitti")
    count, trans_pct, rot = devkit(tmp_path / "gt.txt", tmp_path / "est.txt")
    summary, _ = kitti.odometry(
        text.read_trajectory(tmp_path / "gt.txt"), text.read_trajectory(tmp_path / "est.txt")
    )
    assert summary["n_segments"] == count > 500
    assert_near(summary["trans_pct"], trans_pct, "trans_pct")
    assert_near(summary["rot_deg_per_100m"], rot, "rot_deg_per_100m")


def test_kitti_metric_is_empty_with_a_note_on_a_short_path(tmp_path):
    from epa.core.trajectory import Trajectory
    from epa.metrics import kitti

    t = np.arange(100.0)
    p = np.column_stack([t * 0.5, np.zeros(100), np.zeros(100)])  # 49.5 m: no 100 m segment
    q = np.tile([0.0, 0.0, 0.0, 1.0], (100, 1))
    summary, table = kitti.odometry(Trajectory(t, p, q), Trajectory(t, p, q))
    assert summary["n_segments"] == 0 and summary["trans_pct"] is None and len(table["first"]) == 0


def test_printed_blocks_turn_with_steps_2_and_3_and_change_no_other_number(kitti00):
    """Step 3 turns printed blocks by R (R P, as the devkit would a raw matrix), Step 2 by R_x^T on
    the right; the unit quaternions, positions and every number computed on them are those of the
    same trajectory without printed blocks, bit for bit."""
    from epa.core.geometry import so3_exp
    from epa.core.trajectory import Trajectory
    from epa.readers import text
    from epa.steps.align import Similarity
    from epa.steps.calibrate import Extrinsic

    _, estimates = kitti00
    traj = text.read_trajectory(estimates["ORB"], kitti_printed=True)
    plain = Trajectory(traj.t, traj.p, traj.q)
    rot = so3_exp(np.array([0.1, -0.2, 0.3]))
    for step in (Similarity(rot, np.array([1.0, 2.0, 3.0]), 0.5), Extrinsic(rot, np.ones(3), 2.0)):
        moved, moved_plain = step.apply(traj), step.apply(plain)
        assert np.array_equal(moved.q, moved_plain.q) and np.array_equal(moved.p, moved_plain.p)
        assert moved_plain.r_printed is None
        want = rot @ traj.r_printed if isinstance(step, Similarity) else traj.r_printed @ rot.T
        assert np.array_equal(moved.r_printed, want)
        assert np.abs(moved.r - moved.r_printed).max() < 1e-6  # q: their nearest rotations
