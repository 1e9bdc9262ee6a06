"""The house: one stage in one module, the stage list defined once, a metric added in one module, a
stage run alone (``epa stage``) and the once-per-grid scripts run alone."""

import importlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import run_stages

from epa import simulate
from epa.artifacts import case as case_module
from epa.artifacts import stage as stage_list
from epa.cli import main as cli
from epa.metrics import registry
from epa.metrics.spec import Metric, Table
from epa.outputs import provenance, tables
from epa.workflow import chain, settings

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small_grid(tmp_path_factory):
    """Two cases of the example's handheld_office, every stage but the report, in this process."""
    cwd = tmp_path_factory.mktemp("house")
    simulate.simulate(cwd / "sim")
    (cwd / "truth").mkdir()
    shutil.copy(cwd / "sim/truth/handheld_office.txt", cwd / "truth")
    for alg in ("vio_body", "vio_camera"):
        (cwd / f"algs/{alg}/handheld_office").mkdir(parents=True)
        for f in (cwd / f"sim/algorithms/{alg}/handheld_office").glob("run1*"):
            shutil.copy(f, cwd / f"algs/{alg}/handheld_office")
    (cwd / "cfg.yaml").write_text(
        f"truth_dir: {cwd / 'truth'}\nalgorithms_dir: {cwd / 'algs'}\nresults_dir: {cwd / 'results'}\n"
        "report: {per_case: false}\n"
    )
    cfg = settings.resolve(settings.load_yaml(cwd / "cfg.yaml"))
    keys = ["vio_body/handheld_office/run1", "vio_camera/handheld_office/run1"]
    batch = []
    for key in keys:
        alg, ds, run = key.split("/")
        est = next((cwd / f"algs/{alg}/{ds}").glob(f"{run}.*"))
        batch.append({"key": key, "truth": str(cwd / f"truth/{ds}.txt"), "estimate": str(est)})
    run_stages(batch, cwd / "results", cfg, chain.NAMES[:-1])
    assert tables.make(keys, cwd / "results", cfg) == []
    return cwd, cfg, keys


def test_the_stage_list_is_the_case_folder_layout_and_each_module_says_what_it_writes():
    assert chain.NAMES == stage_list.ORDER
    for stage in chain.STAGES:
        module = importlib.import_module(f"epa.workflow.stages.{stage.name}")
        assert module.STAGE is stage and module.NAME == stage.name
        assert stage.records and all(n.endswith(".json") for n in stage.records)
        assert set(stage.settings) <= set(settings.defaults()) | {"mode", *settings.GRID_FOLDERS}
        assert callable(stage.run)
    # the metrics stage writes the arrays of the registered metrics it computes
    for metric in registry.computed_in("metrics"):
        assert set(metric.arrays) <= set(chain.BY_NAME["metrics"].arrays)


def test_every_registered_metric_declares_the_interface():
    assert all(isinstance(m, Metric) for m in registry.REGISTRY)
    assert registry.validate(registry.REGISTRY) == registry.REGISTRY
    for metric in registry.REGISTRY:
        assert metric.stage in chain.NAMES
        # each setting it declares is a key of the resolved config, in its stage's subset
        for setting in metric.settings:
            section, *rest = setting.split(".")
            assert section in chain.sections_for(metric.stage)
            node = settings.defaults()
            for part in [section, *rest]:
                assert part in node, f"{metric.key}: {setting} is no setting"
                node = node[part]


def test_a_new_metric_is_one_module(small_grid, monkeypatch, tmp_path):
    """A metric module registered in the registry reaches metrics.json, summary.csv, its .tex table
    and error_comparison.txt, with no other change."""
    cwd, cfg, keys = small_grid
    path_ratio = Metric(
        key="path_ratio",
        stage="metrics",
        after="ate",
        summary_columns=("path_ratio",),
        enabled=lambda cfg: True,
        compute=lambda ref, est, cfg: ({"ratio": est.length() / ref.length()}, {}, []),
        summary=lambda record: {"path_ratio": record.get("ratio")},
        tables=(
            Table("path_ratio", "PATH LENGTH RATIO", pair=False, per_run=lambda r: (r["ratio"],)),
        ),
    )
    monkeypatch.setattr(registry, "REGISTRY", registry.REGISTRY + (path_ratio,))
    out = tmp_path / "results"
    shutil.copytree(cwd / "results", out)
    for key in keys:  # metrics onward, from the copied artifacts
        data = chain.CaseData(case_module.CaseFolder(out / "cases" / key))
        for stage in ("metrics", "drift", "consistency", "efficiency"):
            chain.run_stage(stage, data, cfg)
        record = json.loads((out / "cases" / key / "06_metrics/metrics.json").read_text())
        assert list(record).index("path_ratio") == list(record).index("ate") + 1
        assert 0.5 < record["path_ratio"]["ratio"] < 2.0
    tables.make(keys, out, cfg)
    header = (out / "summary.csv").read_text().splitlines()[0].split(",")
    assert header.index("path_ratio") < header.index("notes")
    assert "PATH LENGTH RATIO" in (out / "tables/path_ratio.tex").read_text()
    assert "PATH LENGTH RATIO" in (out / "error_comparison.txt").read_text()


