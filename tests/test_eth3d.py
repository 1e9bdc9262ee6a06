"""The ETH3D SLAM protocol (epa.metrics.eth3d) against the real ETH3D evaluation program's output on
EuRoC MH_01 (tests/oracles/eth3d/, README there), and hand-derived cases of its rules."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import run_stages

from epa.cli import main as cli
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import eth3d, registry
from epa.outputs import tables
from epa.readers import read_printed_quaternions
from epa.readers.image_stamps import read_image_stamps
from epa.readers.text import read_trajectory
from epa.workflow import chain, settings

ORACLE = Path(__file__).parent / "oracles" / "eth3d"
GT = "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
CAM0 = "UZ-SLAMLab_ORB_SLAM3/evaluation/Ground_truth/EuRoC_left_cam/MH01_GT.txt"
RPG = "uzh-rpg_rpg_trajectory_evaluation/results/"
ESTIMATES = {
    "vio_mono": RPG
    + "euroc_mono_stereo/laptop/vio_mono/laptop_vio_mono_MH_01/stamped_traj_estimate.txt",
    "vio_stereo": RPG
    + "euroc_mono_stereo/laptop/vio_stereo/laptop_vio_stereo_MH_01/stamped_traj_estimate.txt",
    "vislam_rp": RPG
    + "euroc_vislam_mono/laptop/vislam_rp/laptop_vislam_rp_MH_01/stamped_traj_estimate0.txt",
    "vislam_ba0": RPG
    + "euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_MH_01/stamped_ba_estimate0.txt",
    "openvins": "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv",
}
# (oracle file tag, image stamps: the cam0 images or the reference's own, the program's --sim3)
RUNS = (("cam0", "cam0", False), ("cam0.sim3", "cam0", True), ("refstamps", "reference", False))


def _as_printed(path: Path) -> Trajectory:
    """A trajectory with its quaternions as the file prints them (not normalised), as the program
    reads it: TUM rows, or the cnspy CSV's first eight columns."""
    rows = np.loadtxt(
        path, delimiter="," if path.suffix == ".csv" else None, skiprows=0, comments=("#", "t,")
    )
    return Trajectory(rows[:, 0], rows[:, 1:4], rows[:, 4:8])


def _lines(text: str) -> list[tuple[str, float | None]]:
    """Each printed line as (label, number); a line without a number as (line, None)."""
    out = []
    for line in text.splitlines():
        label, _, value = line.rpartition(" ")
        if label.endswith("]:"):
            out.append((label, float(value)))
        else:
            out.append((line, None))
    return out


def _compare(mine: str, theirs: str, tol) -> float:
    """Asserts the same lines, each number within ``tol(label)`` relative; returns the largest."""
    a, b = _lines(mine), _lines(theirs)
    assert [x[0] for x in a] == [x[0] for x in b]
    worst = 0.0
    for (label, x), (_, y) in zip(a, b):
        if y is not None:
            rel = abs(x - y) / abs(y)
            assert rel <= tol(label), (label, x, y, rel)
            worst = max(worst, rel)
    return worst


def _stamps(data, which: str, reference: Trajectory) -> np.ndarray:
    return read_image_stamps(data / CAM0, "ns") if which == "cam0" else reference.t


@pytest.mark.parametrize("name", ESTIMATES)
def test_the_programs_arithmetic_on_the_files_as_printed(data, name):
    """With the quaternions as the files print them, every printed number of the real program, to
    1e-12 relative: measured at most 7.5e-14 (the last of 14 digits; 229 of 250 lines identical),
    from LAPACK's SVD against Eigen's and the order of a quaternion product's terms."""
    reference, estimate = _as_printed(data / GT), _as_printed(data / ESTIMATES[name])
    for tag, which, sim3 in RUNS:
        record, _ = eth3d.evaluate(reference, estimate, _stamps(data, which, reference), sim3=sim3)
        _compare(eth3d.printed(record), (ORACLE / f"{name}.{tag}.txt").read_text(), lambda _: 1e-12)


