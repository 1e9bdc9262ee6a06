"""mode: rpg (grids) and epa eval --mode rpg: rpg_trajectory_evaluation's association, alignment and
statistics per case, and analyze_trajectories.py's summary tables. Checked on real rpg EuRoC estimates
against epa rpg (itself rpg's numbers to rounding, tests/test_rpg.py) and against the numbers real rpg
wrote (tests/rpg_expected.yaml), within tests/test_rpg.py's TOL; the settings and the tables' layout by
hand."""

import json
import logging
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import run_stages
from test_rpg import GT, _src, assert_near, assert_stats, make_case, quantity

from epa.artifacts.case import Case
from epa.cli import main as cli
from epa.core.errors import EpaError
from epa.metrics import rpg as rpg_metric
from epa.outputs import tables
from epa.outputs.tables import rpg as rpg_tables
from epa.outputs.tables.results import CaseResult
from epa.rpg import command
from epa.steps import rpg as rpg_steps
from epa.steps import sync
from epa.workflow import chain, discovery, settings

EXPECTED = yaml.safe_load(Path(__file__).with_name("rpg_expected.yaml").read_text())
LABELS = ("trans", "rot", "scale")

# The statistics are compared with tests/test_rpg.py's assert_stats: its TOL holds for mode rpg too.
# epica normalises quaternions as it reads them, rpg at each use: a last-bit difference that the
# arccos of rel_rot amplifies in small angles (the worst rel_rot, 1.4e-10 deg, is mode rpg's).


def make_grid(data: Path, root: Path, runs: dict, mode_cfg: dict):
    """A grid over rpg's estimates: runs {(alg, seq): {run name: estimate file}}; truth <seq>.txt is the
    EuRoC groundtruth (as in tests/test_rpg.py). Every stage but the report, then the tables."""
    (root / "truth").mkdir(parents=True)
    for (alg, seq), files in runs.items():
        truth = root / "truth" / f"{seq}.txt"
        if not truth.exists():
            truth.symlink_to(data / "rpng_open_vins/ov_data/euroc_mav" / f"{GT[seq]}.txt")
        folder = root / "algs" / alg / seq
        folder.mkdir(parents=True)
        for run, name in files.items():
            (folder / f"{run}.txt").symlink_to(data / _src(alg, seq) / name)
    cfg = settings.resolve(
        {
            "truth_dir": str(root / "truth"),
            "algorithms_dir": str(root / "algs"),
            "results_dir": str(root / "results"),
            "mode": "rpg",
            "report": {"per_case": False},
            **mode_cfg,
        }
    )
    _, cases = discovery.discover(cfg["truth_dir"], cfg["algorithms_dir"], cfg=cfg)
    batch = [{"key": c.key, "truth": str(c.truth), "estimate": str(c.estimate)} for c in cases]
    out = root / "results"
    run_stages(batch, out, cfg, chain.NAMES[:-1])
    keys = sorted(c.key for c in cases)
    assert tables.make(keys, out, cfg) == []
    return out, keys


def case_record(out: Path, key: str) -> dict:
    return json.loads((out / "cases" / key / "06_metrics/metrics.json").read_text())


