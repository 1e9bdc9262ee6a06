"""Settings per cell (overrides, metric_scale: false), a fallback that keeps the asked alignment, the
scale check that makes a misfit loud, and segment lengths per dataset: on hand-made settings, on a
Snakemake grid (what an edited override re-runs) and on real ORB-SLAM3 mono and stereo runs of
EuRoC MH_01 against evo's Sim3."""

import json
import shutil

import numpy as np
import pytest
from conftest import ROOT, smooth_path

from epa.artifacts import files
from epa.artifacts.case import Case
from epa.cli import main as cli
from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import accuracy, rpg
from epa.workflow import chain, overrides, settings

BASE = {"truth_dir": ".", "algorithms_dir": "."}


def resolved(**extra):
    return settings.resolve({**BASE, **extra})


# ----------------------------------------------------------------------------- precedence
def test_the_most_specific_setting_wins():
    cfg = resolved(
        align={"method": "posyaw"},
        overrides={
            "datasets": {"kitti_*": {"align": {"method": "se3"}, "metrics": {"segments": "kitti"}}},
            "algorithms": {
                "orb*": {"align": {"first_n": 100}},
                "orb_mono": {"align": {"first_n": 50}},
            },
            "cases": {"orb_mono/kitti_00": {"align": {"method": "none"}}},
        },
    )
    grid_only = overrides.for_case(cfg, "vins", "MH_01")
    assert grid_only.applied == () and grid_only.changed == {}
    kitti = overrides.for_case(cfg, "vins", "kitti_05")
    assert kitti.changed["align"] == {"method": "se3", "first_n": -1}
    assert kitti.changed["metrics"]["segments"] == "kitti"
    # an algorithm's name beats its glob, a cell beats both, each key on its own
    cell = overrides.for_case(cfg, "orb_mono", "kitti_00")
    assert cell.changed["align"] == {"method": "none", "first_n": 50}
    assert cell.applied == (
        "overrides.datasets.kitti_*",
        "overrides.algorithms.orb*",
        "overrides.algorithms.orb_mono",
        "overrides.cases.orb_mono/kitti_00",
    )
    # the grid's other sections are untouched
    case_cfg = overrides.case_config(cfg, cell.changed)
    assert case_cfg["sync"] is cfg["sync"] and case_cfg["align"]["method"] == "none"


def test_two_patterns_of_one_level_that_disagree_are_an_error():
    cfg = resolved(
        overrides={
            "algorithms": {
                "orb*": {"align": {"method": "sim3"}},
                "*mono": {"align": {"method": "se3"}},
            }
        }
    )
    with pytest.raises(
        EpaError, match=r"overrides.algorithms.orb\* and overrides.algorithms.\*mono"
    ):
        overrides.for_case(cfg, "orb_mono", "MH_01")
    assert overrides.for_case(cfg, "orb_stereo", "MH_01").changed["align"]["method"] == "sim3"


def test_metric_scale_false_means_step_2_scale_and_sim3_in_every_mode():
    for mode, want in (("epa", {"scale": True}), ("ov_eval", {}), ("rpg", {})):
        cfg = resolved(mode=mode, sources={"algorithms": {"mono": {"metric_scale": False}}})
        own = overrides.for_case(cfg, "mono", "d")
        assert own.changed["align"]["method"] == "sim3"
        assert ("calibrate" in own.changed) is bool(want)
        assert own.applied[-1].startswith("sources.algorithms.mono.metric_scale: false")
        assert overrides.for_case(cfg, "stereo", "d").applied == ()
    cfg = resolved(
        sources={"algorithms": {"mono": {"metric_scale": False}}},
        overrides={"algorithms": {"mono": {"align": {"method": "se3"}}}},
    )
    with pytest.raises(
        EpaError,
        match="metric_scale: false needs align.method: .sim3.*overrides.algorithms.mono sets",
    ):
        overrides.for_case(cfg, "mono", "d")


