"""A change re-runs only what it affects (docs/running.md, "What a change re-runs"): the bundled
example run once, then a setting of one section changed, and the dry run's job list is exactly the
jobs that read it and those after them. One run of the example (8 batches), then dry runs."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BATCHES = 8  # the example's 18 cases in grid.max_batches batches
STAGES_FROM_EFFICIENCY = {"efficiency": BATCHES, "report": BATCHES}
SUMMARY = {"tables": 1, "figures": 1, "paper": 1, "provenance": 1}


def _config(results: Path, extra: str = "") -> str:
    return (
        f"truth_dir: {ROOT / 'example/truth'}\nalgorithms_dir: {ROOT / 'example/algorithms'}\n"
        f"results_dir: {results}\nefficiency: {{sensor_rate_hz: 20}}\n"
        "report: {per_case: false}\n" + extra
    )


def _snakemake(tmp: Path, config: str, *args: str) -> str:
    (tmp / "cfg.yaml").write_text(config)
    cmd = [sys.executable, "-m", "snakemake", "--cores", "2", "-s", str(ROOT / "Snakefile")]
    out = subprocess.run(
        [*cmd, "-d", str(tmp), "--configfile", str(tmp / "cfg.yaml"), *args],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, (out.stdout + out.stderr)[-3000:]
    return out.stdout + out.stderr


def _planned(log: str) -> dict[str, int]:
    """rule -> jobs, from a dry run's "Job stats" table (without the target rule `all`)."""
    if "Nothing to be done" in log:
        return {}
    table = log[log.index("Job stats:") :].split("\n\n")[0]
    rows = re.findall(r"^(\w+)\s+(\d+)\s*$", table, re.M)
    return {rule: int(n) for rule, n in rows if rule not in ("all", "total")}


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("reruns")
    _snakemake(tmp, _config(tmp / "results"), "--quiet")
    return tmp


@pytest.mark.parametrize(
    "change,expected",
    [
        ("", {}),  # a second run does nothing
        # a per-case report setting: the report stage, and the record of the resolved config
        ("report: {per_case: false, figures: none}\n", {"report": BATCHES, "provenance": 1}),
        # a tables setting: the tables and what is made of them
        ("tables: {spread: ci}\n", SUMMARY),
        # a stage's setting: that stage onward, then the tables
        ("efficiency: {sensor_rate_hz: 10}\n", {**STAGES_FROM_EFFICIENCY, **SUMMARY}),
    ],
    ids=["nothing", "report", "tables", "efficiency"],
)
def test_a_change_reruns_what_reads_it(finished, change, expected):
    config = _config(finished / "results")
    if change:  # the changed section replaces the example's
        key = change.split(":")[0]
        config = "".join(
            line + "\n" for line in config.splitlines() if not line.startswith(key + ":")
        )
        config += change
    assert _planned(_snakemake(finished, config, "-n")) == expected
