"""The bundled example's outputs against the golden copy in tests/golden/example/, by the numeric
contract (docs/reproducibility.md, epa.outputs.contract): the grid's printed outputs (tables,
summary.csv, ...) as text, every case's stage records (JSON, rpg's YAML) number by number, and every
array artifact (CSV, TUM) by its fingerprint: its first and last row and each column's min, max and
mean, number by number. The golden copy was made on one machine; on another CPU these agree within
the contract, and a printed digit may flip only at a rounding boundary (reported, not failed).
A changed formula fails here: tests/test_golden.py::test_a_change_of_1e-6_in_one_metric_fails shows it.

To accept a deliberate change: ``EPA_UPDATE_GOLDEN=1 python -m pytest tests/test_golden.py``, then
review the diff of tests/golden/ before committing it.
"""

import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import run_stages

from epa.outputs import contract, tables
from epa.workflow import chain, compared, discovery, settings

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden" / "example"
# the printed grid files verify compares, but mode rpg's (the example runs mode epa)
GRID_FILES = tuple(n for n in compared.GRID_FILES if not n.startswith("rpg_"))
RECORDS = "records"  # tests/golden/example/records/: the stage records and array fingerprints
UPDATE = os.environ.get("EPA_UPDATE_GOLDEN") == "1"


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The example grid with config/config.yaml, every stage but the per-case report, in this
    process (the workflow's jobs write the same bytes: tests/test_workflow.py)."""
    out = tmp_path_factory.mktemp("golden") / "results"
    cwd = os.getcwd()
    os.chdir(ROOT)  # the config's folders are relative to the checkout, as in `snakemake --cores 2`
    try:
        cfg = settings.resolve(settings.load_yaml(ROOT / "config/config.yaml"))
        _, cases = discovery.discover(cfg["truth_dir"], cfg["algorithms_dir"])
        batch = [{"key": c.key, "truth": str(c.truth), "estimate": str(c.estimate)} for c in cases]
        run_stages(batch, out, cfg, chain.NAMES[:-1])
        assert tables.make(sorted(c.key for c in cases), out, cfg) == []
    finally:
        os.chdir(cwd)
    return out


def record_names(results: Path) -> list[str]:
    """Every stage artifact of every case and the grid's per-dataset consistency series."""
    files = [*results.glob("cases/*/*/*/[0-9][0-9]_*/**/*"), *results.glob("consistency/*/*.csv")]
    return sorted(str(p.relative_to(results)) for p in files if p.is_file())


def fingerprint(text: str) -> str:
    """An array artifact in six rows: its header lines, then its first and last row and each
    column's min, max and mean (a column of words: nan), with the row count in a comment."""
    lines = text.splitlines()
    head = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if line.strip() and not line.startswith("#")]
    sep = "," if "," in (body[0] if body else "") else " "
    if body and sep == "," and not all(_number(c) == _number(c) for c in body[0].split(",")):
        head.append(body.pop(0))  # a CSV's column names
    rows = [line.split(sep) for line in body]
    out = [f"# fingerprint of {len(rows)} rows: first, last, min, max, mean", *head]
    if rows:
        x = np.array([[_number(c) for c in row] for row in rows])
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a column of words: all-NaN
            stats = (np.nanmin(x, 0), np.nanmax(x, 0), np.nanmean(x, 0))
        out += [sep.join(rows[0]), sep.join(rows[-1])]
        out += [sep.join(f"{v:.17g}" for v in row) for row in stats]
    return "\n".join(out) + "\n"


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return np.nan


def golden_text(results: Path, name: str) -> str:
    text = (results / name).read_text()
    return text if name.endswith((".json", ".yaml")) else fingerprint(text)