def _through_epica(path: Path) -> Trajectory:
    """A file as the eth3d metric has it: epica's reader (unit quaternions), its quaternions then
    replaced by those the file prints (read again with the same settings, matched by stamp)."""
    read = read_trajectory(path)
    printed = eth3d.as_printed(read, read_printed_quaternions(path, {}))
    assert printed is not None and np.array_equal(printed.t, read.t)
    return printed


@pytest.mark.parametrize("name", ESTIMATES)
def test_the_program_through_epicas_readers(data, name):
    """Through epica's readers, with the quaternions as printed put back: the program's numbers to
    the tolerance of the files as printed (1e-12; the ground truth prints 6-digit quaternions, which
    normalised moved the relative translation errors by up to 3.8e-5)."""
    reference = _through_epica(data / GT)
    estimate = _through_epica(data / ESTIMATES[name])
    for tag, which, sim3 in RUNS:
        record, _ = eth3d.evaluate(reference, estimate, _stamps(data, which, reference), sim3=sim3)
        theirs = (ORACLE / f"{name}.{tag}.txt").read_text()
        _compare(eth3d.printed(record), theirs, lambda _: 1e-12)


def test_normalised_quaternions_miss_the_printed_digit(data):
    """Why they are read again: with epica's unit quaternions the relative translation errors
    leave the program's by more than the printed digit (measured 3.8e-5 relative)."""
    reference = read_trajectory(data / GT)
    estimate = read_trajectory(data / ESTIMATES["vio_mono"])
    record, _ = eth3d.evaluate(reference, estimate, reference.t)
    theirs = (ORACLE / "vio_mono.refstamps.txt").read_text()
    with pytest.raises(AssertionError):
        _compare(eth3d.printed(record), theirs, lambda _: 1e-12)
    assert _compare(eth3d.printed(record), theirs, lambda _: 1e-4) > 1e-7


def test_quaternions_as_printed_by_source(tmp_path):
    """A text file's quaternions come back as printed (here twice unit length), matched to the
    cropped poses by stamp; a KITTI file, positions only or a pose without a twin give None, and
    the metric then says it keeps epica's unit quaternions."""
    tum = tmp_path / "a.txt"
    tum.write_text("1.0 0 0 0 0 0 0 2\n2.0 1 0 0 0 0 1.2 1.6\n3.0 2 0 0 0 0 0 2\n")
    read = read_trajectory(tum)
    raw = read_printed_quaternions(tum, {})
    assert raw is not None and raw.q.tolist() == [[0, 0, 0, 2], [0, 0, 1.2, 1.6], [0, 0, 0, 2]]
    assert read.q[1].tolist() == pytest.approx([0, 0, 0.6, 0.8])
    kept = eth3d.as_printed(read.select(np.array([False, True, True])), raw)
    assert kept is not None and kept.q.tolist() == [[0, 0, 1.2, 1.6], [0, 0, 0, 2]]
    moved = Trajectory(read.t, read.p + 1e-9, read.q)  # not the file's poses: no twin
    assert eth3d.as_printed(moved, raw) is None
    kitti = tmp_path / "k.txt"
    kitti.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n")
    assert read_printed_quaternions(kitti, {"format": "kitti"}) is None
    positions = tmp_path / "p.txt"
    positions.write_text("1.0 0 0 0\n2.0 1 0 0\n")
    assert read_printed_quaternions(positions, {"format": "position"}) is None
    cfg = settings.resolve({"truth_dir": "t", "algorithms_dir": "a"})
    cfg["metrics"]["eth3d"]["max_interpolation_timespan"] = 2.0  # 1 s steps
    _, _, notes = eth3d.compute(
        read,
        read,
        cfg,
        reference=read,
        estimate=read,
        image_stamps=None,
        printed_quaternions=(raw, None),
    )
    assert [n for n in notes if "normalised ones" in n] == [notes[0]] and "estimate's" in notes[0]


