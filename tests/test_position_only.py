"""Position-only estimates (`t x y z`, issue 36 item 5): read with no orientation, evaluated for
translation, every rotation quantity null with its reason, the tables marking those cells."""

from __future__ import annotations

import csv
import json
import logging

import numpy as np
import pytest
from conftest import run_stages, smooth_path

from epa import readers
from epa.artifacts import files
from epa.cli import main as cli
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.outputs import tables
from epa.outputs.contract import compare_record
from epa.readers import text
from epa.steps import sync
from epa.workflow import discovery, settings

EUROC = "uzh-rpg_rpg_trajectory_evaluation/results/euroc_mono_stereo/laptop/vio_mono"
EST = EUROC + "/laptop_vio_mono_MH_01/stamped_traj_estimate.txt"
GT = "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
NULL_STATS = {
    "n": 0,
    "rmse": None,
    "mean": None,
    "median": None,
    "std": None,
    "min": None,
    "max": None,
}


def strip_to_positions(src, dst) -> None:
    """A full-pose TUM file's ``t x y z`` columns, as a GNSS or UWB system would write them."""
    rows = [line.split()[:4] for line in src.read_text().splitlines() if not line.startswith("#")]
    dst.write_text("".join(" ".join(r) + "\n" for r in rows))


def rotation_stats(record, where=""):
    """Every ``rot_deg`` statistics of a record, with where it sits."""
    if isinstance(record, list):
        return [x for k, v in enumerate(record) for x in rotation_stats(v, f"{where}[{k}]")]
    if not isinstance(record, dict):
        return []
    out = [(f"{where}.rot_deg", record["rot_deg"])] if "rot_deg" in record else []
    return out + [
        x for k, v in record.items() if k != "rot_deg" for x in rotation_stats(v, f"{where}.{k}")
    ]


# ----------------------------------------------------------------------------- reading
def test_four_columns_and_a_t_x_y_z_header_are_read_as_positions(tmp_path):
    traj = smooth_path(50)
    plain, named = tmp_path / "gnss.txt", tmp_path / "uwb.csv"
    plain.write_text(
        "".join(f"{t:.6f} {x:.17g} {y:.17g} {z:.17g}\n" for t, (x, y, z) in zip(traj.t, traj.p))
    )
    named.write_text(
        "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m]\n"
        + "".join(
            f"{round(t * 1e9)},{x:.17g},{y:.17g},{z:.17g}\n" for t, (x, y, z) in zip(traj.t, traj.p)
        )
    )
    for path, fmt in ((plain, "format position (4 columns)"), (named, "format csv (4 columns")):
        notes: list[str] = []
        read = text.read_trajectory(path, notes=notes)
        assert read.position_only and np.isnan(read.q).all()
        assert np.array_equal(read.p, traj.p) and np.allclose(read.t, traj.t, atol=1e-9)
        assert notes[0].startswith(fmt) and "position only" in notes[1]
    assert not smooth_path(5).position_only
    # the stage artifacts keep "no orientation" (NaN), so a job reading them sees a position-only one
    files.write_tum(tmp_path / "est.tum", read)
    assert files.read_tum_file(tmp_path / "est.tum").position_only


def test_a_position_only_trajectory_is_written_without_orientation(tmp_path, capsys):
    traj = Trajectory.positions(smooth_path(20).t, smooth_path(20).p)
    files.write_trajectory(tmp_path / "gnss.txt", traj, "position")
    assert cli.main(["traj", str(tmp_path / "gnss.txt"), "--export", str(tmp_path / "o.csv")]) in (
        0,
        None,
    )
    assert "wrote 20 poses to" in capsys.readouterr().out
    assert (tmp_path / "o.csv").read_text().startswith("t,x,y,z\n")
    assert cli.main(["traj", str(tmp_path / "gnss.txt"), "--export", str(tmp_path / "o.txt")]) in (
        0,
        None,
    )
    assert "o.txt (position)" in capsys.readouterr().out  # t x y z, not TUM with NaN quaternions
    back = text.read_trajectory(tmp_path / "o.txt")
    assert back.position_only and np.array_equal(back.p, traj.p)
    with pytest.raises(EpaError, match="position-only .* the kitti format holds orientations"):
        files.write_trajectory(tmp_path / "k.txt", traj, "kitti")


