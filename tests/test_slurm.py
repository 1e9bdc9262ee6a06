"""The Slurm profile without a cluster: its groups, the plan it makes, and the job-state check
(src/epa/workflow/cluster.py) against stand-in sacct/squeue/scontrol commands. The run on a real Slurm is
.ci/slurm (CI calls it directly: it needs root, apt-get and daemons, which a test should not start)."""

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from epa.workflow import chain
from epa.workflow import cluster as slurm

ROOT = Path(__file__).resolve().parents[1]
PROFILE = ROOT / "profiles" / "slurm" / "config.yaml"


def _profile():
    return yaml.safe_load(PROFILE.read_text())


def test_profile_groups_every_stage_into_one_chain():
    groups = dict(item.split("=") for item in _profile()["groups"])
    assert {groups[name] for name in chain.NAMES} == {"chain"}
    assert {groups[name] for name in ("tables", "provenance", "figures", "paper")} == {"summary"}
    components = dict(item.split("=") for item in _profile()["group-components"])
    assert set(components) == {"chain", "summary"}


def test_profile_relies_on_a_job_state_query_that_needs_no_database():
    prof = _profile()
    assert prof["executor"] == "slurm"
    assert prof["slurm-status-command"] == "squeue"
    # the plugin falls back to sacct when MinJobAge (default 300 s) < 3 x the first wait
    assert 3 * prof["slurm-init-seconds-before-status-checks"] <= 300


def test_every_profile_setting_is_commented():
    lines = PROFILE.read_text().splitlines()
    for i, line in enumerate(lines):
        if re.match(r"^[a-z][a-z-]*:", line):  # a top-level setting: a comment right above it
            assert lines[i - 1].startswith("#"), f"{line!r} has no comment"


@pytest.mark.skipif(
    importlib.util.find_spec("snakemake_executor_plugin_slurm") is None,
    reason="snakemake-executor-plugin-slurm is not installed",
)
def test_dry_run_plans_one_submission_per_eight_batches_and_one_for_the_summary(tmp_path):
    cfg = tmp_path / "grid.yaml"
    cfg.write_text(
        f"truth_dir: {ROOT}/example/truth\nalgorithms_dir: {ROOT}/example/algorithms\n"
        f"results_dir: {tmp_path}/results\nreport:\n  per_case: false\n"
    )
    env = dict(
        os.environ, PYTHONPATH=f"{ROOT / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"
    )
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-n",
            "--profile",
            str(PROFILE),
            "--configfile",
            str(cfg),
            "--directory",
            str(ROOT),
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    text = out.stdout + out.stderr
    # the example: 18 cases in grid.max_batches = 8 batches, 8 chains to a submission: one, then the summary
    assert len(re.findall(r"Group job chain ", text)) == 1
    assert len(re.findall(r"Group job summary ", text)) == 1


# ----------------------------------------------------------------------------- the job-state check
def _fake_slurm(tmp_path, monkeypatch, *, sacct_ok, squeue_ok=True, min_job_age=300, sacct=True):
    """Stand-ins for sacct, squeue and scontrol on PATH (only them)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()

    def tool(name, ok, out=""):
        body = (
            f"#!/bin/sh\nprintf '%s' '{out}'\nexit 0\n"
            if ok
            else f"#!/bin/sh\necho '{name}: error: Slurm accounting storage is disabled' >&2\nexit 1\n"
        )
        (bin_dir / name).write_text(body)
        (bin_dir / name).chmod(0o755)

    if sacct:
        tool("sacct", sacct_ok)
    tool("squeue", squeue_ok)
    tool("scontrol", True, f"MinJobAge               = {min_job_age} sec\\n")
    tool("sinfo", True, "2\\n4\\n")
    monkeypatch.setenv("PATH", str(bin_dir))
    return bin_dir


def test_plugin_default_sacct_without_accounting_stops_with_what_to_set(tmp_path, monkeypatch):
    _fake_slurm(tmp_path, monkeypatch, sacct_ok=False)
    problem = slurm.status_query_problem(None, None)
    assert problem.startswith(
        "the Slurm job-state query `sacct` fails (sacct: error: Slurm accounting"
    )
    assert "set `slurm-status-command: squeue`" in problem
    assert "\n" not in problem


def test_squeue_answers(tmp_path, monkeypatch):
    _fake_slurm(tmp_path, monkeypatch, sacct_ok=False)
    assert slurm.status_query_problem("squeue", 10) is None


def test_squeue_with_a_long_first_wait_falls_back_to_a_failing_sacct(tmp_path, monkeypatch):
    _fake_slurm(tmp_path, monkeypatch, sacct_ok=False, min_job_age=300)
    assert slurm.status_command("squeue", 200, 300) == "sacct"
    problem = slurm.status_query_problem("squeue", 200)
    assert "set `slurm-init-seconds-before-status-checks: 100` or less" in problem


def test_squeue_with_a_short_min_job_age_stops(tmp_path, monkeypatch):
    _fake_slurm(tmp_path, monkeypatch, sacct_ok=False, min_job_age=60, sacct=False)
    problem = slurm.status_query_problem("squeue", 10)
    assert "MinJobAge = 60 s" in problem and "set `slurm-status-command: sacct`" in problem


def test_sacct_setting_without_sacct_uses_squeue(tmp_path, monkeypatch):
    _fake_slurm(tmp_path, monkeypatch, sacct_ok=True, sacct=False)
    assert slurm.status_command("sacct", 40, 300) == "squeue"
    assert slurm.status_query_problem("sacct", 40) is None


def test_no_slurm_commands(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))
    problem = slurm.status_query_problem("squeue", 10)
    assert "`squeue` fails (squeue: command not found)" in problem


# ----------------------------------------------------------------------------- a cluster job's CPUs
def test_usable_cpus_is_the_slurm_allocation_not_the_node(monkeypatch):
    node = len(os.sched_getaffinity(0))
    monkeypatch.delenv("SLURM_CPUS_PER_TASK", raising=False)
    assert slurm.usable_cpus() == node
    monkeypatch.setenv("SLURM_CPUS_PER_TASK", "1")
    assert slurm.usable_cpus() == 1
    monkeypatch.setenv("SLURM_CPUS_PER_TASK", str(node + 8))  # never more than the process may use
    assert slurm.usable_cpus() == node


def test_a_submission_wider_than_any_node_stops(tmp_path, monkeypatch):
    _fake_slurm(tmp_path, monkeypatch, sacct_ok=True)
    assert slurm.cores_problem(4) is None
    problem = slurm.cores_problem(8)
    assert "no Slurm node has more than 4" in problem and "set `cores: 4` or less" in problem