def test_few_pairs_warn_and_no_pairs_print_nothing(data):
    """80 images in motion: fewer than 50 pairs at 0.5 and 1 m (the program's warning), none at 1.5
    and 2 m (not printed): the program's lines, its numbers to 1e-12 (byte-identical on this CPU's
    default path; numbers made by another program are never compared bit for bit: the baseline
    numpy/OpenBLAS path moves the 17th digit)."""
    reference, estimate = _as_printed(data / GT), _as_printed(data / ESTIMATES["vislam_ba0"])
    stamps = read_image_stamps(data / CAM0, "ns")[1000:1080]
    record, _ = eth3d.evaluate(reference, estimate, stamps)
    theirs = (ORACLE / "vislam_ba0.cam0_1000_1080.txt").read_text()
    _compare(eth3d.printed(record), theirs, lambda _: 1e-12)
    assert [r["n_pairs"] for r in record["modes"][0]["relative"]][2:] == [0, 0]


def test_an_estimate_ending_before_the_images_prints_no_numbers(data):
    reference = read_trajectory(data / GT)
    early = Trajectory(
        np.array([1403636570.0, 1403636575.0]), np.eye(3)[:2], np.tile([0, 0, 0, 1.0], (2, 1))
    )
    record, errors = eth3d.evaluate(reference, early, read_image_stamps(data / CAM0, "ns"))
    assert not record["available"] and errors == {}
    assert eth3d.printed(record) == (ORACLE / "early.txt").read_text()


# ----------------------------------------------------------------------------- hand-derived rules
def _loop_pairs(d, distance, tol):
    """The program's pair search written as its loop (a test oracle for the vectorised one)."""
    out, s, n = [], 0, len(d)
    for i in range(n):
        goal = d[i] + distance
        ref = abs(goal - d[s])
        ended = False
        while abs(goal - d[s + 1]) < ref:
            s += 1
            if s >= n - 1:
                ended = True
                break
        if ended:
            break
        if i != s and not abs((d[s] - d[i]) - distance) > tol:
            out.append((i, s))
    return out


def test_pair_search_by_hand():
    # 0.1 m steps: for 0.5 m the walk from pose 0 runs past the target to 1.0 m (its reference
    # distance is from where it started, 0.5 m): pose 9 (0.9 m); its pair is 0.9 m long, dropped.
    d = np.arange(21) * 0.1
    first, second = eth3d.pairs(d, 0.5, 0.025)
    assert (first[0], second[0]) == (4, 9)  # the first pair kept: 0.4 -> 0.9 m
    assert list(zip(first.tolist(), second.tolist())) == _loop_pairs(d, 0.5, 0.025)
    # the walk steps over a zero-length step (its reference distance is stale) but never leaves
    # one it stands on: a reference standing still over the first two images has no pair at all
    d = np.array([0.0, 0.0, 0.3, 0.6, 0.9, 1.2, 1.5])
    assert eth3d.pairs(d, 0.3, 0.025)[0].tolist() == [] == _loop_pairs(d, 0.3, 0.025)
    assert len(eth3d.pairs(d[1:], 0.3, 0.025)[0]) == 4


def test_pair_search_equals_the_programs_loop(rng):
    """9000 random paths with zero-length and uneven steps: the same pairs as the loop."""
    for trial in range(3000):
        n = int(rng.integers(2, 60))
        steps = rng.choice([0.0, 0.01, 0.05, 0.1, 0.3, 0.7], size=n - 1) * rng.random(n - 1)
        d = np.concatenate([[0.0], np.cumsum(np.round(steps, 2) if trial % 3 else steps)])
        for distance in (0.05, 0.5, 1.0):
            first, second = eth3d.pairs(d, distance, 0.025)
            assert list(zip(first.tolist(), second.tolist())) == _loop_pairs(d, distance, 0.025)


def test_reference_drops_and_estimate_holds():
    t = np.array([0.0, 0.01, 0.02, 0.1, 0.11])
    p = np.column_stack([t * 10, 0 * t, 0 * t])
    q = np.tile([0, 0, 0, 1.0], (5, 1))
    stamps = np.array([-0.5, 0.0, 0.005, 0.05, 0.105, 0.11, 0.2])
    keep, p_at, _ = eth3d.poses_at(t, p, q, stamps, 1 / 75)
    # before the first pose, across the 0.08 s gap, at and after the last pose: dropped
    assert keep.tolist() == [False, True, True, False, True, False, False]
    assert p_at[:, 0].tolist() == pytest.approx([0.0, 0.05, 1.05])
    keep, p_at, _ = eth3d.poses_at(t, p, q, stamps, None)
    assert keep.all()
    assert p_at[:, 0].tolist() == pytest.approx([0.0, 0.0, 0.05, 0.5, 1.05, 1.1, 1.1])