def test_step1_finds_a_known_offset_on_linear_speed():
    ref = smooth_path(1200)  # 60 s at 20 Hz
    est = Trajectory.positions(ref.t - 0.137, ref.p)  # t_ref = t_est + 0.137
    found = sync.estimate_offset(ref, est, speed=sync.linear_speed)
    assert found.used and abs(found.offset - 0.137) < max(3 * found.std, 1e-3)
    # the angular signal of a position-only estimate is no signal at all
    assert np.isnan(sync.angular_speed(est)[1]).all()


# ----------------------------------------------------------------------------- a real EuRoC run
def _eval(data, tmp_path, est, name, *args):
    out = tmp_path / name
    rc = cli.main(["eval", str(data / GT), str(est), "--out", str(out), "--artifacts", *args])
    assert rc in (0, None)
    return out, json.loads((out / "06_metrics/metrics.json").read_text())


@pytest.fixture(scope="module")
def euroc_runs(data, tmp_path_factory):
    """The same EuRoC estimate full-pose and stripped to ``t x y z``, with the same matched poses
    (the configured offset: Step 1 would use two different signals) and no extrinsic."""
    tmp = tmp_path_factory.mktemp("euroc")
    strip_to_positions(data / EST, tmp / "est_positions.txt")
    (tmp / "cfg.yaml").write_text("metrics:\n  per_axis: true\n")
    same = ("--no-offset-estimate", "--no-calibrate", "--config", str(tmp / "cfg.yaml"))
    full = _eval(data, tmp, data / EST, "full", *same)
    pos = _eval(data, tmp, tmp / "est_positions.txt", "pos", *same)
    return full, pos


def test_translation_errors_equal_the_full_pose_runs(euroc_runs):
    (_, full), (_, pos) = euroc_runs
    assert pos["n_matched"] == full["n_matched"] == 3638
    assert compare_record(
        "alignment", json.dumps(full["alignment"]), json.dumps(pos["alignment"])
    ).ok
    assert compare_record(
        "ate", json.dumps(full["ate"]["trans_m"]), json.dumps(pos["ate"]["trans_m"])
    ).ok
    assert compare_record(
        "ate_2d", json.dumps(full["ate_2d"]["trans_xy_m"]), json.dumps(pos["ate_2d"]["trans_xy_m"])
    ).ok
    assert pos["ate"]["trans_m"]["rmse"] == pytest.approx(0.2041, abs=1e-4)


def test_rpe_translation_is_the_world_frame_displacement_error(euroc_runs):
    """Without the estimate's orientation the RPE compares each pair's displacement in the aligned
    world frame: |(p_j - p_i) - (q_j - q_i)|, derived here from the full-pose run's own arrays. The
    full-pose RPE turns the estimate's displacement by the orientation error D_i of pose i, so the
    two differ by at most 2 sin(theta_i / 2) |p_j - p_i| (theta_i: pose i's ATE rotation error)."""
    (full_dir, _), (pos_dir, pos) = euroc_runs
    aligned = files.read_tum_file(full_dir / "05_align/aligned.tum")
    ref_cropped = files.read_tum_file(full_dir / "02_crop/ref.tum")
    i_ref, _ = files.read_pair_indices(full_dir / "04_calibrate/pairs.csv")
    p_ref = ref_cropped.p[i_ref]
    seg_full = files.read_csv(full_dir / "06_metrics/rpe_segments.csv")
    seg_pos = files.read_csv(pos_dir / "06_metrics/rpe_segments.csv")
    i, j = seg_pos["i"].astype(int), seg_pos["j"].astype(int)
    assert np.array_equal(i, seg_full["i"]) and np.array_equal(j, seg_full["j"])
    moved = aligned.p[j] - aligned.p[i]
    world = np.linalg.norm(moved - (p_ref[j] - p_ref[i]), axis=1)
    assert np.allclose(seg_pos["trans_m"], world, rtol=1e-12, atol=1e-12)
    theta = np.radians(files.read_csv(full_dir / "06_metrics/ape.csv")["rot_deg"])[i]
    bound = 2 * np.sin(theta / 2) * np.linalg.norm(moved, axis=1)
    assert np.all(np.abs(seg_full["trans_m"] - seg_pos["trans_m"]) <= bound + 1e-12)
    assert np.isnan(seg_pos["rot_deg"]).all()  # no rotation error: none was read
    mean8 = np.mean(world[seg_pos["length_m"] == 8.0])
    assert pos["rpe_distance"]["8"]["trans_m"]["mean"] == pytest.approx(mean8, rel=1e-12)