def test_grid_outputs_are_the_golden_text(example):
    names = list(GRID_FILES) + [
        f"tables/{p.name}" for p in sorted((example / "tables").glob("*.tex"))
    ]
    if UPDATE:
        shutil.rmtree(GOLDEN / "tables", ignore_errors=True)
        for name in names:
            (GOLDEN / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(example / name, GOLDEN / name)
    want = sorted(
        str(p.relative_to(GOLDEN))
        for p in GOLDEN.rglob("*")
        if p.is_file() and RECORDS not in p.relative_to(GOLDEN).parts
    )
    assert sorted(names) == want
    for name in names:
        got = contract.compare_printed(
            name, (GOLDEN / name).read_text(), (example / name).read_text()
        )
        assert got.ok, got.line()


def test_case_records_are_the_golden_numbers(example):
    names = record_names(example)
    if UPDATE:
        shutil.rmtree(GOLDEN / RECORDS, ignore_errors=True)
        for name in names:
            (GOLDEN / RECORDS / name).parent.mkdir(parents=True, exist_ok=True)
            (GOLDEN / RECORDS / name).write_text(golden_text(example, name))
    assert names == record_names(GOLDEN / RECORDS)
    failed = []
    for name in names:
        got = contract.compare_record(
            name, (GOLDEN / RECORDS / name).read_text(), golden_text(example, name)
        )
        if not got.ok:
            failed.append(got.line())
    assert not failed, "records that break the contract:\n" + "\n".join(failed[:20])


def test_a_change_of_1e_6_in_one_metric_fails(example, tmp_path, monkeypatch):
    """The contract still catches a changed formula: the per-pose APE scaled by 1 + 1e-6 in one case
    breaks its metrics.json, ape.csv and drift records against the golden copy."""
    from epa.metrics import accuracy

    ape = accuracy.ape
    monkeypatch.setattr(
        accuracy, "ape", lambda *a, **k: tuple(x * (1 + 1e-6) for x in ape(*a, **k))
    )
    key = "vio_body/drone_figure8/run1"
    case = {
        "key": key,
        "truth": str(ROOT / "example/truth/drone_figure8.txt"),
        "estimate": str(ROOT / f"example/algorithms/{key.split('/', 1)[0]}/drone_figure8/run1.txt"),
    }
    cfg = settings.resolve(settings.load_yaml(ROOT / "config/config.yaml"))
    run_stages([case], tmp_path, cfg, chain.NAMES[:-1])
    verdicts = {}
    for name in ("06_metrics/metrics.json", "06_metrics/ape.csv", "05_align/transform.json"):
        full = f"cases/{key}/{name}"
        verdicts[name] = contract.compare_record(
            full, (GOLDEN / RECORDS / full).read_text(), golden_text(tmp_path, full)
        )
    assert verdicts["06_metrics/metrics.json"].verdict == contract.Verdict.DIFFERS
    assert "$.ate" in verdicts["06_metrics/metrics.json"].worst.where
    assert verdicts["06_metrics/ape.csv"].verdict == contract.Verdict.DIFFERS
    assert verdicts["05_align/transform.json"].ok  # upstream of the change: still within


def test_a_tampered_digit_fails(example):
    """A sixth significant digit changed in a record, one printed digit changed in a table."""
    name = "cases/vio_body/drone_figure8/run1/06_metrics/metrics.json"
    text = (GOLDEN / RECORDS / name).read_text()
    value = repr(__import__("json").loads(text)["ate"]["trans_m"]["rmse"])
    tampered = text.replace(value, repr(float(value) * (1 + 1e-5)), 1)
    got = contract.compare_record(name, text, tampered)
    assert got.verdict == contract.Verdict.DIFFERS and got.worst.where == "$.ate.trans_m.rmse"
    table = (GOLDEN / "error_comparison.txt").read_text()
    digit = table.index("0.0")  # the first printed number with decimals: its last digit + 2
    end = digit + len(contract._NUMBER.match(table, digit).group())
    changed = table[: end - 1] + str((int(table[end - 1]) + 2) % 10) + table[end:]
    got = contract.compare_printed("error_comparison.txt", table, changed)
    assert got.verdict == contract.Verdict.DIFFERS and got.worst.where.startswith("line ")


def test_tables_from_cases_read_in_parallel_are_the_same_bytes(example, tmp_path, monkeypatch):
    """The tables rule reads a large grid's cases in forked processes (results.collect): the same
    tables, here forced on the example's 18 cases, handed back 5 at a time. What a case keeps is
    only the columns the tables read, in arrays of their own (not views of the whole parsed table,
    which a 10,000-case grid held in memory all at once), each segment length's pairs as the run of
    rows the metrics stage writes (no length column)."""
    from epa.outputs.tables import results

    monkeypatch.setattr(results, "PARALLEL_FROM_CASES", 2)
    monkeypatch.setattr(results, "SHARE_CASES", 5)
    out = tmp_path / "results"
    out.mkdir()
    (out / "cases").symlink_to(example / "cases")
    cfg = settings.resolve(settings.load_yaml(ROOT / "config/config.yaml"))
    keys = sorted("/".join(p.parts[-3:]) for p in (example / "cases").glob("*/*/*"))
    grid = results.collect(keys, out, workers=2)
    assert [f"{c.algorithm}/{c.dataset}/{c.run}" for c in grid] == keys and len(keys) == 18
    kept = [c for c in grid if c.ok]
    assert kept and all(
        set(c.segments) == {"length_runs", "rot_deg", "trans_m", "valid"} for c in kept
    )
    lengths = [float(s) for s in cfg["metrics"]["segments"]]
    assert all(sorted(c.segments["length_runs"]) == lengths for c in kept)
    assert all(set(c.time) == {"rot_deg", "trans_m", "valid"} for c in kept)
    columns = [
        a
        for c in kept
        for t in (c.segments, c.time, c.ape)
        for k, a in t.items()
        if k != "length_runs"
    ]
    # an array unpickled from a worker keeps a buffer of its own bytes; never the whole table's
    assert all(a.base is None or memoryview(a.base).nbytes == a.nbytes for a in columns)
    assert all(c.segments["valid"].dtype == bool for c in kept)
    assert tables.make(keys, out, cfg, workers=2) == []
    for name in GRID_FILES:
        assert (out / name).read_bytes() == (example / name).read_bytes(), name
