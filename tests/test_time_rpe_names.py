"""The time RPE's names follow metrics.time_delta: its record in metrics.json and drift.json, its
tables (the .tex files and error_comparison.txt's titles), its summary.csv columns and the case
report's row. The default's names (1 s) are the golden copies' (tests/test_golden.py)."""

import csv
import dataclasses
import json

import pytest

from epa import simulate
from epa.cli import main as cli
from epa.metrics import accuracy
from epa.outputs import tables
from epa.workflow import settings

CASE = "vio_camera/drone_figure8/run1"


def test_the_name_is_the_interval_as_segment_lengths_are_spelled():
    assert accuracy.time_rpe_key(1.0) == "rpe_time_1s"
    assert accuracy.time_rpe_key(2.0) == "rpe_time_2s"
    assert accuracy.time_rpe_key(0.5) == "rpe_time_0.5s"
    assert tables.summary.time_rpe_columns(0.5) == (
        "time_rpe_0.5s_trans_mean_m",
        "time_rpe_0.5s_rot_mean_deg",
    )
    one, two = accuracy.base_tables(1.0), accuracy.base_tables(2.0)
    assert "rpe_time_1s" in one and "valid_rpe_time_1s" in one and "rpe_time" not in one
    assert "rpe_time_2s" in two and "valid_rpe_time_2s" in two and "rpe_time_1s" not in two
    assert accuracy.time_rpe_in({"ate": {}, "rpe_time_0.5s": {"n": 1}}) == ("0.5s", {"n": 1})
    assert accuracy.time_rpe_in({"ate": {}}) is None


@pytest.fixture(scope="module")
def two_seconds(tmp_path_factory):
    """One example case evaluated with metrics.time_delta 2.0, and the grid tables of it."""
    root = tmp_path_factory.mktemp("time_delta")
    simulate.simulate(root / "sim")
    (root / "cfg.yaml").write_text("metrics:\n  time_delta: 2.0\n")
    results = root / "results"
    ref = root / "sim/truth/drone_figure8.txt"
    est = root / "sim/algorithms" / CASE.replace("/run1", "/run1.csv")
    out = results / "cases" / CASE
    args = ["eval", str(ref), str(est), "--out", str(out), "--artifacts", "--report"]
    assert cli.main([*args, "--config", str(root / "cfg.yaml")]) == 0
    folders = {"truth_dir": str(root / "sim/truth"), "algorithms_dir": str(root / "sim/algorithms")}
    cfg = settings.resolve({**folders, "metrics": {"time_delta": 2.0}})
    assert tables.make([CASE], results, cfg) == []
    return out, results, cfg


def test_records_are_keyed_by_the_interval(two_seconds):
    out, _, _ = two_seconds
    m = json.loads((out / "06_metrics/metrics.json").read_text())
    d = json.loads((out / "07_drift/drift.json").read_text())
    assert "rpe_time_1s" not in m and m["rpe_time_2s"]["delta_s"] == 2.0
    assert m["rpe_time_2s"]["trans_m"]["n"] > 0
    # in place of the 1 s RPE: after the drift rate, before evo's RPE
    keys = list(m)
    assert keys.index("drift_rate_pct") + 1 == keys.index("rpe_time_2s") == keys.index("rpe") - 1
    assert "rpe_time_1s" not in d["drift_valid"] and d["drift_valid"]["rpe_time_2s"]["trans_m"]


def test_tables_and_summary_columns_follow(two_seconds):
    out, results, cfg = two_seconds
    m = json.loads((out / "06_metrics/metrics.json").read_text())
    names = tables.table_names(cfg)
    assert "rpe_time_2s" in names and "valid_rpe_time_2s" in names and "rpe_time_1s" not in names
    assert sorted(p.stem for p in (results / "tables").glob("*.tex")) == sorted(names)
    text = (results / "error_comparison.txt").read_text()
    assert "FULL TRAJECTORY 2S TIME RPE LATEX TABLE" in text and "1S TIME RPE" not in text
    assert "DRIFT-VALID ONLY 2S TIME RPE LATEX TABLE" in text
    # the per-algorithm block names the interval too
    assert "        RPE time 2s - mean_ori = " in text and "RPE time 1s" not in text
    with open(results / "summary.csv", newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert "time_rpe_1s_trans_mean_m" not in row
    # the column holds the record's number, printed to 9 significant digits
    assert row["time_rpe_2s_trans_mean_m"] == f"{m['rpe_time_2s']['trans_m']['mean']:.9g}"
    assert row["time_rpe_2s_rot_mean_deg"] == f"{m['rpe_time_2s']['rot_deg']['mean']:.9g}"


def test_the_case_report_row_names_the_interval(two_seconds):
    out, _, _ = two_seconds
    report = (out / "10_report/report_en.md").read_text()
    assert "RPE 2 s (m / deg)" in report and "RPE 1 s" not in report


def test_a_table_after_the_time_rpe_follows_it_under_any_interval(two_seconds):
    """A metric's Table.after names the base tables as BASE_TABLES spells them (the time RPE's:
    rpe_time, whatever its interval)."""
    from epa.metrics import ate_2d
    from epa.outputs.tables.latex import build_tables
    from epa.outputs.tables.results import collect

    _, results, cfg = two_seconds
    grid = collect([CASE], results)
    table = dataclasses.replace(ate_2d.METRIC.tables[0], after="rpe_time")
    moved = dataclasses.replace(ate_2d.METRIC, tables=(table,))
    names = [t[0] for t in build_tables(grid, [8.0], metrics=(moved,), time_delta=2.0)]
    assert names[names.index("rpe_time_2s") + 1] == table.name


def test_a_record_after_the_time_rpe_follows_it_under_any_interval():
    """A metric's ``after`` names the base record's keys as RECORD_KEYS spells them (the time RPE's:
    rpe_time, whatever its interval)."""
    from epa.metrics import ate_2d, registry

    moved = dataclasses.replace(ate_2d.METRIC, after="rpe_time")
    record = {"drift_rate_pct": {}, "rpe_time_2s": {"delta_s": 2.0}, "rpe": []}
    assert registry.anchor(moved, record, [moved]) == "rpe_time_2s"
    assert registry.anchor(moved, {"rpe_time_1s": {}, "rpe": []}, [moved]) == "rpe_time_1s"
    assert registry.anchor(moved, {"rpe": []}, [moved]) is None  # no time RPE: last


def test_the_base_tables_a_metric_may_follow_are_the_tables_the_grid_writes():
    from epa.outputs.tables import latex

    for delta in (1.0, 2.0):  # no metric on: the base tables alone, in order
        names = [t[0] for t in latex.build_tables([], [8], time_delta=delta)]
        assert names == list(accuracy.base_tables(delta))