def test_every_rotation_quantity_is_null_with_its_reason(euroc_runs):
    (_, full), (pos_dir, pos) = euroc_runs
    drift = json.loads((pos_dir / "07_drift/drift.json").read_text())
    found = rotation_stats(pos) + rotation_stats(drift, "drift")
    assert all(s == NULL_STATS for _, s in found), [w for w, s in found if s != NULL_STATS]
    # the same places as the full-pose run's, but for the rotation metric that is null as a whole
    full_places = {w for w, _ in rotation_stats(full) if not w.startswith(".per_axis")}
    assert {w for w, _ in rotation_stats(pos)} == full_places
    assert len(rotation_stats(drift)) == 8  # drift-valid: ATE, 6 segment lengths, 1 s RPE
    assert pos["position_only"] is True and "position_only" not in full
    assert pos["ate_2d"]["yaw_deg"] == NULL_STATS
    assert pos["per_axis"] is None and full["per_axis"]["ate"]  # a rotation metric: null
    notes = " ".join(pos["notes"])
    assert "the estimate is position-only: every rotation error is null" in notes
    assert "per_axis: null: it needs orientations (the estimate is position-only)" in notes
    assert np.isnan(files.read_tum_file(pos_dir / "05_align/aligned.tum").q).all()  # none invented


def test_a_position_only_reference_gives_the_same_translation_errors(data, tmp_path, euroc_runs):
    """GNSS-like ground truth (the reference stripped to ``t x y z``) and a full-pose estimate: the
    same translation numbers as the stripped estimate against the full reference, rotation null."""
    (_, full), (_, pos) = euroc_runs
    strip_to_positions(data / GT, tmp_path / "gt_positions.txt")
    out = tmp_path / "ref_pos"
    args = ["--no-offset-estimate", "--no-calibrate"]
    rc = cli.main(
        ["eval", str(tmp_path / "gt_positions.txt"), str(data / EST), "--out", str(out), *args]
    )
    assert rc in (0, None)
    ref_pos = json.loads((out / "06_metrics/metrics.json").read_text())
    assert compare_record(
        "ate", json.dumps(full["ate"]["trans_m"]), json.dumps(ref_pos["ate"]["trans_m"])
    ).ok
    assert compare_record(
        "rpe", json.dumps(pos["rpe_distance"]), json.dumps(ref_pos["rpe_distance"])
    ).ok  # D = I either way: the world-frame displacement error
    assert ref_pos["ate"]["rot_deg"] == NULL_STATS and ref_pos["position_only"] is True
    assert "the reference is position-only: every rotation error is null" in " ".join(
        ref_pos["notes"]
    )


def test_an_estimate_with_covariance_against_a_position_only_reference(tmp_path):
    """The example's OpenVINS run (with covariance) against its ground truth stripped to t x y z:
    translation errors, and no NEES (it joins rotation errors), said so."""
    from conftest import ROOT

    strip_to_positions(ROOT / "example/truth/drone_figure8.txt", tmp_path / "truth.txt")
    est = ROOT / "example/algorithms/vio_body/drone_figure8/run1.txt"
    out = tmp_path / "out"
    assert cli.main(["eval", str(tmp_path / "truth.txt"), str(est), "--out", str(out)]) in (0, None)
    nees = json.loads((out / "08_consistency/consistency.json").read_text())
    assert nees == {
        "available": False,
        "reason": "the reference is position-only: the NEES needs the rotation errors",
    }
    metrics = json.loads((out / "06_metrics/metrics.json").read_text())
    assert metrics["ate"]["rot_deg"] == NULL_STATS and metrics["ate"]["trans_m"]["n"] > 2000


