"""Provenance of a results folder (``provenance.json`` and ``config.resolved.yaml``): what made it.

Everything but the ``volatile`` section is a function of the inputs, the resolved config, the
checkout and the installed environment: two runs on the same machine with the same inputs write the
same bytes outside ``volatile``. ``volatile`` holds what must vary from run to run: the time, the
command line, the host, the working directory (the folder relative input paths are read from) and
the workflow's folder. No table, ``summary.csv`` or case artifact ever holds any of it.
See docs/reproducibility.md.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import os
import platform
import shlex
import socket
import stat
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

from epa import __version__

FORMAT = 1
PROVENANCE = "provenance.json"
CONFIG = "config.resolved.yaml"
# the runtime dependencies (pyproject.toml's [project] dependencies), by distribution name
RUNTIME_PACKAGES = (
    "numpy",
    "scipy",
    "pandas",
    "matplotlib",
    "rosbags",
    "pyyaml",
    "jsonschema",
    "snakemake",
)
VOLATILE = ("created_utc", "command_line", "host", "workdir", "workflow_dir")
COMMAND_ENV = "EPA_COMMAND_LINE"  # the Snakefile puts Snakemake's command line here for the script


def sha256(path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def file_record(path) -> dict:
    """An input file as recorded: its path (as the config gives it), size and sha256; or missing."""
    p = Path(path)
    try:
        if not stat.S_ISREG(p.stat().st_mode):  # a device or a FIFO is never read here
            return {"path": str(path), "missing": True, "not_a_file": True}
        return {"path": str(path), "size": p.stat().st_size, "sha256": sha256(p)}
    except (OSError, ValueError):
        return {"path": str(path), "missing": True}


def case_inputs(truth, estimate, timing=None) -> list[str]:
    """The files one case reads: each side's file or a ROS 2 bag folder's files, and a timing file."""
    from epa.readers import bags

    paths = set()
    for p in (truth, estimate):
        try:
            paths.update(str(f) for f in bags.bag_files(p))
        except OSError:  # a name the system refuses: recorded as given (and missing)
            paths.add(str(p))
    if timing:
        paths.add(str(timing))
    return sorted(paths)


def run_timing(cfg: dict, estimate, algorithm: str):
    """A run's timing file under ``cfg`` (None when it has none or its configured one is missing)."""
    from epa import readers
    from epa.core.errors import EpaError

    try:
        return readers.timing_file(estimate, readers.options(cfg, "estimate", algorithm=algorithm))
    except (EpaError, OSError):
        return None


def grid_inputs(cfg: dict, cases, idle_truths: dict | None = None) -> list[str]:
    """Every file a grid reads: its cases' references, runs, timing files, bag files, and (mode
    ov_eval) the references no run uses."""
    paths: set[str] = set()
    for c in cases:
        paths.update(case_inputs(c.truth, c.estimate, run_timing(cfg, c.estimate, c.algorithm)))
    paths.update(str(p) for p in (idle_truths or {}).values())
    return sorted(paths)


def _git(folder, *args) -> str | None:
    try:
        out = subprocess.run(
            ["git", "-C", str(folder), *args], capture_output=True, text=True, timeout=20
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def checkout(folder) -> dict:
    """The workflow's git commit when ``folder`` is a checkout (and whether tracked files differ)."""
    if folder is None:
        return {}
    commit = _git(folder, "rev-parse", "HEAD")
    if not commit:
        return {}
    status = _git(folder, "status", "--porcelain", "--untracked-files=no")
    return {"git_commit": commit, "git_dirty": bool(status)}


def environment() -> dict:
    """Python, every runtime dependency's version and the platform (deterministic on one machine)."""
    packages = {}
    for name in RUNTIME_PACKAGES:
        try:
            packages[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            packages[name] = None
    return {
        "python": {
            "version": platform.python_version(),
            "implementation": platform.python_implementation(),
        },
        "packages": packages,
        "platform": {
            "system": platform.system(),
            "release": platform.release(),
            "machine": platform.machine(),
            "platform": platform.platform(),
        },
    }


def config_yaml(cfg: dict) -> str:
    """The resolved config as YAML (every setting, defaults included; keys in the schema's order)."""
    import yaml

    head = (
        "# Every setting of this run, defaults included (epica resolved them). Regenerate with\n"
        "# `epa verify RESULTS_DIR` or `snakemake --cores 2 --configfile config.resolved.yaml`.\n"
    )
    return head + yaml.safe_dump(
        json.loads(json.dumps(cfg)), sort_keys=False, allow_unicode=True, width=100
    )


def document(
    kind: str,
    cfg: dict,
    inputs,
    *,
    workflow_dir=None,
    command_line: str | None = None,
    workdir=None,
    extra: dict | None = None,
) -> dict:
    """The provenance record: ``kind`` is ``grid`` (a workflow's results) or ``case`` (``epa eval``)."""
    doc = {
        "format": FORMAT,
        "kind": kind,
        "epica": {"version": __version__, **checkout(workflow_dir)},
        **environment(),
        **(extra or {}),
        "config": cfg,
        "config_file": CONFIG,
        "inputs": [file_record(p) for p in sorted(set(map(str, inputs)))],
        "volatile": {
            "created_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "command_line": command_line
            or os.environ.get(COMMAND_ENV)
            or shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]]),
            "host": socket.gethostname(),
            "workdir": str(Path(workdir or os.getcwd()).resolve()),
            "workflow_dir": None if workflow_dir is None else str(Path(workflow_dir).resolve()),
        },
    }
    return doc


def write(folder, doc: dict) -> list[Path]:
    """``provenance.json`` and ``config.resolved.yaml`` into ``folder``."""
    from epa.artifacts import files as io

    folder = Path(folder)
    io.write_text(folder / CONFIG, config_yaml(doc["config"]))
    io.write_text(folder / PROVENANCE, json.dumps(doc, indent=2, ensure_ascii=False) + "\n")
    return [folder / PROVENANCE, folder / CONFIG]


def read(folder) -> dict:
    with open(Path(folder) / PROVENANCE, encoding="utf-8") as fh:
        return json.load(fh)


def stable(doc: dict) -> dict:
    """The record without its volatile fields: equal for two runs of the same inputs."""
    return {k: v for k, v in doc.items() if k != "volatile"}
