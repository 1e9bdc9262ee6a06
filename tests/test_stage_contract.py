"""The stage contract in code: each stage module declares itself once (``STAGE``,
:class:`epa.artifacts.stage.Stage`), and the case folder's layout, ``CaseData``'s fields, the values
``epa eval`` lets go, its returned records and the workflow's stage rules are derived from the
declarations. A stage added in a test (tests/toy_stage.py: its module, appended to the stage list)
gets all of them."""

import dataclasses
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import toy_stage
from conftest import run_stages
from test_chain import let_go_after
from test_steps_sim import case as sim_case

from epa.artifacts import files
from epa.artifacts import stage as stage_list
from epa.artifacts.case import Both, CaseFolder, Record, data_class
from epa.artifacts.stage import Stage, Value, folder
from epa.cli import main as cli
from epa.core.trajectory import Trajectory
from epa.workflow import chain, settings
from epa.workflow import jobs as grid

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("load", "crop", "sync", "calibrate", "align", "metrics")
STAGES += ("drift", "consistency", "efficiency", "report")


@pytest.fixture
def toy(monkeypatch):
    toy_stage.register(monkeypatch.setattr, monkeypatch.setitem)
    return toy_stage.STAGE


@pytest.fixture(scope="module")
def camera_case(tmp_path_factory):
    """A camera-frame estimate 0.25 s late: Step 2 applies an extrinsic, so the calibrated estimate
    is a file of its own (04_calibrate/est.tum), written only with the arrays."""
    d = tmp_path_factory.mktemp("camera")
    ref, est, _, _ = sim_case("drone_figure8", offset=0.25, noise=0.002)
    files.write_tum(d / "ref.txt", ref.shifted(1e9))
    files.write_tum(d / "est.txt", est.shifted(1e9))
    return d / "ref.txt", d / "est.txt"


def resolved():
    return settings.resolve({"truth_dir": ".", "algorithms_dir": "."})


def test_the_declarations_give_the_layout_the_fields_and_when_a_value_is_let_go():
    assert chain.NAMES == STAGES
    assert [folder(n) for n in STAGES[:2]] + [folder("report")] == [
        "01_load",
        "02_crop",
        "10_report",
    ]
    hints = chain.CaseData.__annotations__
    assert hints["cropped"] == Both == tuple[Trajectory, Trajectory]
    assert hints["aligned"] is Trajectory
    assert hints["metrics_record"] == Record == dict[str, Any]
    assert hints["timing"] == dict[str, np.ndarray] | None
    assert set(hints) == {v.name for st in chain.STAGES for v in st.values}
    # what each stage reads under the settings, from which run_case lets values go
    # (tests/test_chain.py follows a run)
    cfg = resolved()
    assert chain.reads_under("calibrate", cfg) == frozenset(chain.BY_NAME["calibrate"].reads)
    assert "cropped" not in chain.reads_under("metrics", cfg)
    assert [st.result for st in chain.STAGES if st.result] == [
        "metrics_record",
        "drift_record",
        "consistency_record",
        "efficiency_record",
    ]


def test_a_stage_added_to_the_list_gets_its_folder_field_settings_and_last_reads(toy):
    assert chain.NAMES == (*STAGES, "toy") and chain.BY_NAME["toy"] is toy
    assert folder("toy") == "11_toy" and folder("report") == "10_report"
    assert chain.previous("toy") == "report"
    assert chain.CaseData.__annotations__["toy_record"] == Record
    assert chain.reads_under("toy", resolved()) == {"calibrated"}  # kept in memory for it
    cfg = resolved()
    assert chain.settings_for("toy", cfg) == {"align": cfg["align"]}


def test_a_stage_added_runs_in_epa_eval_and_reads_the_calibrated_estimate(
    toy, camera_case, tmp_path, monkeypatch
):
    ref, est = camera_case
    # kept in memory for it (no metric reads it under the defaults): let go after it
    assert let_go_after(monkeypatch, ref, est, tmp_path / "k", resolved())["calibrated"] == "toy"
    # the calibrated estimate as the workflow writes it
    assert cli.main(["eval", str(ref), str(est), "--out", str(tmp_path / "a"), "--artifacts"]) == 0
    calibrated = files.read_tum_file(tmp_path / "a/04_calibrate/est.tum")
    assert cli.main(["eval", str(ref), str(est), "--out", str(tmp_path / "e")]) == 0
    assert not (tmp_path / "e/04_calibrate/est.tum").exists()
    record = json.loads((tmp_path / "e/11_toy/toy.json").read_text())
    assert record["n"] == len(calibrated) and record["align"] == "se3"
    assert record["est_length_m"] == pytest.approx(calibrated.length(), rel=1e-12)
    records = chain.run_case(ref, est, tmp_path / "r", resolved())
    assert list(records) == ["metrics", "drift", "consistency", "efficiency", "toy"]
    assert records["toy"] == record


def test_a_stage_added_reaches_evaluate_read_case_and_metrics_json(toy, camera_case, tmp_path):
    """Its record, with no edit elsewhere: in epa.evaluate's and read_case's records (after the
    others) and in `epa eval`'s metrics.json (the stages with a result; the per-case report's
    copy holds those before the report stage)."""
    import epa
    from epa import api

    ref, est = camera_case
    assert list(api.RECORDS)[-2:] == ["efficiency", "toy"]
    assert chain.DOCUMENT[-1] == ("toy", "toy.json")
    result = epa.evaluate(ref, est, out_dir=tmp_path / "cases/alg/ds/run")
    assert result.records["toy"]["n"] == result.metrics["n_matched"] > 0
    back = epa.read_case(tmp_path, "alg/ds/run")
    assert back.records["toy"] == result.records["toy"]
    out = tmp_path / "e"
    assert cli.main(["eval", str(ref), str(est), "--out", str(out)]) == 0
    doc = json.loads((out / "metrics.json").read_text())
    assert list(doc) == ["metrics", "drift", "consistency", "efficiency", "toy"]
    assert doc["toy"] == result.records["toy"]