def test_steps_1_and_2_of_a_position_only_estimate(data, tmp_path):
    """Step 1 on linear speed agrees with the full-pose run's angular one within its deviation;
    Step 2 is off with its reason; the translation numbers stand."""
    strip_to_positions(data / EST, tmp_path / "est_positions.txt")
    _, full = _eval(data, tmp_path, data / EST, "full")
    _, pos = _eval(data, tmp_path, tmp_path / "est_positions.txt", "pos")
    step1 = pos["sync"]["step1"]
    assert step1["signal"].startswith("linear speed") and step1["status"] == "trusted"
    assert step1["est_motion_m_s"] > 0.05 and "est_motion_rad_s" not in step1
    angular = full["sync"]["step1"]["offset"]
    assert abs(step1["offset"] - angular) < 3 * step1["std"]
    calib = pos["calibrate"]
    assert calib["step2_status"] == "disabled" and calib["extrinsic"] is None
    assert calib["step2_reason"].startswith("the estimate is position-only")
    assert pos["extrinsic_rot_deg"] is None and pos["eval_source"] == "epa"
    assert pos["ate"]["trans_m"]["rmse"] == pytest.approx(full["ate"]["trans_m"]["rmse"], abs=0.005)


# ----------------------------------------------------------------------------- a grid
def test_a_grid_marks_the_position_only_algorithms_rotation_cells(data, tmp_path, caplog):
    truth, algs = tmp_path / "truth", tmp_path / "algorithms"
    (algs / "vio_mono/MH_01_easy").mkdir(parents=True)
    (algs / "gnss/MH_01_easy").mkdir(parents=True)
    truth.mkdir()
    (truth / "MH_01_easy.txt").symlink_to(data / GT)  # left where it lies
    (algs / "vio_mono/MH_01_easy/run1.txt").symlink_to(data / EST)
    strip_to_positions(data / EST, algs / "gnss/MH_01_easy/run1.txt")
    results = tmp_path / "results"
    cfg = settings.resolve(
        {"truth_dir": str(truth), "algorithms_dir": str(algs), "results_dir": str(results)}
    )
    _, found = discovery.discover(truth, algs, cfg=cfg)
    batch = [
        {
            "key": c.key,
            "truth": str(c.truth),
            "estimate": str(c.estimate),
            "truth_source": readers.options(cfg, "reference", dataset=c.dataset),
            "estimate_source": readers.options(cfg, "estimate", algorithm=c.algorithm),
        }
        for c in found
    ]
    with caplog.at_level(logging.WARNING, logger="epa"):
        run_stages(batch, results, cfg)  # each stage reads the last one's artifacts
        assert tables.make([c.key for c in found], results, cfg) == []
    ate = (results / "tables/ate.tex").read_text().splitlines()
    gnss = next(r for r in ate if r.startswith("gnss &"))
    vio = next(r for r in ate if r.startswith("vio\\_mono &"))
    assert gnss.startswith("gnss & - / 0.204 & - / 0.204")
    assert not vio.split("&")[1].strip().startswith("-")
    for name in ("rpe_distance", "rpe_time_1s", "valid_ate", "ate_2d"):
        row = next(
            r for r in (results / f"tables/{name}.tex").read_text().splitlines() if "gnss" in r
        )
        cells = [c.strip() for c in row.rstrip(" \\").split("&")[1:]]
        assert cells and all(c.startswith("- / ") and "nan" not in c for c in cells), (name, row)
    drift_rate = (results / "tables/drift_rate.tex").read_text()
    assert "gnss & 2.221 & 1.623" in drift_rate  # translation-only tables: numbers, no mark
    with open(results / "summary.csv", encoding="utf-8") as fh:
        rows = {r["algorithm"]: r for r in csv.DictReader(fh)}
    assert rows["gnss"]["ate_rot_rmse_deg"] == "nan" and rows["vio_mono"]["notes"] == ""
    assert (
        rows["gnss"]["notes"]
        == "position-only estimate: its rotation columns are nan (no orientation)"
    )
    comparison = (results / "error_comparison.txt").read_text()
    assert "ATE: mean_ori = - | mean_pos = 0.204 (1 runs)" in comparison
    assert "RPE: seg 8 - median_ori = - | median_pos = 0.1166" in comparison
    report = (results / "cases/gnss/MH_01_easy/run1/10_report/report_en.md").read_text()
    assert "| ATE (m / deg) | 0.2039 / – |" in report
    assert "status `disabled`: the estimate is position-only" in report
    # the full-pose algorithm's numbers are its own: the same as a run of it alone
    alone = json.loads(
        (results / "cases/vio_mono/MH_01_easy/run1/06_metrics/metrics.json").read_text()
    )
    assert alone["ate"]["rot_deg"]["n"] == 3638 and "position_only" not in alone
