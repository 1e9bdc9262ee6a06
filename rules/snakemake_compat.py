"""The Snakemake internals epica reads where Snakemake offers no public way, all in one place.

Everything else in the rules is Snakemake's public API: directives, profiles (profiles/default sets
`force-use-threads` and the scheduler), `workflow.cores`, `workflow.current_basedir`. Each function
below names the attribute it reads; on a Snakemake that lacks it, the run stops with one line
saying which and what range epica is checked on, never with an AttributeError in the middle of a
run. tests/test_snakemake_compat.py runs each one on the installed Snakemake.
"""

from __future__ import annotations

import snakemake
from snakemake.exceptions import WorkflowError

# The Snakemake releases every function below was checked on (the range in pyproject.toml; CI runs
# the example on both ends).
CHECKED = "9.1.4 to 9.27.1"


def _attribute(workflow, path: str, why: str):
    """``workflow.<path>``, or one line saying that this Snakemake has no such attribute."""
    value = workflow
    for name in path.split("."):
        try:
            value = getattr(value, name)
        except AttributeError:
            raise WorkflowError(
                f"epa: error: epica reads Snakemake's workflow.{path} ({why}), which Snakemake "
                f"{snakemake.__version__} does not have; epica is checked on Snakemake {CHECKED} "
                f"(pip install 'snakemake>=9.1.4,<10')"
            ) from None
    return value


def module_name(workflow) -> str | None:
    """The name epica has as another workflow's module (`module epica:`), None when it is the main
    workflow. Public API has no such question: a module's config is its host's, given whole."""
    return _attribute(workflow, "modifier.namespace", "is epica another workflow's module")


def user_config_files(workflow) -> list:
    """The `--configfile` files of the command line (or a profile), without the Snakefile's own
    config/config.yaml: the grid a user names must name its own folders."""
    return list(_attribute(workflow, "overwrite_configfiles", "the --configfile files") or [])


def command_line_config(workflow) -> dict:
    """The `--config key=value` settings (Snakemake 9.x merges the `--configfile` files' in too):
    Snakemake reads nested values given there as strings, which epica turns back into the
    schema's types for these keys only."""
    return dict(
        _attribute(workflow, "config_settings.overwrite_config", "the --config settings") or {}
    )


def executor(workflow) -> tuple[str | None, object]:
    """The executor plugin's name ("local", "slurm", ...) and its settings (the plugin's own
    options, e.g. the slurm plugin's status_command), for the checks before a cluster run."""
    plugin = _attribute(workflow, "executor_plugin", "the executor of this run")
    settings = _attribute(workflow, "executor_settings", "the executor's settings")
    return getattr(plugin, "name", None), settings


def in_cluster_job(workflow) -> bool:
    """True in the Snakemake a cluster executor starts inside a job (`--mode remote`)."""
    return bool(_attribute(workflow, "remote_exec", "is this a cluster job's Snakemake"))


def run_here(workflow, rules, cpus: int) -> None:
    """Inside a cluster job: ``rules`` run in this process as local rules (not each under `srun` in
    a Snakemake of its own), as many side by side as the job has ``cpus``. The `localrules:`
    directive takes literal names only; the rules are epica's generated stage list."""
    _attribute(workflow, "localrules", "the localrules directive's function")(*rules)
    if _attribute(workflow, "nodes", "the --jobs limit") is not None:
        # the executor starts the job's Snakemake with --jobs 1; its CPUs are the limit instead
        _attribute(workflow, "register_resource", "the --jobs limit's resource")("_nodes", cpus)


def scheduler_timers() -> list:
    """Snakemake's pending job-rate-limiter timers. Its scheduler starts a 1 s threading.Timer at
    each scheduling round (`--max-jobs-per-timespan`, whose shortest span is 1 s), and the process
    waits for the last one to fire before it ends: up to 1 s after the run, for nothing. Only the
    scheduler's (its function is a JobScheduler method's): any other timer is left alone."""
    import threading

    return [
        thread
        for thread in threading.enumerate()
        if isinstance(thread, threading.Timer)
        and "JobScheduler." in getattr(getattr(thread, "function", None), "__qualname__", "")
    ]
