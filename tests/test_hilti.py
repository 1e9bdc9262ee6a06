"""The Hilti SLAM Challenge score (epa.metrics.hilti) against the 2022 challenge's own evaluation on
real files (tests/oracles/hilti: its outputs, the command, the commit; control points drawn from
EuRoC MH_01's reference), hand-derived cases, and the protocol through `epa eval` and a grid."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, run_stages, smooth_path

from epa.cli import main as cli
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import hilti
from epa.outputs import tables
from epa.workflow import chain, settings

ORACLE = Path(__file__).resolve().parent / "oracles" / "hilti"
sys.path.insert(0, str(ORACLE))
import hilti_cases as cases  # noqa: E402  (the oracle's inputs, shared with its driver)

needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"no shared data at {DATA}")
# APE statistics: evo's Umeyama and norms against epica's, other operation orders; measured at most
# 1e-15 m, so 1e-12 m. Scores are exact: integer points over the script's own divisor.
TOL_M = 1e-12
STATS = ("rmse", "mean", "median", "std", "min", "max")


def cfg(**over) -> dict:
    return {
        "metrics": {"hilti": settings.defaults()["metrics"]["hilti"] | {"enabled": True} | over}
    }


def trajectory(a: np.ndarray) -> Trajectory:
    q = a[:, 4:] / np.linalg.norm(a[:, 4:], axis=1, keepdims=True)
    return Trajectory(a[:, 0].copy(), a[:, 1:4].copy(), q)


def oracle_2022(name: str) -> dict:
    """results.csv's row (index, dataset, rmse ... sse, points_estimate, points_reference,
    completeness, score) and the bin counts the script returns."""
    lines = (ORACLE / f"{name}_2022.txt").read_text().splitlines()
    row = lines[1].removeprefix("results.csv ").split(",")
    cols = ("rmse", "mean", "median", "std", "min", "max", "sse")
    out = {c: float(v) for c, v in zip(cols, row[2:9])} | {"score_printed": row[-1]}
    out["n_control_points"] = int(lines[0].split()[1])
    out["per_bin"] = [int(float(line.rsplit(" ", 1)[1])) for line in lines[2:7]]
    return out


def oracle_2023(name: str) -> dict:
    out = {}
    for line in (ORACLE / f"{name}_2023.txt").read_text().splitlines():
        key, value = line.split(" ", 1)
        out[key] = json.loads(value) if key in ("per_bin", "points") else float(value)
    return out


@needs_data
@pytest.mark.parametrize("drawn", [True, False], ids=["drawn", "file"])
@pytest.mark.parametrize("name", list(cases.CASES))
def test_2022_equals_the_challenge_script_on_real_files(name, drawn):
    dense = cases.reference(DATA, name)
    # the control points drawn by the metric from the dense reference, or given as the reference
    ref = trajectory(dense if drawn else cases.control_points(dense))
    setting = cfg(year=2022, control_every_s=cases.EVERY_S if drawn else None)
    est = trajectory(cases.estimate(DATA, name))
    got, _, notes = hilti.compute(None, None, setting, reference=ref, estimate=est)
    want = oracle_2022(name)
    assert notes == [] and got["n_control_points"] == want["n_control_points"]
    assert got["lever_arm_m"] == list(hilti.POLE_TIP_2022_M)
    for s in STATS:
        assert got[f"{s}_m"] == pytest.approx(want[s], abs=TOL_M), s
    assert got["per_bin"] == want["per_bin"]
    assert repr(got["score"]) == want["score_printed"]  # results.csv's digits


@needs_data
@pytest.mark.parametrize("name", list(cases.CASES))
def test_2023_equals_the_challenge_evaluation_with_the_2023_table(name):
    ref = trajectory(cases.reference(DATA, name))
    est = trajectory(cases.estimate(DATA, name))
    setting = cfg(year=2023, control_every_s=cases.EVERY_S)
    got, _, _ = hilti.compute(None, None, setting, reference=ref, estimate=est)
    want = oracle_2023(name)
    assert got["lever_arm_m"] == [0.0, 0.0, 0.0] and got["n_matched"] == want["n_matched"]
    for s in STATS:
        assert got[f"{s}_m"] == pytest.approx(want[s], abs=TOL_M), s
    assert got["per_bin"] == want["per_bin"] and got["points"] == want["points"]
    assert got["score"] == want["score"]


def test_a_rigidly_moved_estimate_scores_100_and_injected_errors_fall_in_their_bins():
    ref = smooth_path(600)  # 30 s
    turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    moved = Trajectory.from_rp(ref.t, turn @ ref.r, ref.p @ turn.T + [5.0, -2, 1])
    for year in (2022, 2023):
        got, _, _ = hilti.compute(
            None,
            None,
            cfg(year=year, control_every_s=1.0, lever_arm_m=[0, 0, 0]),
            reference=ref,
            estimate=moved,
        )
        assert got["n_control_points"] == 30 and got["score"] == 100.0
    # the tables by hand: strictly below a threshold earns its points
    points, counts = hilti.points(np.array([0.0, 0.0099, 0.01, 0.03, 0.0599, 0.1, 0.5]), 2022)
    assert points.tolist() == [10, 10, 6, 3, 3, 0, 0] and counts == [2, 1, 2, 0, 2]
    points, counts = hilti.points(np.array([0.004, 0.005, 0.02, 0.05, 0.08, 0.2, 0.4]), 2023)
    assert points.tolist() == [20, 10, 6, 5, 3, 1, 0] and counts == [1, 1, 1, 1, 1, 1, 1]
    assert hilti.score(6 * 10 + 4 * 1, 10, 2022) == 64.0
    assert hilti.score(5 * 20, 10, 2023) == 50.0


def test_the_2022_pole_tip_moves_every_estimate_position_by_its_rotated_lever():
    ref = smooth_path(300)
    tip = np.asarray(hilti.POLE_TIP_2022_M)
    control = ref.select(np.arange(0, 300, 20))
    # a reference of the pole tip's path: an estimate of the IMU scores 100 only with the lever
    tips = Trajectory(control.t, control.p + np.einsum("nab,b->na", control.r, tip), control.q)
    with_tip, _, _ = hilti.compute(None, None, cfg(year=2022), reference=tips, estimate=ref)
    without, _, _ = hilti.compute(
        None, None, cfg(year=2022, lever_arm_m=[0, 0, 0]), reference=tips, estimate=ref
    )
    assert with_tip["rmse_m"] < 1e-12 and with_tip["score"] == 100.0
    assert without["rmse_m"] > 0.01


def test_a_dense_reference_has_no_score_and_says_why():
    ref = smooth_path(600)
    got, _, notes = hilti.compute(None, None, cfg(), reference=ref, estimate=ref)
    assert got["score"] is None and "dense trajectory" in got["reason"] and len(notes) == 1


def test_fewer_than_three_matched_control_points_is_one_line():
    ref = smooth_path(600)
    with pytest.raises(
        EpaError, match="1 of the 3 control points have an estimate pose within 2 s"
    ):
        hilti.compute(
            None, None, cfg(control_every_s=10.0), reference=ref, estimate=ref.select(slice(0, 100))
        )


MH01 = cases.GT_BODY
BA0 = cases.CASES["mh01_vislam_ba0"][1]


@needs_data
def test_epa_eval_and_a_grid_give_the_challenge_score(tmp_path):
    config = tmp_path / "cfg.yaml"
    config.write_text("metrics:\n  hilti: {enabled: true, year: 2022, control_every_s: 10}\n")
    out = tmp_path / "out"
    args = ["eval", str(DATA / MH01), str(DATA / BA0), "--out", str(out), "--config", str(config)]
    assert cli.main(args) == 0
    got = json.loads((out / "06_metrics/metrics.json").read_text())["hilti"]
    want = oracle_2022("mh01_vislam_ba0")
    assert repr(got["score"]) == want["score_printed"] and got["per_bin"] == want["per_bin"]
    grid_cfg = settings.resolve(
        {
            "truth_dir": str(DATA),
            "algorithms_dir": str(DATA),
            "metrics": {"hilti": {"enabled": True, "control_every_s": 10}},
        }
    )
    grid = [{"key": "ba0/MH_01/run1", "truth": str(DATA / MH01), "estimate": str(DATA / BA0)}]
    results = tmp_path / "results"
    run_stages(grid, results, grid_cfg, chain.NAMES[:-1])
    assert tables.make([c["key"] for c in grid], results, grid_cfg) == []
    header, row = (results / "summary.csv").read_text().splitlines()[:2]
    values = dict(zip(header.split(","), row.split(",")))
    assert float(values["hilti_score"]) == pytest.approx(float(want["score_printed"]), rel=1e-8)
    assert f"{float(want['score_printed']):.3f}" in (results / "tables/hilti.tex").read_text()
    assert "HILTI SLAM CHALLENGE SCORE" in (results / "error_comparison.txt").read_text()
    off = settings.resolve({"truth_dir": "t", "algorithms_dir": "a"})
    assert "hilti" in tables.table_names(grid_cfg) and "hilti" not in tables.table_names(off)


@needs_data
def test_epa_eval_on_a_control_point_file(tmp_path):
    """The challenge's situation: the reference is a file of a few control points. epica's own
    Steps 1-3 run too, so they are told to match them as the challenge does (docs/protocols.md)."""
    control = tmp_path / "control.txt"
    np.savetxt(control, cases.control_points(cases.reference(DATA, "mh01_vio_mono")), fmt="%.17g")
    config = tmp_path / "cfg.yaml"
    config.write_text("metrics:\n  hilti: {enabled: true}\nsync:\n  min_pairs: 3\n")
    est = DATA / cases.CASES["mh01_vio_mono"][1]
    out = tmp_path / "out"
    recipe = ["--policy", "evo", "--max-diff", "2", "--no-offset-estimate", "--no-calibrate"]
    args = ["eval", str(control), str(est), "--out", str(out), "--config", str(config), *recipe]
    assert cli.main(args) == 0
    got = json.loads((out / "06_metrics/metrics.json").read_text())["hilti"]
    want = oracle_2022("mh01_vio_mono")
    assert repr(got["score"]) == want["score_printed"] and got["per_bin"] == want["per_bin"]
