"""rules/snakemake_compat.py, the one place the rules read Snakemake's internals: each internal is
read on the installed Snakemake by a probe workflow (one run), and a Snakemake without it stops with
one line naming it. Checked on Snakemake 9.1.4 and 9.27.1 (the ends of pyproject.toml's range).
Also: a dry run starts no process, and the worker pool's fork server imports the main script's
imports once."""

import importlib.util
import json
import os
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COMPAT_PATH = ROOT / "rules" / "snakemake_compat.py"


def _compat():
    spec = importlib.util.spec_from_file_location("epica_snakemake_compat_test", COMPAT_PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


compat = _compat()

# A main workflow and a module of it, each calling every function of snakemake_compat at parse
# time, in onstart (where the executor is known) and in onsuccess (the scheduler's timer).
PROBE = """
import importlib.util, json

spec = importlib.util.spec_from_file_location("c", {compat!r})
c = importlib.util.module_from_spec(spec)
spec.loader.exec_module(c)


def probe(where, name, fn):
    try:
        value = fn()
    except Exception as exc:
        value = "ERROR " + str(exc)
    with open("probe.jsonl", "a") as fh:
        fh.write(json.dumps({{"where": where, "name": name, "value": repr(value)}}) + "\\n")


probe("{where}", "modifier.namespace", lambda: c.module_name(workflow))
probe("{where}", "overwrite_configfiles", lambda: [Path(p).name for p in c.user_config_files(workflow)])
probe("{where}", "config_settings.overwrite_config", lambda: c.command_line_config(workflow)["given"])
probe("{where}", "remote_exec", lambda: c.in_cluster_job(workflow))
probe("{where}", "localrules+register_resource", lambda: c.run_here(workflow, ["{where}_done"], 1))
"""
MAIN = (
    "from pathlib import Path\n"
    + PROBE.format(compat=str(COMPAT_PATH), where="main")
    + """

module inner:
    snakefile:
        "inner.smk"


use rule * from inner as inner_*


rule main_done:
    output:
        "main_done.txt",
    shell:
        "sleep 1.5; touch {output}"


rule all:
    default_target: True
    input:
        "main_done.txt",
        "inner_done.txt",


onstart:
    probe("main", "executor_plugin+executor_settings", lambda: c.executor(workflow)[0])


onsuccess:
    probe("main", "JobScheduler timer", lambda: len(c.scheduler_timers()) > 0)
"""
)
INNER = (
    "from pathlib import Path\n"
    + PROBE.format(compat=str(COMPAT_PATH), where="inner")
    + """

rule inner_done:
    output:
        "inner_done.txt",
    shell:
        "touch {output}"
"""
)


@pytest.fixture(scope="module")
def probed(tmp_path_factory):
    """internal -> what the probe read, where it read it."""
    tmp = tmp_path_factory.mktemp("probe")
    (tmp / "Snakefile").write_text(MAIN)
    (tmp / "inner.smk").write_text(INNER)
    (tmp / "given.yaml").write_text("x: 1\n")
    out = subprocess.run(
        [sys.executable, "-m", "snakemake", "--cores", "1", "--workflow-profile", "none"]
        + ["--configfile", "given.yaml", "--config", "given=2"],
        cwd=tmp,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, (out.stdout + out.stderr)[-3000:]
    found = {}
    for line in (tmp / "probe.jsonl").read_text().splitlines():
        row = json.loads(line)
        found[(row["where"], row["name"])] = row["value"]
    return found


@pytest.mark.parametrize(
    "where,name,expected",
    [
        ("main", "modifier.namespace", "None"),
        ("inner", "modifier.namespace", "'inner'"),
        ("main", "overwrite_configfiles", "['given.yaml']"),
        ("main", "config_settings.overwrite_config", "2"),  # read as YAML reads 2
        ("main", "remote_exec", "False"),
        ("main", "localrules+register_resource", "None"),
        ("main", "executor_plugin+executor_settings", "'local'"),
        # a rule ran for 1.5 s: the 1 s timer of the scheduler's last round (or more) is pending
        ("main", "JobScheduler timer", "True"),
    ],
)
def test_each_internal_is_there_on_this_snakemake(probed, where, name, expected):
    import snakemake

    got = probed.get((where, name))
    assert got == expected, (
        f"Snakemake {snakemake.__version__}: workflow.{name} read {got} where epica expects "
        f"{expected} (rules/snakemake_compat.py; checked on {compat.CHECKED})"
    )


@pytest.mark.parametrize(
    "read,internal",
    [
        (compat.module_name, "workflow.modifier.namespace"),
        (compat.user_config_files, "workflow.overwrite_configfiles"),
        (compat.command_line_config, "workflow.config_settings.overwrite_config"),
        (compat.executor, "workflow.executor_plugin"),
        (compat.in_cluster_job, "workflow.remote_exec"),
        (lambda wf: compat.run_here(wf, ["a"], 2), "workflow.localrules"),
    ],
)
def test_a_snakemake_without_it_is_one_line_naming_it(read, internal):
    from snakemake.exceptions import WorkflowError

    workflow = types.SimpleNamespace(modifier=types.SimpleNamespace())  # has none of them
    with pytest.raises(WorkflowError) as err:
        read(workflow)
    message = str(err.value)
    assert message.startswith("epa: error: epica reads Snakemake's " + internal + " (")
    assert f"checked on Snakemake {compat.CHECKED}" in message and "\n" not in message


def test_other_timers_are_not_the_schedulers():
    import threading

    timer = threading.Timer(60, lambda: None)
    timer.start()
    try:
        assert timer not in compat.scheduler_timers()
    finally:
        timer.cancel()


def _descendants(pid: int) -> set[int]:
    """Every live process under ``pid`` (Linux: /proc/<pid>/task/<tid>/children)."""
    found, stack = set(), [pid]
    while stack:
        parent = stack.pop()
        try:
            tasks = os.listdir(f"/proc/{parent}/task")
        except OSError:  # it has ended
            continue
        for task in tasks:
            try:
                kids = Path(f"/proc/{parent}/task/{task}/children").read_text().split()
            except OSError:
                continue
            for kid in map(int, kids):
                if kid not in found:
                    found.add(kid)
                    stack.append(kid)
    return found


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux's /proc")
def test_a_dry_run_starts_no_process(tmp_path):
    """`snakemake -n` parses the Snakefile and plans: no worker pool, no fork server, no Python
    process of any kind (the fork server would live until the run ends). Sampled every 10 ms. The
    commands Snakemake and its plugins run themselves (`uname -p` for its run record, `which
    squeue`) are no workers; a process seen between its fork and its exec still shows its parent's
    command line."""
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(
        f"truth_dir: {ROOT / 'example/truth'}\nalgorithms_dir: {ROOT / 'example/algorithms'}\n"
        f"results_dir: {tmp_path / 'results'}\n"
    )
    cmd = [sys.executable, "-m", "snakemake", "-n", "--cores", "2", "-s", str(ROOT / "Snakefile")]
    cmd += ["--configfile", str(cfg), "-d", str(tmp_path)]
    started: dict[int, str] = {}  # pid -> its command line when last seen
    with open(tmp_path / "log", "w") as out:  # a file: a full pipe would stop the dry run
        run = subprocess.Popen(cmd, stdout=out, stderr=out)
        while run.poll() is None:
            for pid in _descendants(run.pid):
                try:
                    started[pid] = Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")
                except OSError:
                    started.setdefault(pid, "")
            time.sleep(0.01)
    log = (tmp_path / "log").read_text()
    assert run.returncode == 0, log[-2000:]
    assert "rule load:" in log or "localrule load:" in log  # it planned the whole grid
    pythons = {
        pid: c
        for pid, c in started.items()
        if ("python" in c or "multiprocessing" in c) and c.strip() != " ".join(cmd)
    }
    assert pythons == {}


def test_the_fork_server_imports_a_scripts_imports_once(tmp_path, monkeypatch):
    """Under a console script (`snakemake`), each worker would run the script again: its imports
    go to the fork server's preload, so the workers find them imported."""
    from epa.workflow import jobs

    script = tmp_path / "snakemake"
    script.write_text(
        "import re\nimport sys\nfrom snakemake.cli import main\nif 1:\n    import x\n"
    )
    main = types.ModuleType("__main__")
    main.__file__, main.__spec__ = str(script), None
    monkeypatch.setitem(sys.modules, "__main__", main)
    assert jobs._main_imports() == ["re", "sys", "snakemake.cli"]
    main.__spec__ = types.SimpleNamespace(name="snakemake.__main__")  # python -m snakemake
    assert jobs._main_imports() == []