def test_missing_output_is_penalised():
    """An estimate that stops halfway is held at its last pose: the ATE grows by exactly that."""
    t = np.arange(201) * 0.05
    p = np.column_stack([t, 0 * t, 0 * t])  # 1 m/s along x
    q = np.tile([0, 0, 0, 1.0], (201, 1))
    reference = Trajectory(t, p, q)
    whole, _ = eth3d.evaluate(reference, reference, t, max_interpolation_timespan=0.1)
    assert whole["modes"][0]["ate_rmse_cm"] == pytest.approx(0.0, abs=1e-9)
    assert whole["modes"][0]["relative"][1]["translation_pct"] == pytest.approx(0.0, abs=1e-9)
    half = reference.select(t <= 5.0)
    record, _ = eth3d.evaluate(reference, half, t, max_interpolation_timespan=0.1)
    assert (
        record["n_held"] == 99
    )  # image stamps 5.05 .. 9.95 (the last one dropped, no reference after it)
    # by hand: 1-D positions, the stopped estimate's best SE3 fit is a shift along x
    kept = t[:-1]
    est = np.minimum(kept, 5.0)
    shift = np.mean(kept - est)
    expected = 100 * math.sqrt(np.mean((kept - est - shift) ** 2))
    assert record["modes"][0]["ate_rmse_cm"] == pytest.approx(expected, rel=1e-9)


def test_an_estimate_after_the_images_has_no_fit():
    """Held at its first pose at every image stamp: no alignment, no NaN (the program's would be)."""
    t = np.arange(100) * 0.01
    reference = Trajectory(t, np.column_stack([t, 0 * t, 0 * t]), np.tile([0, 0, 0, 1.0], (100, 1)))
    late = reference.shifted(5.0)
    record, errors = eth3d.evaluate(reference, late, t)
    assert not record["available"] and "no alignment" in record["reason"] and errors == {}
    assert eth3d.printed(record) == ""


def test_sim3_only_with_the_flag_and_scale_absorbed():
    t = np.arange(400) * 0.05
    p = np.column_stack([np.sin(t), np.cos(t), 0.1 * t])
    q = np.tile([0, 0, 0, 1.0], (400, 1))
    reference = Trajectory(t, p, q)
    scaled = Trajectory(t, 0.5 * p + 3.0, q)
    record, _ = eth3d.evaluate(reference, scaled, t, sim3=True, max_interpolation_timespan=0.1)
    assert [m["mode"] for m in record["modes"]] == ["SIM3"]
    assert record["modes"][0]["scale"] == pytest.approx(2.0, rel=1e-12)
    assert record["modes"][0]["ate_rmse_cm"] == pytest.approx(0.0, abs=1e-9)
    both, _ = eth3d.evaluate(reference, scaled, t, max_interpolation_timespan=0.1)
    assert [m["mode"] for m in both["modes"]] == ["SE3", "SIM3"]
    assert both["modes"][0]["ate_rmse_cm"] > 10