def test_a_value_let_go_is_never_read_back_from_a_file_epa_eval_did_not_write(
    toy, camera_case, tmp_path, monkeypatch
):
    """run_case lets a value go once no stage from there on reads it under the case's settings
    (``reads_for``): a stage whose reads_for leaves out what it reads finds it gone, rather than
    reading the calibrated estimate back from a file `epa eval` never wrote."""
    monkeypatch.setattr(toy_stage, "STAGE", dataclasses.replace(toy, reads_for=lambda cfg: ()))
    with pytest.raises(AttributeError, match="'calibrated' is not among the values"):
        chain.run_case(*camera_case, tmp_path / "e", resolved())
    assert not (tmp_path / "e/04_calibrate/est.tum").exists()
    monkeypatch.setattr(
        toy_stage, "STAGE", dataclasses.replace(toy, reads_for=lambda cfg: ("calibrated", "x"))
    )
    with pytest.raises(ValueError, match=r"stage toy: reads_for gives \['x'\], not read"):
        chain.run_case(*camera_case, tmp_path / "e", resolved())


def test_a_stage_reads_only_the_values_it_declares(toy, camera_case, tmp_path, monkeypatch):
    monkeypatch.setattr(toy_stage, "STAGE", dataclasses.replace(toy, reads=()))
    with pytest.raises(AttributeError, match="'calibrated' is not among the values"):
        chain.run_case(*camera_case, tmp_path / "e", resolved())
    data = chain.CaseData(CaseFolder(tmp_path / "e"))
    with pytest.raises(AttributeError, match="no stage hands on a value 'calibratd'"):
        data.calibratd = None
    with pytest.raises(AttributeError, match="no stage hands on a value 'calibratd'"):
        data.calibratd  # noqa: B018


def test_a_stage_added_runs_in_a_grid_job(toy, camera_case, tmp_path):
    ref, est = camera_case
    cases = [{"key": "cam/seq/run1", "truth": str(ref), "estimate": str(est)}]
    manifests = run_stages(cases, tmp_path, resolved())
    assert grid.read_manifest(manifests["toy"]) == {"cam/seq/run1": {"status": "ok"}}
    record = json.loads((tmp_path / "cases/cam/seq/run1/11_toy/toy.json").read_text())
    calibrated = files.read_tum_file(tmp_path / "cases/cam/seq/run1/04_calibrate/est.tum")
    assert record["est_length_m"] == pytest.approx(calibrated.length(), rel=1e-12)


def test_a_stage_added_is_a_workflow_rule(tmp_path):
    """The stage rules are made from the stage list: a Snakefile that appends the toy stage before
    including the workflow plans one toy job per batch, after the report's, and `all` asks for it."""
    (tmp_path / "cfg.yaml").write_text(
        f"truth_dir: {ROOT / 'example/truth'}\nalgorithms_dir: {ROOT / 'example/algorithms'}\n"
        f"results_dir: {tmp_path / 'results'}\n"
    )
    wrapper = tmp_path / "Snakefile.toy"
    wrapper.write_text(
        f"import sys\nsys.path.insert(0, {str(ROOT / 'tests')!r})\nimport toy_stage\n"
        f"toy_stage.register()\ninclude: {str(ROOT / 'Snakefile')!r}\n"
    )
    cmd = [sys.executable, "-m", "snakemake", "all", "-s", str(wrapper), "--cores", "1"]
    cmd += ["--directory", str(tmp_path), "--configfile", str(tmp_path / "cfg.yaml")]
    run = subprocess.run(
        [*cmd, "-n", "--quiet", "rules"], capture_output=True, text=True, cwd=tmp_path
    )
    assert run.returncode == 0, run.stdout + run.stderr
    jobs = dict(re.findall(r"^(\w+)\s+(\d+)$", run.stdout + run.stderr, re.M))
    assert jobs["toy"] == jobs["report"] == jobs["load"] and int(jobs["toy"]) >= 1
    assert jobs["all"] == "1"


def test_declarations_are_checked():
    def run(data, cfg, write_arrays):
        return None

    with pytest.raises(ValueError, match="records must be one or more .json files"):
        Stage(name="x", run=run, records=("x.csv",))
    with pytest.raises(ValueError, match="result 'y' is not a value it hands on"):
        Stage(name="x", run=run, records=("x.json",), result="y")
    with pytest.raises(ValueError, match="not a public attribute name"):
        Value("_x", dict, lambda s: {})
    reader = Stage(name="x", run=run, records=("x.json",), reads=("nothing",))
    with pytest.raises(ValueError, match="stage x: no stage hands on a value 'nothing' before it"):
        chain.derive((*chain.STAGES, reader))
    twice = Stage(name="x", run=run, records=("x.json",), values=(Value("aligned", dict, dict),))
    with pytest.raises(ValueError, match="value 'aligned': handed on twice"):
        data_class(v for st in (*chain.STAGES, twice) for v in st.values)
    with pytest.raises(KeyError, match="no stage 'x'"):
        folder("x")
    assert stage_list.ORDER == STAGES