def test_a_pattern_that_matches_nothing_is_an_error_naming_it():
    cases = [Case("vins", "MH_01", "r1"), Case("orb", "MH_02", "r1")]
    for given, says in (
        ({"algorithms": {"vnis": {}}}, "overrides.algorithms.vnis: matches no algorithm"),
        ({"datasets": {"kitti*": {}}}, "overrides.datasets.kitti*: matches no dataset"),
        ({"cases": {"orb/MH_03": {}}}, "overrides.cases.orb/MH_03: matches no cell"),
    ):
        with pytest.raises(EpaError, match=says.replace("*", r"\*")):
            overrides.for_grid(resolved(overrides=given), cases)
    cfg = resolved(overrides={"cases": {"orb/MH_0*": {"drift": {"mode": "scale_aware"}}}})
    assert list(overrides.for_grid(cfg, cases)) == ["orb/MH_02/r1"]


@pytest.mark.parametrize(
    "config, says",
    [
        ("overrides: {algorithms: {a: {align: {methd: sim3}}}}", "overrides.algorithms.a.align: "),
        ("overrides: {algorithms: {a: {mode: rpg}}}", "overrides.algorithms.a: "),
        ("overrides: {cases: {a: {}}}", "overrides.cases: "),
        ("overrides: {datasets: {d: {crop: {start: 5, end: 2}}}}", "crop.end (2) must be after"),
        ("metrics: {segments: autox}", "metrics.segments: "),
    ],
)
def test_a_bad_override_is_one_line_naming_the_key(tmp_path, capsys, config, says):
    files.write_trajectory(tmp_path / "ref.txt", smooth_path(), "tum")
    (tmp_path / "cfg.yaml").write_text(config + "\n")
    argv = [
        "eval",
        str(tmp_path / "ref.txt"),
        str(tmp_path / "ref.txt"),
        "--out",
        str(tmp_path / "o"),
    ]
    assert cli.main(argv + ["--config", str(tmp_path / "cfg.yaml"), "--dataset", "d"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("epa: error: ") and says in err and err.count("\n") == 1


# ----------------------------------------------------------------------------- segment lengths
def test_auto_and_kitti_segment_lengths():
    assert accuracy.segment_lengths("auto", 91.74) == [9.17, 18.34, 27.52, 36.69, 45.87]
    assert accuracy.segment_lengths("auto", 91.74) == rpg.boxplot_distances(91.74)
    assert accuracy.segment_lengths("kitti", 5.0) == [100.0 * k for k in range(1, 9)]
    assert accuracy.segment_lengths([8, 16], 5.0) == [8.0, 16.0]


def _estimate(ref: Trajectory, scale: float) -> Trajectory:
    r0 = geometry.so3_exp(np.array([0.0, 0.0, 0.7]))
    return Trajectory(
        ref.t, scale * ref.p @ r0.T + [1.0, 2.0, 0.0], geometry.rot_to_quat(r0 @ ref.r)
    )


# ----------------------------------------------------------------------------- a Snakemake grid
@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """Two datasets, a metric algorithm and an undeclared one at scale 0.3, run by Snakemake with
    defaults."""
    from test_workflow import smk

    root = tmp_path_factory.mktemp("cells")
    for ds, n in (("office", 600), ("hall", 500)):
        ref = smooth_path(n)
        files.write_trajectory(root / f"truth/{ds}.txt", ref, "tum")
        files.write_trajectory(root / f"algs/stereo/{ds}/run1.txt", _estimate(ref, 1.0), "tum")
        files.write_trajectory(root / f"algs/mono/{ds}/run1.txt", _estimate(ref, 0.3), "tum")
    (root / "cfg.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\n"
        "sync: {estimate_offset: false}\ncalibrate: {enabled: false}\n"
    )
    smk(root)
    return root


def _doc(results, key):
    return json.loads((results / "cases" / key / "06_metrics/metrics.json").read_text())


def test_with_defaults_an_undeclared_monocular_estimate_is_flagged(grid):
    results = grid / "results"
    mono = _doc(results, "mono/office/run1")
    assert mono["sim3_check"]["scale"] == pytest.approx(1 / 0.3, rel=1e-6)
    assert "metric_scale: false" in mono["sim3_check"]["warning"]
    assert _doc(results, "stereo/office/run1")["sim3_check"]["warning"] is None
    flags = json.loads((results / "cases/mono/office/run1/10_report/report.json").read_text())
    assert any("metric_scale: false" in f for f in flags["flags"])
    assert (
        results / "cases/mono/office/run1/10_report/figures"
    ).is_dir()  # a flagged case is drawn
    row = next(
        r for r in (results / "summary.csv").read_text().splitlines() if r.startswith("mono,office")
    )
    assert "metric_scale: false" in row
    # the end-of-run summary names the case and the setting that fixes it, for its algorithm
    from epa.outputs import tables

    summary = tables.failure_report(results / "summary.csv")
    assert (
        "mono: 0 of 2 cases fell back to the ov_eval way (Step 1 or 2 not trusted), 2 flagged"
        in summary
    )
    assert "mono/office/run1: sim3_check: " in summary
    assert "declare sources.algorithms.mono.metric_scale: false" in summary
    # and every table marks its cells
    assert "mono & " in (results / "tables/ate.tex").read_text()
    assert "\\textsuperscript{f}" in (results / "tables/ate.tex").read_text()


def _planned(root) -> set[str]:
    """The batches a dry run would run a stage job for."""
    from test_workflow import smk

    out = smk(root, "-n")
    return {line.split("batch=", 1)[1].strip() for line in out.splitlines() if "batch=" in line}


def test_an_edited_override_reruns_only_the_cases_it_matches(grid, tmp_path):
    from test_workflow import smk

    root = tmp_path / "g"
    shutil.copytree(grid, root, symlinks=True)
    cfg = (root / "cfg.yaml").read_text()
    (root / "cfg.yaml").write_text(
        cfg + "overrides: {algorithms: {mono: {align: {method: sim3}}}}\n"
    )
    assert _planned(root) == {"mono/office/run1", "mono/hall/run1"}
    smk(root)
    mono = _doc(root / "results", "mono/office/run1")
    assert mono["alignment"]["method"] == "sim3"
    assert mono["ate"]["trans_m"]["rmse"] < 1e-9  # the injected scale is exactly undone
    # Sim3 for an algorithm not declared monocular: the scale may hide a failure, said so
    assert "declare metric_scale: false" in mono["sim3_check"]["warning"]
    assert mono["load"]["settings"]["applied"] == ["overrides.algorithms.mono"]
    assert mono["load"]["settings"]["changed"]["align"] == {"method": "sim3", "first_n": -1}
    assert "settings" not in _doc(root / "results", "stereo/office/run1")["load"]
    # a dataset's override: that dataset's cases only
    (root / "cfg.yaml").write_text(
        cfg + "overrides: {algorithms: {mono: {align: {method: sim3}}},"
        " datasets: {hall: {drift: {mode: scale_aware}}}}\n"
    )
    assert _planned(root) == {"mono/hall/run1", "stereo/hall/run1"}


# ----------------------------------------------------------------------------- real data
def _real(data):
    ref = data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
    mono = data / "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_mono.txt"
    return ref, mono


def _evo_sim3_rmse(ref: Trajectory, est: Trajectory) -> float:
    """evo's own Sim3 alignment (Umeyama with scale) and APE translation RMSE on matched poses."""
    evo_traj = pytest.importorskip("evo.core.trajectory")
    from evo.core import metrics as em

    def pose(t: Trajectory):
        return evo_traj.PoseTrajectory3D(t.p.copy(), t.q[:, [3, 0, 1, 2]].copy(), t.t.copy())

    r, e = pose(ref), pose(est)
    e.align(r, correct_scale=True)
    ape = em.APE(em.PoseRelation.translation_part)
    ape.process_data((r, e))
    return float(ape.get_statistic(em.StatisticsType.rmse))


def test_real_monocular_with_defaults_is_flagged_never_a_silent_number(data, tmp_path):
    ref, mono = _real(data)
    m = chain.run_case(ref, mono, tmp_path / "o", resolved())["metrics"]
    check = m["sim3_check"]
    assert m["alignment"]["method"] == "se3" and m["ate"]["trans_m"]["rmse"] > 3.0
    assert check["scale"] == pytest.approx(5.15, abs=0.02) and check["error_removed"] > 0.98
    assert "metric_scale: false" in check["warning"]


def test_real_monocular_declared_agrees_with_evo_sim3_on_the_same_association(data, tmp_path):
    """metric_scale: false: Step 2 solves the scale (5.17, as the data's notes give it), Step 3
    fits Sim3; the ATE is evo's Sim3 APE of the same calibrated, matched poses."""
    ref, mono = _real(data)
    cfg = resolved(sources={"algorithms": {"estimate": {"metric_scale": False}}})
    case_cfg, own = overrides.one_case(cfg, "estimate", "MH_01")
    out = chain.run_case_data(ref, mono, tmp_path / "o", case_cfg, keep=("calibrated",))
    m = out.metrics_record
    assert m["eval_source"] == "epa" and m["alignment"]["method"] == "sim3"
    used = m["sim3_check"]["evaluated_scale"]
    assert used["fitted_by"] == "step2+step3" and used["value"] == pytest.approx(5.17, abs=0.01)
    assert 0 < used["std"] < 0.01 and m["sim3_check"]["warning"] is None
    rmse = m["ate"]["trans_m"]["rmse"]
    assert rmse == pytest.approx(0.0186, abs=5e-4)
    # evo on the same association (the Step 1-2 corrected estimate): the same Umeyama, 1e-9 m
    assert rmse == pytest.approx(_evo_sim3_rmse(*out.calibrated), abs=1e-9)


def test_real_fallback_keeps_the_asked_sim3(data, tmp_path):
    """--align sim3 without the declaration: Step 2 (no scale) is not trusted on a monocular run,
    so the case falls back without Steps 1-2, and stays Sim3: evo_ape -as's number (0.0382 m)."""
    ref, mono = _real(data)
    out = chain.run_case_data(
        ref, mono, tmp_path / "o", resolved(align={"method": "sim3"}), keep=("calibrated",)
    )
    m = out.metrics_record
    plan = m["calibrate"]["plan"]
    assert plan["fallback"] and plan["eval_source"] == "ov_eval"
    assert [d.split(" ")[0] for d in plan["dropped"]] == ["Step", "Step"]
    assert m["alignment"] == {**m["alignment"], "method": "sim3", "fallback": True}
    rmse = m["ate"]["trans_m"]["rmse"]
    assert rmse == pytest.approx(0.0382, abs=5e-4)
    assert rmse == pytest.approx(_evo_sim3_rmse(*out.calibrated), abs=1e-9)


def test_auto_segments_are_rpgs_distances_on_rpgs_results(data, tmp_path):
    """rpg's own example results (vislam_rp on MH_04): segments auto in mode epa gives the
    distances rpg prints for the case (its files relative_error_statistics_9_2.yaml, ...), the ones
    mode rpg computes."""
    ref = data / "rpng_open_vins/ov_data/euroc_mav/MH_04_difficult.txt"
    est = (
        data / "uzh-rpg_rpg_trajectory_evaluation/results/euroc_vislam_mono/laptop/vislam_rp"
        "/laptop_vislam_rp_MH_04/stamped_traj_estimate0.txt"
    )
    auto = chain.run_case(ref, est, tmp_path / "a", resolved(metrics={"segments": "auto"}))
    lengths = accuracy.recorded_lengths(auto["metrics"])
    rpg_mode = chain.run_case(ref, est, tmp_path / "r", resolved(mode="rpg"))["metrics"]["rpg"]
    assert lengths == rpg_mode["distances_m"]
    import yaml

    expected = yaml.safe_load((ROOT / "tests/rpg_expected.yaml").read_text())
    names = [n for n in expected["vislam_rp_MH_04_se3_1"]["listing"] if n.startswith("relative")]
    printed = sorted(
        float(n[len("relative_error_statistics_") : -5].replace("_", ".")) for n in names
    )
    assert [round(x, 1) for x in lengths] == printed


def test_mode_rpg_takes_each_estimate_folders_eval_cfg(data, tmp_path):
    """rpg sets the alignment per estimate folder (eval_cfg.yaml): in mode rpg each case takes its
    folder's, over the grid's align; the config's overrides still win; metric_scale: false against
    a folder's posyaw is an error naming the file."""
    rpg_results = data / "uzh-rpg_rpg_trajectory_evaluation/results/euroc_mono_stereo/laptop"
    folder = rpg_results / "vio_stereo/laptop_vio_stereo_MH_01"
    est = folder / "stamped_traj_estimate.txt"
    case = Case("vio_stereo", "MH_01", "run1", estimate=est)
    cfg = resolved(mode="rpg", align={"method": "se3"})
    own = overrides.for_grid(cfg, [case])[case.key]
    assert own.applied == (str(folder / "eval_cfg.yaml"),)
    assert own.changed["align"] == {"method": "posyaw", "first_n": -1}
    ref = data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
    m = chain.run_case(ref, est, tmp_path / "o", overrides.case_config(cfg, own.changed))["metrics"]
    assert m["rpg"]["align_type"] == "posyaw" and m["alignment"]["method"] == "posyaw"
    cfg = resolved(
        mode="rpg", overrides={"algorithms": {"vio_stereo": {"align": {"method": "sim3"}}}}
    )
    assert overrides.for_grid(cfg, [case])[case.key].changed["align"]["method"] == "sim3"
    cfg = resolved(mode="rpg", sources={"algorithms": {"vio_stereo": {"metric_scale": False}}})
    with pytest.raises(EpaError, match="eval_cfg.yaml sets 'posyaw'"):
        overrides.for_grid(cfg, [case])
    assert overrides.for_grid(resolved(align={"method": "se3"}), [case]) == {}  # mode epa: not read


@pytest.fixture(scope="module")
def mixed(data, tmp_path_factory):
    """A paper's mixed grid from real files: ORB-SLAM3 monocular and stereo on EuRoC MH_01 (body
    frame reference: Step 2 finds the camera), ORB-SLAM (stereo) on KITTI 00, per-cell settings:
    the monocular one declared, KITTI with the devkit's lengths and scale-aware drift."""
    from test_workflow import smk

    root = tmp_path_factory.mktemp("mixed")
    links = {
        "truth/MH_01.txt": "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt",
        "truth/KITTI_00.txt": "MichaelGrupp_evo/test/data/KITTI_00_gt.txt",
        "truth/KITTI_00_times.txt": "MichaelGrupp_evo/test/data/KITTI_00_gt_times.txt",
        "algs/orb3_mono/MH_01/run1.txt": "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_mono.txt",
        "algs/orb3_stereo/MH_01/run1.txt": "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_stereo.txt",
        "algs/orb3_stereo/KITTI_00/run1.txt": "MichaelGrupp_evo/test/data/KITTI_00_ORB.txt",
    }
    for name, target in links.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).symlink_to(data / target)
    (root / "cfg.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\n"
        "sources: {algorithms: {orb3_mono: {metric_scale: false}}}\n"
        "overrides:\n"
        "  datasets:\n"
        "    'KITTI_*': {metrics: {segments: kitti}, drift: {mode: scale_aware}}\n"
    )
    smk(root)
    return root / "results"


def test_a_real_mixed_grid_evaluates_each_cell_as_it_fits(mixed):
    mono = _doc(mixed, "orb3_mono/MH_01/run1")
    assert mono["alignment"]["method"] == "sim3" and mono["sim3_check"]["warning"] is None
    assert mono["ate"]["trans_m"]["rmse"] == pytest.approx(0.0186, abs=5e-4)
    stereo = _doc(mixed, "orb3_stereo/MH_01/run1")
    assert stereo["alignment"]["method"] == "se3" and stereo["sim3_check"]["warning"] is None
    kitti = _doc(mixed, "orb3_stereo/KITTI_00/run1")
    assert accuracy.recorded_lengths(kitti) == [100.0 * k for k in range(1, 9)]
    assert accuracy.recorded_lengths(stereo) == [8.0, 16.0, 24.0, 32.0, 40.0, 48.0]
    drift = json.loads((mixed / "cases/orb3_stereo/KITTI_00/run1/07_drift/drift.json").read_text())
    assert drift.get("warning") is None  # scale-aware thresholds fit the kilometres
    # one table: the lengths of both datasets, each cell from the datasets that have it
    tex = (mixed / "tables/rpe_distance.tex").read_text()
    assert "\\textbf{48m} & \\textbf{100m}" in tex and "\\textbf{800m}" in tex
    assert (
        "segment lengths per dataset: KITTI\\_00 100, 200, 300, 400, 500, 600, 700, 800 m;"
        " MH\\_01 8, 16, 24, 32, 40, 48 m"
    ) in tex
    rows = {
        r.split(",")[0] + "/" + r.split(",")[1]: r
        for r in (mixed / "summary.csv").read_text().splitlines()
    }
    header = rows["algorithm/dataset"].split(",")
    mono_row = dict(zip(header, rows["orb3_mono/MH_01"].split(",")))
    assert mono_row["alignment"] == "sim3" and float(mono_row["scale"]) == pytest.approx(
        5.17, abs=0.01
    )
    assert 0 < float(mono_row["scale_std"]) < 0.01
    assert mono_row["rpe_100m_trans_mean_m"] == ""  # MH_01 has no 100 m segment length
