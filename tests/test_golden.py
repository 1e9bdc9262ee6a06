"""The bundled example's outputs are the golden bytes in tests/golden/example/: the grid's tables and
summary.csv in full, every case's stage artifacts (records and arrays) by sha256. A refactor that
changes a number, a digit or a byte of any of them fails here.

To accept a deliberate change: ``EPA_UPDATE_GOLDEN=1 python -m pytest tests/test_golden.py``, then
review the diff of tests/golden/ before committing it.
"""

import hashlib
import os
import shutil
from pathlib import Path

import pytest
from conftest import run_stages

from epa.outputs import tables
from epa.workflow import chain, discovery, settings

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden" / "example"
GRID_FILES = (
    "error_comparison.txt",
    "summary.csv",
    "comparison.txt",
    "comparison.tex",
    "success_curves.csv",
    "consistency/summary.csv",
)
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


def _hashes(results: Path) -> str:
    files = sorted(
        p
        for folder in ("cases", "consistency")
        for p in (results / folder).rglob("*")
        if p.is_file() and "logs" not in p.parts and p.name != "summary.csv"
    )
    return "".join(
        f"{hashlib.sha256(p.read_bytes()).hexdigest()}  {p.relative_to(results)}\n" for p in files
    )


def test_grid_outputs_are_the_golden_bytes(example):
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
        if p.suffix != ".sha256" and p.is_file()
    )
    assert sorted(names) == want
    for name in names:
        assert (example / name).read_bytes() == (GOLDEN / name).read_bytes(), name


def test_case_artifacts_are_the_golden_bytes(example):
    got = _hashes(example)
    if UPDATE:
        (GOLDEN / "artifacts.sha256").write_text(got)
    want = (GOLDEN / "artifacts.sha256").read_text()
    changed = sorted(set(got.splitlines()) ^ set(want.splitlines()))
    assert not changed, "artifacts that differ from the golden copy:\n" + "\n".join(changed[:20])


def test_tables_from_cases_read_in_parallel_are_the_same_bytes(example, tmp_path, monkeypatch):
    """The tables rule reads a large grid's cases in forked processes (results.collect): the same
    tables, here forced on the example's 18 cases."""
    from epa.outputs.tables import results

    monkeypatch.setattr(results, "PARALLEL_FROM_CASES", 2)
    out = tmp_path / "results"
    out.mkdir()
    (out / "cases").symlink_to(example / "cases")
    cfg = settings.resolve(settings.load_yaml(ROOT / "config/config.yaml"))
    keys = sorted("/".join(p.parts[-3:]) for p in (example / "cases").glob("*/*/*"))
    assert len(results.collect(keys, out, workers=2)) == len(keys) == 18
    assert tables.make(keys, out, cfg, workers=2) == []
    for name in GRID_FILES:
        assert (out / name).read_bytes() == (example / name).read_bytes(), name
