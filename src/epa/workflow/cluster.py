"""Slurm: the CPUs a cluster job may use, and the check a run through snakemake-executor-plugin-slurm
(2.x) needs before it submits anything.

The plugin learns that a job has finished only from its job-state query (``sacct`` or ``squeue``). A
query that fails, or a finished job that has already left ``squeue``, looks to it like a job still
queued, and the run waits forever. :func:`status_query_problem` asks the query the plugin will use
once, the way the plugin will, and says in one line what to set when it does not answer.

No snakemake import here: the workflow passes the executor's settings (see rules/common.smk).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
from datetime import datetime, timedelta

PLUGIN_INIT_SECONDS = 40  # the plugin's default slurm-init-seconds-before-status-checks
PLUGIN_MAX_SLEEP = 180  # the plugin's longest wait between two queries (s)
PROFILE = "profiles/slurm/config.yaml"


def usable_cpus() -> int:
    """The CPUs this process may use: its affinity mask and, in a Slurm job, its allocation
    (SLURM_CPUS_PER_TASK; a cluster job's Snakemake is started with --cores all, the node's)."""
    usable = (
        len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    )
    allocated = os.environ.get("SLURM_CPUS_PER_TASK", "")
    if allocated.isdigit() and int(allocated) > 0:
        usable = min(usable, int(allocated))
    return max(1, usable)


def min_job_age() -> int | None:
    """Slurm's MinJobAge (s): how long a finished job stays visible to squeue; None if unknown."""
    out = _run(["scontrol", "show", "config"])[1]
    m = re.search(r"^\s*MinJobAge\s*=\s*(\d+)\s*([a-zA-Z]*)", out, re.M)
    if not m:
        return None
    return int(m.group(1)) * (3600 if m.group(2).lower() in ("h", "hour", "hours") else 1)


def status_command(
    status_setting: str | None, init_seconds: int | None, min_age: int | None
) -> str:
    """The command the plugin will poll with, as it decides (plugin 2.x, job_status_query.py and
    check_active_jobs): its ``status_command`` setting (default sacct where sacct exists), except
    that squeue falls back to sacct when MinJobAge is under 3 x the first wait and sacct exists, and
    sacct falls back to squeue when sacct does not exist."""
    has_sacct = shutil.which("sacct") is not None
    name = status_setting or ("sacct" if has_sacct else "squeue")
    init = init_seconds or PLUGIN_INIT_SECONDS
    if name == "squeue" and (min_age is None or min_age < 3 * init) and has_sacct:
        name = "sacct"
    if name == "sacct" and not has_sacct:
        name = "squeue"
    return name


def query(name: str) -> list[str]:
    """The plugin's query for one run (a run name no job has: the answer is empty, or an error)."""
    if name == "sacct":
        start = f"{datetime.now() - timedelta(days=2):%Y-%m-%dT%H:00}"
        return [
            "sacct",
            "-X",
            "--parsable2",
            "--clusters",
            "all",
            "--noheader",
            "--format=JobIdRaw,State",
            "--starttime",
            start,
            "--endtime",
            "now",
            "--name",
            "epica-status-check",
        ]
    return [
        "squeue",
        "--format=%i|%T",
        "--states=all",
        "--noheader",
        "--name",
        "epica-status-check",
    ]


def status_query_problem(status_setting: str | None, init_seconds: int | None) -> str | None:
    """None when the job-state query the plugin will rely on answers; else one line saying what to set."""
    min_age = min_job_age()
    name = status_command(status_setting, init_seconds, min_age)
    init = init_seconds or PLUGIN_INIT_SECONDS
    rc, out, err = _run(query(name))
    if rc != 0:
        said = (err or out).strip().splitlines()
        why = said[-1] if said else f"exit status {rc}"
        cmd = shlex.join(query(name)[:1])
        if name == "sacct" and status_setting == "squeue":
            limit = f"<= {min_age // 3}" if min_age else "<= MinJobAge / 3"
            return (
                f"the Slurm job-state query `{cmd}` (which the plugin uses instead of squeue because "
                f"MinJobAge {min_age} s is under 3 x slurm-init-seconds-before-status-checks = "
                f"{3 * init} s) fails ({why}), so the run would wait forever: set "
                f"`slurm-init-seconds-before-status-checks: {limit.split()[-1]}` or less in {PROFILE}, "
                f"or enable Slurm accounting (slurmdbd)"
            )
        if name == "sacct":
            return (
                f"the Slurm job-state query `{cmd}` fails ({why}), so the run would wait forever: "
                f"set `slurm-status-command: squeue` in {PROFILE} (with "
                f"slurm-init-seconds-before-status-checks <= MinJobAge / 3) or enable Slurm "
                f"accounting (slurmdbd)"
            )
        return (
            f"the Slurm job-state query `{cmd}` fails ({why}): the run would wait forever; run "
            f"Snakemake where Slurm's commands reach the controller"
        )
    if name == "squeue" and min_age is not None and min_age < PLUGIN_MAX_SLEEP:
        return (
            f"job states come from squeue, but Slurm forgets a finished job after MinJobAge = "
            f"{min_age} s, less than the plugin's longest wait between queries ({PLUGIN_MAX_SLEEP} "
            f"s), so a run could wait forever: set `slurm-status-command: sacct` in {PROFILE} "
            f"(needs Slurm accounting) or ask for MinJobAge >= {PLUGIN_MAX_SLEEP}"
        )
    return None


def cores_problem(cores) -> str | None:
    """None when some node has the CPUs one submission asks for (the profile's ``cores``); else one
    line. Slurm keeps a job that no node can hold pending (reason PartitionConfig), and the run waits."""
    if not isinstance(cores, int) or cores < 1:
        return None
    rc, out, _ = _run(["sinfo", "-h", "-N", "-o", "%c"])
    counts = [int(x) for x in re.findall(r"\d+", out)] if rc == 0 else []
    if not counts or cores <= max(counts):
        return None
    return (
        f"a submission asks for {cores} CPUs (`cores: {cores}` in {PROFILE}) but no Slurm node has "
        f"more than {max(counts)}, so its jobs would pend forever: set `cores: {max(counts)}` or less"
    )


def _run(cmd: list[str]) -> tuple[int, str, str]:
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    except FileNotFoundError:
        return 127, "", f"{cmd[0]}: command not found"
    except subprocess.TimeoutExpired:
        return 124, "", "no answer within 60 s"
    return p.returncode, p.stdout, p.stderr