def test_grid_case_is_epa_rpg_on_the_same_files(data, tmp_path):
    """vio_mono MH_03, posyaw on all frames: the grid's statistics, its rpg files and epa eval --mode
    rpg are epa rpg's. Positions enter as printed and this alignment uses positions only, so the
    absolute translation statistics are bit-identical (both are epica, on one machine); epica
    normalises quaternions as it reads them, rpg at each use, so what uses orientations agrees to
    rounding only (tests/test_rpg.py's TOL, as epa rpg with the oracle)."""
    est = "stamped_traj_estimate.txt"
    out, keys = make_grid(
        data,
        tmp_path / "grid",
        {("vio_mono", "MH_03"): {"run1": est}},
        {"align": {"method": "posyaw"}},
    )
    record = case_record(out, keys[0])
    assert record["eval_source"] == "rpg" and record["sync"]["policy"] == "rpg"
    ours = record["rpg"]
    case = make_case(data, tmp_path, "vio_mono", "MH_03", {est: est}, "posyaw", -1)
    theirs = command.run_case(case)["trials"][0]
    assert record["n_matched"] == theirs["n_matched"]
    assert ours["distances_m"] == theirs["distances"]
    assert ours["absolute"]["trans"] == theirs["abs_stats"]["trans"]  # epica twice: bit for bit
    for lab in LABELS:
        assert_stats(ours["absolute"][lab], theirs["abs_stats"][lab], "abs_" + lab)
    for rel in ours["relative"]:
        e = theirs["rel"][rel["distance_m"]]
        for m, lab in zip(rpg_metric.REL_METRICS, rpg_metric.REL_LABELS):
            assert_stats(rel[lab], e[m + "_stats"], m, str(rel["distance_m"]))
    # rpg's files, under rpg's names, with the same keys and numbers
    mine = sorted((out / "cases" / keys[0] / "06_metrics/rpg").iterdir())
    save = case / "saved_results/traj_est"
    assert [p.name for p in mine] == sorted(
        p.name for p in save.iterdir() if not p.name.startswith("stamped_")
    )
    for p in mine:
        a, b = yaml.safe_load(p.read_text()), yaml.safe_load((save / p.name).read_text())
        assert list(a) == list(b)
        for lab in a:
            assert_stats(a[lab], b[lab], quantity(p.name, lab), p.name)
    # every pair's relative errors, rpg's pairs included
    table = (
        (out / "cases" / keys[0] / "06_metrics/rpg_relative_errors.csv").read_text().splitlines()
    )
    first = theirs["rel"][theirs["distances"][0]]
    assert len(table) - 1 == sum(len(theirs["rel"][d]["pairs"]) for d in theirs["distances"])
    assert [int(x) for x in table[1].split(",")[1:3]] == first["pairs"][0].tolist()
    # epa eval --mode rpg: the same record as the grid's case
    gt = data / "rpng_open_vins/ov_data/euroc_mav/MH_03_medium.txt"
    args = [
        "eval",
        str(gt),
        str(data / _src("vio_mono", "MH_03") / est),
        "--out",
        str(tmp_path / "e"),
    ]
    assert cli.main([*args, "--mode", "rpg", "--align", "posyaw"]) == 0
    assert json.loads((tmp_path / "e/06_metrics/metrics.json").read_text())["rpg"] == ours
    assert sorted(p.name for p in (tmp_path / "e/06_metrics/rpg").iterdir()) == [
        p.name for p in mine
    ]


def test_grid_trials_are_real_rpgs(data, tmp_path):
    """vislam_ba MH_03, runs 0, 1, 2, 4, 5 (the trials real rpg evaluated, se3 on 5 frames): each run's
    ATE and its statistics over runs are rpg's MulTrajError numbers (to tests/test_rpg.py's TOL), the
    relative errors pooled from the grid's per-case files are rpg's mt_rel_err files, and the summary
    table's cells print them as analyze_trajectories.py does."""
    exp = EXPECTED["vislam_ba_MH_03_se3_5_mt"]
    runs = {str(i): f"stamped_ba_estimate{i}.txt" for i in exp["trials"]}
    out, keys = make_grid(
        data,
        tmp_path,
        {("vislam_ba", "MH_03"): runs},
        {"align": {"method": "se3", "first_n": 5}},
    )
    records = [case_record(out, k)["rpg"] for k in keys]
    files = exp["files"]
    for lab in LABELS:
        want = files[f"mt_rmse_{lab}_all_se3_5.txt"]
        assert len(records) == len(want)
        assert_near([r["absolute"][lab]["rmse"] for r in records], want, "abs_" + lab, lab)
    assert_stats(
        records[3]["absolute"]["trans"],
        files["absolute_err_statistics_se3_5_#4.yaml"]["trans"],
        "abs_trans",
        "#4",
    )
    mt_abs = rpg_metric.trial_rmse_statistics([r["absolute"] for r in records])
    for lab in LABELS:
        want = files["mt_abs_err_se3_5.yaml"][lab]
        assert_stats(mt_abs["rmse_" + lab], want, "abs_" + lab, "mt_abs_err")
    grid = tables.results.collect(keys, out)
    mt = rpg_metric.multi_trial_statistics([rpg_tables._trial_errors(out, c) for c in grid])
    for d, stats in mt["rel_stats"].items():
        want = files[f"mt_rel_err_{rpg_metric.dist_str(d)}.yaml"]
        for m, lab in zip(rpg_metric.REL_METRICS, rpg_metric.REL_LABELS):
            assert_stats(stats[m], want[lab], m, f"mt {d}")
    for m, lab in zip(rpg_metric.REL_METRICS, rpg_metric.REL_LABELS):
        assert_stats(mt["overall"][m], files["mt_rel_err_overall.yaml"][lab], m, "overall")
    t = files["mt_abs_err_se3_5.yaml"]["trans"]
    cell = f"{t['mean']:3.3f}, {t['median']:3.3f} ({t['min']:3.3f} - {t['max']:3.3f})"
    assert cell == "3.530, 1.604 (0.373 - 8.804)"
    assert (out / "rpg_translation_rmse.txt").read_text() == (
        f"      &       MH_03\nvislam_ba &      {cell} \n"
    )
    overall = files["mt_rel_err_overall.yaml"]
    assert (out / "rpg_rel_err.txt").read_text() == (
        "      &      Translation (\\%) &  Rotation (deg/meter)\n"
        f"vislam_ba &     {overall['trans_perc']['mean']:.3f} &  "
        f"{overall['rot_deg_per_m']['mean']:.3f} \n"
    )
    tex = (out / "tables/rpg_translation_rmse.tex").read_text()
    assert f"vislam\\_ba & {cell} \\\\" in tex and "\\textbf{MH\\_03}" in tex


