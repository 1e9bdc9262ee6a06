"""The Python API (epa.evaluate, epa.read_results, epa.read_case; docs/api.md): the same numbers as
the grid, settings as keywords with one-line errors, an import that stays light, and the page's
session run as written."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, run_stages

import epa
from epa.core.errors import EpaError
from epa.outputs import tables
from epa.workflow import chain, discovery, settings

ROOT = Path(__file__).resolve().parents[1]
TRUTH = ROOT / "example/truth/drone_figure8.txt"
RUN1 = ROOT / "example/algorithms/vio_body/drone_figure8/run1.txt"
GOLDEN = ROOT / "tests/golden/example/summary.csv"


def golden_row(key: str) -> dict:
    lines = GOLDEN.read_text().splitlines()
    names = lines[0].split(",")
    for line in lines[1:]:
        row = dict(zip(names, line.split(",")))
        if "/".join((row["algorithm"], row["dataset"], row["run"])) == key:
            return row
    raise KeyError(key)


def test_import_epa_loads_neither_snakemake_nor_matplotlib_nor_pandas():
    code = (
        "import sys, epa; epa.Result; "
        "print(sorted(m for m in ('snakemake', 'matplotlib', 'pandas') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(ROOT / "src")},
    )
    assert out.stdout.strip() == "[]"


def test_evaluate_gives_the_grids_numbers():
    # the example grid's settings that reach these columns are the defaults but for the segments
    result = epa.evaluate(TRUTH, RUN1, metrics={"segments": [8, 16, 24, 32, 40, 48]})
    golden = golden_row("vio_body/drone_figure8/run1")
    assert result.status == "ok" and result.reason is None
    assert result.metrics["n_matched"] == int(golden["n_matched"]) == 2980
    # summary.csv prints 9 significant digits: agreement to its last printed digit
    assert result.ate_rmse_m == pytest.approx(float(golden["ate_trans_rmse_m"]), rel=1e-8)
    assert result.ate_rot_rmse_deg == pytest.approx(float(golden["ate_rot_rmse_deg"]), rel=1e-8)
    assert result.metrics["drift_rate_pct"]["8"] == pytest.approx(
        float(golden["drift_rate_8m_pct"]), rel=1e-8
    )
    errors = result.errors["trans_m"]
    assert isinstance(errors, np.ndarray) and errors.shape == (2980,)
    assert np.sqrt(np.mean(errors**2)) == pytest.approx(result.ate_rmse_m, rel=1e-12)
    assert list(result.records) == list(epa.api.RECORDS)
    frame = result.to_frame()
    assert list(frame.columns) == ["t", "dist_m", "trans_m", "rot_deg", "yaw_deg", "trans_xy_m"]
    assert len(result.to_frame("rpe_time")) == result.metrics["rpe_time_1s"]["trans_m"]["n"]


def test_a_setting_changes_what_it_says():
    plain = epa.evaluate(TRUTH, RUN1, mode="ov_eval")
    assert plain.metrics["eval_source"] == "ov_eval"
    assert plain.records["sync"]["step1"]["used"] is False
    assert plain.ate_rmse_m != epa.evaluate(TRUTH, RUN1).ate_rmse_m


def test_out_dir_keeps_the_case_folder(tmp_path):
    result = epa.evaluate(TRUTH, RUN1, out_dir=tmp_path / "case")
    assert (tmp_path / "case/06_metrics/ape.csv").is_file()
    assert result.folder == tmp_path / "case"


@pytest.mark.parametrize(
    ("given", "message"),
    [
        (
            {"algin": {"method": "sim3"}},
            "epa.evaluate: unknown setting 'algin' (settings: mode, load, sources, crop, sync,",
        ),
        ({"align": {"method": "se4"}}, "epa.evaluate: align.method: 'se4' is not one of"),
        ({"truth_dir": "x"}, "epa.evaluate: unknown setting 'truth_dir'"),
    ],
)
def test_a_wrong_setting_is_one_line(given, message):
    with pytest.raises(EpaError) as err:
        epa.evaluate(TRUTH, RUN1, **given)
    text = err.value.one_line()
    assert text.startswith(message) and "\n" not in text


def test_a_missing_file_names_it(tmp_path):
    with pytest.raises(EpaError) as err:
        epa.evaluate(TRUTH, tmp_path / "nothing.txt")
    assert str(tmp_path / "nothing.txt") in err.value.one_line()


def test_read_results_without_a_grid_is_one_line(tmp_path):
    with pytest.raises(EpaError, match="no summary.csv: run the workflow"):
        epa.read_results(tmp_path)


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """The example grid with config/config.yaml in this process, as tests/test_golden.py runs it."""
    out = tmp_path_factory.mktemp("api") / "results"
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        cfg = settings.resolve(settings.load_yaml(ROOT / "config/config.yaml"))
        _, cases = discovery.discover(cfg["truth_dir"], cfg["algorithms_dir"])
        batch = [{"key": c.key, "truth": str(c.truth), "estimate": str(c.estimate)} for c in cases]
        run_stages(batch, out, cfg, chain.NAMES[:-1])
        assert tables.make(sorted(c.key for c in cases), out, cfg) == []
    finally:
        os.chdir(cwd)
    return out


def test_read_results_lists_every_case_with_summary_csvs_numbers(grid):
    frame = epa.read_results(grid)
    golden = {k: golden_row(k)["status"] for k in frame["case"]}
    assert len(frame) == 18 and dict(zip(frame["case"], frame["status"])) == golden
    row = frame.set_index("case").loc["vio_body/drone_figure8/run1"]
    assert row["ate_trans_rmse_m"] == pytest.approx(0.0576048617, rel=1e-8)
    assert row["folder"] == str(grid / "cases/vio_body/drone_figure8/run1")


def test_read_results_shows_a_case_the_tables_did_not_list(grid, tmp_path):
    import shutil

    results = tmp_path / "results"
    shutil.copytree(grid, results)
    lines = (results / "summary.csv").read_text().splitlines(keepends=True)
    (results / "summary.csv").write_text("".join(lines[:1] + lines[2:]))  # run1 left out
    row = epa.read_results(results).set_index("case").loc["vio_body/drone_figure8/run1"]
    assert row["status"] == "ok" and row["ate_trans_rmse_m"] == pytest.approx(0.0576048617)


def python_blocks(page: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), re.S)


def test_the_api_page_runs_as_written(grid, tmp_path, monkeypatch):
    """docs/api.md's blocks in order, from a checkout whose results/ is the grid's and whose
    ../shared/data is the real data (the last block is skipped where it is absent)."""
    checkout = tmp_path / "epica"
    checkout.mkdir()
    (checkout / "example").symlink_to(ROOT / "example")
    (checkout / "results").symlink_to(grid)
    blocks = python_blocks(ROOT / "docs/api.md")
    assert len(blocks) == 9
    if DATA.is_dir():
        (tmp_path / "shared").mkdir()
        (tmp_path / "shared/data").symlink_to(DATA)
    else:
        blocks = [b for b in blocks if "shared/data" not in b]
    monkeypatch.chdir(checkout)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "docs/api.md", "exec"), namespace)  # noqa: S102 - the page's own code
    assert namespace["best"].loc["drone_figure8", "ate_trans_rmse_m"] > 0
    if DATA.is_dir():
        assert 0.05 < namespace["ov"].ate_rmse_m < 0.2  # OpenVINS on MH_01: about 0.11 m


def test_each_sides_source_settings_reach_that_side():
    with pytest.raises(EpaError) as err:
        epa.evaluate(TRUTH, RUN1, estimate_source={"topic": "/odom"})
    assert err.value.one_line().startswith(str(RUN1) + ": a topic is set for this source")
    with pytest.raises(EpaError) as err:
        epa.evaluate(TRUTH, RUN1, reference_source={"topic": "/odom"})
    assert err.value.one_line().startswith(str(TRUTH) + ": a topic is set for this source")


def _pair(folder: Path) -> tuple[Path, Path]:
    """A 15 m helix and an estimate 1 cm off it: too short for the default segments (a warning)."""
    t = 100 + np.arange(300) * 0.05
    p = np.c_[np.cos(t), np.sin(t), 0.1 * t]
    q = np.tile([0, 0, 0, 1.0], (len(t), 1))
    for name, pos in (("ref.txt", p), ("est.txt", p + 0.01 * np.sin(7 * t)[:, None])):
        np.savetxt(folder / name, np.c_[t, pos, q], fmt="%.6f")
    return folder / "ref.txt", folder / "est.txt"


WARNED = "mode ov_eval overrides sync.policy: 'evo' -> 'ov_eval'"


@pytest.mark.parametrize("asked", [False, True])
def test_evaluate_prints_nothing_unless_asked(tmp_path, asked):
    """In a fresh interpreter (pytest's own log handlers would hide Python's last-resort printing):
    the warnings go nowhere, or where the caller's logging configuration sends them."""
    ref, est = _pair(tmp_path)
    code = (
        "import logging, sys, epa\n"
        + ("logging.basicConfig(format='%(name)s: %(message)s')\n" if asked else "")
        + f"r = epa.evaluate({str(ref)!r}, {str(est)!r}, mode='ov_eval', sync={{'policy': 'evo'}})\n"
        "assert r.status == 'ok', r.reason\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout == ""
    if asked:  # each module's logger, a child of "epa"
        assert f"epa.workflow.settings: {WARNED}\n" in done.stderr
        assert "epa.workflow.stages.metrics: no 16 m segment fits" in done.stderr
    else:
        assert done.stderr == ""


def test_a_case_log_still_takes_every_modules_records(tmp_path):
    """The workflow's per-case log attaches to "epa": the modules' own loggers reach it."""
    from epa.workflow import jobs

    ref, est = _pair(tmp_path)
    with jobs.case_log(tmp_path / "case.log"):
        epa.evaluate(ref, est, mode="ov_eval", sync={"policy": "evo"})
    lines = (tmp_path / "case.log").read_text().splitlines()
    assert f"WARNING {WARNED}" in lines
    assert "INFO consistency: the estimate has no covariance" in lines
    assert sum("segment fits in the 15.023 m matched path" in line for line in lines) == 5


def test_the_building_blocks_give_evos_numbers():
    """read, associate, align, APE and RPE one step at a time, as evo's notebook user writes them;
    the numbers are evo 1.38.1's (sync.associate_trajectories max_diff 0.01, align without scale,
    APE, RPE 1 m consecutive) on the same two files."""
    ref, est = epa.read_trajectory(TRUTH), epa.read_trajectory(RUN1)
    ref, est = epa.associate(ref, est, max_diff=0.01)
    assert len(ref) == len(est) == 2980
    aligned, fit = epa.align(ref, est, method="se3")
    assert isinstance(fit, epa.Similarity) and fit.s == 1.0
    ape = epa.ape(ref, aligned)
    assert epa.stats(ape["trans_m"])["rmse"] == pytest.approx(0.05730467269584577, rel=1e-12)
    assert epa.stats(ape["rot_deg"])["rmse"] == pytest.approx(0.2505654883932078, rel=1e-12)
    rpe = epa.rpe(ref, aligned, delta=1.0, unit="m")
    assert len(rpe["i"]) == 548
    assert epa.stats(rpe["trans_m"])["rmse"] == pytest.approx(0.029776231280606885, rel=1e-12)
    assert epa.stats(rpe["rot_deg"])["rmse"] == pytest.approx(0.2909741085218831, rel=1e-12)


def test_sim3_undoes_a_scale_and_posyaw_keeps_gravity():
    ref, est = epa.associate(epa.read_trajectory(TRUTH), epa.read_trajectory(RUN1))
    se3 = epa.ape(ref, epa.align(ref, est)[0])["trans_m"]
    half = epa.Trajectory(est.t, 0.5 * est.p, est.q)
    aligned, fit = epa.align(ref, half, method="sim3")
    assert fit.s == pytest.approx(2.0, rel=0.01)
    # Sim3 on the halved estimate: at most SE3's error on the original (it has one more freedom)
    assert epa.stats(epa.ape(ref, aligned)["trans_m"])["rmse"] <= epa.stats(se3)["rmse"] + 1e-12
    _, yaw_only = epa.align(ref, est, method="posyaw")
    assert yaw_only.R[2] == pytest.approx([0, 0, 1])  # a rotation about z


def test_the_building_blocks_refuse_in_one_line():
    ref, est = epa.read_trajectory(TRUTH), epa.read_trajectory(RUN1)
    with pytest.raises(EpaError, match="associate them first"):
        epa.ape(ref, est)
    with pytest.raises(EpaError, match="unknown setting 'topik'"):
        epa.read_trajectory(TRUTH, topik="/odom")
    with pytest.raises(EpaError, match="unknown rpe unit 'f'"):
        epa.rpe(*epa.associate(ref, est), unit="f")


def test_the_package_root_lists_the_api_it_reaches_lazily():
    import epa
    from epa import api

    assert epa.__all__ == api.__all__
    assert all(getattr(epa, name) is getattr(api, name) for name in epa.__all__)