def test_sim3_relative_translation_by_hand():
    """The program's Sim3 quirk, derived by hand: an estimate at half the scale, its rotations exact.
    The fit is s = 2, R = I; the program's quaternion of 2 I is (0, 0, 0, sqrt(7)/2), of squared norm
    7/4, so the aligned estimate's relative translation, turned by the inverse of that quaternion
    times q_j (squared norm 4/7) with a formula for unit quaternions, is (4/7) R_j^T d + (3/7) d for
    d = p_i - p_j, where the reference's is R_j^T d: the error is (3/7) |d - R_j^T d|."""
    t = np.arange(600) * 0.01
    yaw = 0.8 * np.sin(t)
    p = np.column_stack([np.cos(t), np.sin(t), 0.2 * t])
    q = np.column_stack([0 * t, 0 * t, np.sin(yaw / 2), np.cos(yaw / 2)])
    reference = Trajectory(t, p, q)
    half = Trajectory(t, 0.5 * p, q)
    record, _ = eth3d.evaluate(reference, half, t, sim3=True, max_interpolation_timespan=0.1)
    assert record["modes"][0]["ate_rmse_cm"] == pytest.approx(0.0, abs=1e-9)
    d_path = eth3d.path_from_start(p[:-1])  # the last stamp has no reference pose after it
    for rel in record["modes"][0]["relative"]:
        i, j = eth3d.pairs(d_path, rel["distance_m"], 0.025)
        d = p[i] - p[j]
        c, s = np.cos(yaw[j]), np.sin(yaw[j])
        back = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
        err = 100 * (3 / 7) * np.linalg.norm(d - back, axis=1) / (d_path[j] - d_path[i])
        assert rel["n_pairs"] == len(i) > 50
        assert rel["translation_pct"] == pytest.approx(np.mean(err), rel=1e-9)
        assert rel["rotation_deg_per_m"] == pytest.approx(0.0, abs=1e-9)


def test_bad_image_stamps(tmp_path):
    reference = Trajectory(np.arange(10.0), np.zeros((10, 3)), np.tile([0, 0, 0, 1.0], (10, 1)))
    with pytest.raises(EpaError, match="0 of 2 image stamps lie between two reference poses"):
        eth3d.evaluate(reference, reference, np.array([20.0, 21.0]))
    with pytest.raises(EpaError, match="not sorted"):
        eth3d.evaluate(reference, reference, np.array([2.0, 1.0]))
    path = tmp_path / "rgb.txt"
    path.write_text("# images\n1.0 rgb/1.png\n2.5 rgb/2.png\n")
    assert read_image_stamps(path).tolist() == [1.0, 2.5]
    path.write_text("1403636580863555584,a.png\n1403636580913555456.000,b.png\n")
    assert read_image_stamps(path, "ns").tolist() == [1403636580.863555584, 1403636580.913555456]
    path.write_text("1.0\n2.0\nx\n")
    with pytest.raises(EpaError, match=r"rgb.txt:3: image stamp 'x' is not a number"):
        read_image_stamps(path)
    path.write_text("1.5\n")
    with pytest.raises(EpaError, match="not an integer of nanoseconds"):
        read_image_stamps(path, "ns")


# ----------------------------------------------------------------------------- through epica
def test_registered_as_a_protocol():
    assert "eth3d" in registry.protocols()
    metric = next(m for m in registry.REGISTRY if m.key == "eth3d")
    assert metric.inputs == ("reference", "estimate", "image_stamps", "printed_quaternions")


def test_epa_eval_writes_the_programs_output(data, tmp_path):
    """``epa eval`` with metrics.eth3d on: the record, the per-pair errors, the printed lines (the
    files' quaternions as printed: the program's numbers to 1e-12)."""
    config = tmp_path / "cfg.yaml"
    config.write_text(
        f"metrics:\n  eth3d:\n    enabled: true\n    image_stamps: {data / CAM0}\n    image_stamps_unit: ns\n"
    )
    out = tmp_path / "out"
    rc = cli.main(
        [
            "eval",
            str(data / GT),
            str(data / ESTIMATES["vio_stereo"]),
            "--out",
            str(out),
            "--config",
            str(config),
        ]
    )
    assert rc == 0
    record = json.loads((out / "06_metrics" / "metrics.json").read_text())["eth3d"]
    assert record["available"] and record["n_images"] == 3638 and record["n_held"] == 0
    notes = json.loads((out / "06_metrics" / "metrics.json").read_text())["notes"]
    assert not [n for n in notes if "normalised ones" in n]  # both files' quaternions as printed
    text = (out / "06_metrics" / "eth3d" / "eth3d.txt").read_text()
    _compare(text, (ORACLE / "vio_stereo.cam0.txt").read_text(), lambda _: 1e-12)