def test_grid_first_pose_alignment_is_real_rpgs(data, tmp_path):
    """vislam_rp MH_04 with rpg's se3 on the first pose (align.first_n 1, mode rpg only): the case's
    statistics are those real rpg wrote, and a single run prints rpg's single-trial cell."""
    exp = EXPECTED["vislam_rp_MH_04_se3_1"]
    out, keys = make_grid(
        data,
        tmp_path,
        {("vislam_rp", "MH_04"): {"run1": "stamped_traj_estimate0.txt"}},
        {"align": {"method": "se3", "first_n": 1}},
    )
    ours = case_record(out, keys[0])["rpg"]
    for lab in LABELS:
        assert_stats(
            ours["absolute"][lab],
            exp["files"]["absolute_err_statistics_se3_1.yaml"][lab],
            "abs_" + lab,
        )
    for rel in ours["relative"]:
        want = exp["files"][
            f"relative_error_statistics_{rpg_metric.dist_str(rel['distance_m'])}.yaml"
        ]
        for m, lab in zip(rpg_metric.REL_METRICS, rpg_metric.REL_LABELS):
            assert_stats(rel[lab], want[lab], m, str(rel["distance_m"]))
    rmse = exp["files"]["absolute_err_statistics_se3_1.yaml"]["trans"]["rmse"]
    assert (out / "rpg_translation_rmse.txt").read_text() == (
        f"      &       MH_04\nvislam_rp &      {rmse:3.3f} \n"
    )
    assert sorted(p.name for p in (out / "cases" / keys[0] / "06_metrics/rpg").iterdir()) == sorted(
        n for n in exp["listing"] if n.endswith(".yaml")
    )


def _result(alg, ds, run, rmse=None):
    c = CaseResult(Case(alg, ds, run))
    if rmse is None:
        c.status = "failed: load: no poses"
    else:
        c.metrics = {"rpg": {"absolute": {lab: {"rmse": rmse} for lab in LABELS}}}
    return c


def test_rmse_table_layout_is_rpgs():
    """rpg's write_tex_table: header '      &      ' and columns joined by ' & ', the last after a
    space; rows '<name> &     ' then the cells; sorted names; rpg's cell formats; a cell without a
    successful run is '-' (rpg stops there), a failed run is left out as rpg leaves a failed trial."""
    grid = [
        _result("b", "MH_01", "0", 0.5),
        _result("b", "MH_01", "1", 0.25),
        _result("b", "MH_01", "2", 1.0),
        _result("a", "MH_01", "0", 0.125),
        _result("a", "MH_02", "0", None),
        _result("b", "MH_02", "0", 2.0),
    ]
    values, rows, cols, median = rpg_tables.rmse_table(grid)
    assert (rows, cols, median) == (["a", "b"], ["MH_01", "MH_02"], False)
    assert rpg_tables.write_tex_table(values, rows, cols) == (
        "      &      MH_01 &  MH_02\n"
        "a &     0.125, 0.125 (0.125 - 0.125) &  - \n"
        "b &     0.583, 0.500 (0.250 - 1.000) &  2.000, 2.000 (2.000 - 2.000) \n"
    )
    values, *_ = rpg_tables.rmse_table(grid, median_only=True)
    assert values == [["0.125", "-"], ["0.500", "2.000"]]
    one = [g for g in grid if g.run == "0"]  # one run per cell: rpg without --mul_trials
    assert rpg_tables.rmse_table(one)[0] == [["0.125", "-"], ["0.500", "2.000"]]