def test_epa_stage_runs_one_stage_from_the_previous_artifacts(small_grid, capsys):
    cwd, _, keys = small_grid
    case_dir = cwd / "results/cases" / keys[1]
    want = {
        n: (case_dir / n).read_bytes()
        for n in ("05_align/transform.json", "06_metrics/metrics.json")
    }
    for name in want:
        (case_dir / name).unlink()
    for stage in ("align", "metrics"):
        assert cli.main(["stage", stage, str(case_dir), "--config", str(cwd / "cfg.yaml")]) == 0
    assert "metrics: " in capsys.readouterr().out
    assert {n: (case_dir / n).read_bytes() for n in want} == want
    # the load stage finds the case's files through the grid's config; --configfile, the earlier
    # spelling of --config, still works and says so
    assert cli.main(["stage", "load", str(case_dir), "--configfile", str(cwd / "cfg.yaml")]) == 0
    assert capsys.readouterr().err == "epa: WARNING: --configfile is deprecated: use --config\n"


@pytest.mark.parametrize(
    "args, says",
    [
        (["stage", "nope", "{case}"], "no stage 'nope'"),
        (["stage", "align", "{results}/cases/x/y/z"], "no case 'x/y/z'"),
    ],
)
def test_epa_stage_refuses_in_one_line(small_grid, capsys, args, says):
    cwd, _, keys = small_grid
    fill = {"case": str(cwd / "results/cases" / keys[0]), "results": str(cwd / "results")}
    argv = [a.format(**fill) for a in args] + ["--config", str(cwd / "cfg.yaml")]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("epa: error: ") and says in err and err.count("\n") == 1


def test_the_tables_and_figures_scripts_run_on_their_own(small_grid, tmp_path):
    cwd, _, _ = small_grid
    want = {p.name: p.read_bytes() for p in (cwd / "results").glob("*.*") if p.is_file()}
    for name in want:
        (cwd / "results" / name).unlink()
    cmd = [sys.executable, str(ROOT / "scripts/tables.py"), "--configfile", str(cwd / "cfg.yaml")]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    got = {p.name: p.read_bytes() for p in (cwd / "results").glob("*.*") if p.is_file()}
    for d in (got, want):  # written by the script (the fixture ran tables.make alone)
        d.pop(provenance.PROVENANCE, None), d.pop(provenance.CONFIG, None)
    assert got == want
    doc = provenance.read(cwd / "results")
    assert doc["config"] == settings.resolve(settings.load_yaml(cwd / "cfg.yaml"))
    assert len(doc["inputs"]) >= 3 and all(r.get("sha256") for r in doc["inputs"])
    cmd = [sys.executable, str(ROOT / "scripts/figures.py"), "--configfile", str(cwd / "cfg.yaml")]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert (cwd / "results/figures/ate.pdf").stat().st_size > 1000
    bad = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts/tables.py"),
            "--configfile",
            str(tmp_path / "no.yaml"),
        ],
        capture_output=True,
        text=True,
    )
    assert (
        bad.returncode == 2
        and bad.stderr.startswith("epa: error: ")
        and "Traceback" not in bad.stderr
    )


def test_no_function_in_src_is_over_80_lines():
    import ast

    long = [
        f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1})"
        for path in sorted((ROOT / "src").rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > 80
    ]
    assert not long, f"functions over 80 lines: {long}"


def test_the_parser_is_chosen_by_the_process_not_by_what_is_imported():
    import pandas  # noqa: F401 - imported, but not chosen

    from epa.core import runtime
    from epa.workflow.stages import load

    runtime.reset()
    assert load.c_parser_min_bytes() > 0 and not runtime.pandas_parser()
    runtime.use_pandas_parser()
    assert load.c_parser_min_bytes() == 0
    runtime.reset()
    assert not runtime.pandas_parser()