def test_a_bag_keeps_epicas_unit_quaternions_with_a_note(data, tmp_path):
    """An estimate from a bag: its quaternions are epica's unit ones (a note says so), the text
    reference's as printed; the relative errors then stay within 1e-4 of the program's on the text
    file the bag was written from (normalised: up to 3.8e-5)."""
    from bag_fixture import write_bag

    estimate = read_trajectory(data / ESTIMATES["vio_stereo"])
    bag = tmp_path / "est.bag"
    write_bag(bag, {"/pose": ("geometry_msgs/msg/PoseStamped", estimate)})
    out = tmp_path / "out"
    rc = cli.main(
        ["eval", str(data / GT), str(bag), "--est-topic", "/pose", "--protocol", "eth3d"]
        + ["--out", str(out)]
    )
    assert rc == 0
    notes = json.loads((out / "06_metrics" / "metrics.json").read_text())["notes"]
    assert [n for n in notes if "normalised ones" in n] == [
        next(n for n in notes if n.startswith("eth3d: the estimate's quaternions"))
    ]
    text = (out / "06_metrics" / "eth3d" / "eth3d.txt").read_text()
    _compare(text, (ORACLE / "vio_stereo.refstamps.txt").read_text(), lambda _: 1e-4)


def test_a_grid_with_eth3d_on_has_its_table_and_columns(data, tmp_path):
    """Each stage a job; the case folder's dataset names the image stamps file ({dataset})."""
    stamps = tmp_path / "stamps" / "MH_01.csv"
    stamps.parent.mkdir()
    first = (data / CAM0).read_text().splitlines(keepends=True)[:1000]  # the first 999 images
    stamps.write_text("".join(first))  # in tmp_path: no data file is kept in the project
    cfg = settings.resolve(
        {
            "truth_dir": str(tmp_path),
            "algorithms_dir": str(tmp_path),
            "metrics": {
                "eth3d": {
                    "enabled": True,
                    "image_stamps": str(tmp_path / "stamps" / "{dataset}.csv"),
                    "image_stamps_unit": "ns",
                }
            },
        }
    )
    cases = [
        {
            "key": f"{name}/MH_01/run1",
            "truth": str(data / GT),
            "estimate": str(data / ESTIMATES[name]),
        }
        for name in ("vio_stereo", "vislam_rp")
    ]
    out = tmp_path / "results"
    run_stages(cases, out, cfg, chain.NAMES[:-1])  # every stage but the report
    assert tables.make([c["key"] for c in cases], out, cfg) == []
    summary = (out / "summary.csv").read_text().splitlines()
    header = summary[0].split(",")
    row = dict(zip(header, next(r for r in summary if r.startswith("vio_stereo,")).split(",")))
    record = json.loads((out / "cases/vio_stereo/MH_01/run1/06_metrics/metrics.json").read_text())
    assert not [n for n in record["notes"] if "normalised ones" in n]  # read again by the job
    record = record["eth3d"]
    n_images = len(read_image_stamps(stamps, "ns"))
    assert record["image_stamps"].endswith("{dataset}.csv") and record["n_images"] == n_images
    se3 = record["modes"][0]["ate_rmse_cm"]
    assert float(row["eth3d_se3_ate_rmse_cm"]) == pytest.approx(se3, rel=1e-8)  # 9 digits printed
    tex = (out / "tables/eth3d.tex").read_text()
    assert "ETH3D SLAM" in tex and f"{se3:.3f}" in tex and "eth3d" in tables.table_names(cfg)
    assert "ETH3D SLAM" in (out / "error_comparison.txt").read_text()
    off = settings.resolve({"truth_dir": "t", "algorithms_dir": "a"})
    assert "eth3d" not in tables.table_names(off)


def test_no_eth3d_columns_where_it_is_off(tmp_path):
    from epa.metrics import eth3d
    from epa.outputs.tables import summary

    assert not any(c.startswith("eth3d_") for c in summary.columns([8], 1.0, metrics=()))
    on = summary.columns([8], 1.0, metrics=(eth3d.METRIC,))
    assert [c for c in on if c.startswith("eth3d_")] == list(eth3d.METRIC.summary_columns)