def test_mode_rpg_settings():
    cfg = settings.resolve({"truth_dir": ".", "algorithms_dir": ".", "mode": "rpg"})
    assert cfg["sync"]["policy"] == "rpg" and cfg["sync"]["max_diff"] == 0.02
    assert not cfg["sync"]["estimate_offset"] and not cfg["calibrate"]["enabled"]
    one = {"truth_dir": ".", "algorithms_dir": ".", "align": {"first_n": 1}}
    assert settings.resolve({**one, "mode": "rpg"})["align"]["first_n"] == 1
    with pytest.raises(
        EpaError, match=r"^config: align\.first_n: 1 is not allowed: .*mode rpg only"
    ):
        settings.resolve(one)
    with pytest.raises(EpaError, match=r"align\.first_n: 1 is not allowed with align\.method sim3"):
        settings.resolve({**one, "mode": "rpg", "align": {"method": "sim3", "first_n": 1}})
    with pytest.raises(EpaError, match=r"^config: mode: .rgp. is not one of"):
        settings.resolve({"truth_dir": ".", "algorithms_dir": ".", "mode": "rgp"})


def test_mode_rpg_warns_where_it_overrides(caplog):
    with caplog.at_level(logging.WARNING, logger="epa"):
        settings.resolve(
            {"truth_dir": ".", "algorithms_dir": ".", "mode": "rpg", "sync": {"policy": "evo"}}
        )
    assert "mode rpg overrides sync.policy: 'evo' -> 'rpg'" in caplog.text


def test_epa_eval_mode_rpg_refuses_in_one_line(tmp_path, capsys):
    ref = tmp_path / "ref.txt"
    ref.write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")
    code = cli.main(
        [
            "eval",
            str(ref),
            str(ref),
            "--out",
            str(tmp_path / "o"),
            "--mode",
            "rpg",
            "--align",
            "sim3",
            "--first-n",
            "1",
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "align.first_n: 1 is not allowed with align.method sim3" in err[0]


def test_rpg_policy_is_rpgs_association():
    """Closest pairs first, each pose once, crossings allowed, strictly within max_diff: rpg keeps the
    crossing pair ov_eval's association (estimate order, never back) cannot; both leave out the pair
    exactly max_diff apart (ov_eval's best difference starts at max_difference and must shrink;
    dyadic stamps: the differences are exact)."""
    t_ref, t_est = np.array([0.0, 0.1875, 4.0]), np.array([0.15625, 0.21875, 4.25])
    i_ref, i_est = sync.associate_rpg(t_ref, t_est, 0.25)
    assert list(zip(i_ref.tolist(), i_est.tolist())) == [(1, 0), (0, 1)]
    assert [(j, i) for i, j in rpg_steps.associate(t_est, t_ref, 0.0, 0.25)] == [(1, 0), (0, 1)]
    i_ref, i_est = sync.associate_ov_eval(t_ref, t_est, 0.25)
    assert list(zip(i_ref.tolist(), i_est.tolist())) == [(1, 0)]


def test_rpg_scale_through_the_origin_is_left_out(tmp_path, capsys):
    """rpg's scale error divides by the reference's distance from the origin: where the reference
    passes through it (a KITTI reference starts there), rpg would print inf or nan; mode rpg leaves
    the statistic out with a note, and the rest stands."""
    t = np.arange(200) * 0.05
    p = np.column_stack([np.sin(t), t - t[0], 0.1 * np.cos(t) - 0.1])  # p[0] is the origin
    rows = np.column_stack([t, p, np.zeros((200, 3)), np.ones(200)])
    ref = tmp_path / "ref.txt"
    np.savetxt(ref, rows, fmt="%.9f")
    assert (
        cli.main(["eval", str(ref), str(ref), "--out", str(tmp_path / "o"), "--mode", "rpg"]) == 0
    )
    record = json.loads((tmp_path / "o/06_metrics/metrics.json").read_text())
    assert record["rpg"]["absolute"]["scale"] is None
    assert record["rpg"]["absolute"]["trans"]["max"] < 1e-9
    assert any("rpg's scale error divides" in n for n in record["notes"])
    (name,) = [p.name for p in (tmp_path / "o/06_metrics/rpg").glob("absolute_*")]
    doc = yaml.safe_load((tmp_path / "o/06_metrics/rpg" / name).read_text())
    assert sorted(doc) == ["rot", "trans"]
