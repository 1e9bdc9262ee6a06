# Parse-time setup: resolved settings (schema defaults filled in), the discovered cases, their batches.
# Every stage rule runs one stage for one batch (one case on small grids) in-process; see
# docs/performance.md for why, with the measurements.
import os
import shlex
import sys

import epa
from epa.core.errors import EpaError
from snakemake.exceptions import WorkflowError
from epa import readers as epa_readers
from epa.artifacts import files as epa_files
from epa.outputs import report as epa_report, tables as epa_tables
from epa.outputs import paper as epa_paper, provenance as epa_provenance
from epa.readers import bags as epa_bags
from epa.workflow import (
    chain as epa_chain,
    discovery as epa_discovery,
    jobs as epa_jobs,
    overrides as epa_overrides,
)
from epa.workflow import cluster as epa_cluster, settings as epa_settings
from epa.workflow import terminal as epa_terminal

epa_terminal.show_warnings()  # epa's warnings on stderr (the library prints nothing itself)


def workers():
    """Worker processes for in-process jobs: the cores Snakemake was given, and no more than this
    process may use: a cluster job is started with --cores all (the node's), but gets its
    allocation; without --cores (e.g. a remote job, or `snakemake --report`, where Snakemake
    refuses the question) one, in the calling thread."""
    cores = given_cores()
    return 1 if cores is None else max(1, min(cores, epa_cluster.usable_cpus()))


def given_cores():
    """--cores (the profile's `cores`), or None where Snakemake was given none."""
    try:
        return int(workflow.cores)
    except (TypeError, ValueError, WorkflowError):
        return None


# epica's own folder (this file's parent's): every internal path starts here, also where epica is
# another workflow's module (`module epica: snakefile: ...`), where workflow.basedir is that one's.
EPICA_DIR = os.path.dirname(str(workflow.current_basedir))


def _snakemake_compat():
    """rules/snakemake_compat.py: the only place that reads Snakemake's internals."""
    import importlib.util

    name = "epica_snakemake_compat"
    if name not in sys.modules:
        path = os.path.join(EPICA_DIR, "rules", "snakemake_compat.py")
        spec = importlib.util.spec_from_file_location(name, path)
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


snakemake_compat = _snakemake_compat()
# Stage jobs run in this process's threads (their work in epica's worker pool): profiles/default
# sets force-use-threads; a host workflow using epica as a module sets it (docs/running.md).
MODULE_NAME = snakemake_compat.module_name(workflow)  # None: the main workflow
IS_MODULE = MODULE_NAME is not None
COMMAND_LINE_CONFIG = snakemake_compat.command_line_config(workflow)

try:  # a mistake in the config or the folders is one line, not a traceback
    # a module's config is the host's config["epica"], given whole: nothing bundled is merged in
    if IS_MODULE:
        NAMED = set(config)
        CONFIG_SOURCE = f"config of module {MODULE_NAME}"
    else:
        NAMED = epa_settings.check_user_configs(
            snakemake_compat.user_config_files(workflow), COMMAND_LINE_CONFIG
        )
        # as Snakemake lists them: the --configfile files, else the Snakefile's configfile:
        CONFIG_SOURCE = ", ".join(
            map(str, snakemake_compat.user_config_files(workflow))
        ) or os.path.join("config", "config.yaml")
    EPA = epa_settings.resolve(
        epa_settings.without_bundled_folders(
            epa_settings.coerce_overrides(config, COMMAND_LINE_CONFIG),
            NAMED,
        ),
        source=CONFIG_SOURCE,
    )
    TRUTH, CASES = epa_discovery.discover_config(EPA, source=CONFIG_SOURCE)
    # the cases whose settings differ from the grid's (overrides, metric_scale: false)
    CASE_SETTINGS = epa_overrides.for_grid(EPA, CASES, source=CONFIG_SOURCE)
except EpaError as exc:
    raise WorkflowError(f"epa: error: {exc.one_line()}") from None
EPA_VERSION = epa.__version__
RESULTS = EPA["results_dir"]
CASE_BY_KEY = {c.key: c for c in CASES}
BATCHES = epa_jobs.batches(sorted(CASE_BY_KEY), EPA["grid"]["max_batches"])


wildcard_constraints:
    batch=".+",


# onstart runs in the main process only, after the DAG, never in a dry run, a cluster job or a
# module (there the host's runs). The command line goes to provenance.json only (an environment
# variable, not a parameter, so a new command line re-runs nothing). A cluster run: before
# anything is submitted, the job-state query the slurm executor will rely on must answer, and some
# node must have the CPUs a submission asks for (else the run waits forever).
onstart:
    os.environ[epa_provenance.COMMAND_ENV] = shlex.join(
        ["snakemake", *sys.argv[1:]]
    )
    executor_name, executor_settings = snakemake_compat.executor(workflow)
    if executor_name == "slurm":
        problem = epa_cluster.status_query_problem(
            getattr(executor_settings, "status_command", None),
            getattr(executor_settings, "init_seconds_before_status_checks", None),
        ) or epa_cluster.cores_problem(given_cores())
        if problem:
            raise WorkflowError(f"epa: error: {problem}")


def manifest(stage):
    """A stage job's declared output: which cases of its batch succeeded (artifacts are per case)."""
    return f"{RESULTS}/batches/{{batch}}/{stage}.json"


def batch_log(stage):
    return f"{RESULTS}/batches/{{batch}}/logs/{stage}.log"


def stage_job(params, input, output, log, wildcards):
    """The arguments of a stage job's body, epa.workflow.jobs.run_job. params.stage, not the rule
    loop's variable: the loop has moved on when the job runs."""
    return dict(
        stage=params.stage,
        cases=params.cases,
        results_dir=RESULTS,
        cfg=params.settings,
        manifest=output.manifest,
        upstream_manifest=input.get("upstream"),
        log_path=log[0],
        workers=workers(),
        timing_path=batch_timing(params.stage, wildcards.batch),
    )


def batch_timing(stage, batch):
    """Where a stage job writes its wall and CPU seconds (a benchmark file; see rules/stages.smk)."""
    return f"{RESULTS}/batches/{batch}/benchmarks/{stage}.tsv"


def batch_sources(batch):
    """The user's files a load job reads. One that does not exist (a dangling link) is left out, so
    its case fails with "file not found" instead of stopping the whole grid; so is one whose path has
    braces, which Snakemake cannot take literally (it is still read; an edit to it is not noticed).
    """
    paths = {
        str(f)
        for k in BATCHES[batch]
        for p in (CASE_BY_KEY[k].truth, CASE_BY_KEY[k].estimate)
        for f in epa_bags.bag_files(p)  # a ROS 2 bag folder: its files
    }
    paths |= {p for k in BATCHES[batch] if (p := timing_of(CASE_BY_KEY[k]))}
    return sorted(
        p for p in paths if os.path.exists(p) and "{" not in p and "}" not in p
    )


def timing_of(c):
    """A run's timing file (an edit re-runs its case); a configured one that is missing is the case's error."""
    try:
        path = epa_readers.timing_file(c.estimate, epa_discovery.sources_of(EPA, c)[1])
    except EpaError:
        return None
    return None if path is None else str(path)


def load_case(c):
    """What the load stage needs of one case: its files, each side's source settings, and the
    case's own settings where it has some (recorded in its load.json)."""
    truth_source, estimate_source = epa_discovery.sources_of(EPA, c)
    out = {
        "key": c.key,
        "truth": str(c.truth),
        "estimate": str(c.estimate),
        "truth_source": truth_source,
        "estimate_source": estimate_source,
    }
    own = CASE_SETTINGS.get(c.key)
    if own is not None:
        out["settings_record"] = own.record()
        out["settings"] = own.for_stage(epa_chain.sections_for("load"))
    return out


def stage_case(key, stage):
    """What a later stage needs of one case: its key, and the sections of its own settings that
    the stage reads (so an override re-runs only the batches of the cases it matches).
    """
    own = CASE_SETTINGS.get(key)
    changed = own.for_stage(epa_chain.sections_for(stage)) if own is not None else None
    return {"key": key, "settings": changed} if changed else {"key": key}


def stage_params(stage):
    """Everything a stage's result depends on, so a change re-runs exactly what it affects."""
    if (
        stage == "load"
    ):  # only load reads the user's files: a moved file or a source's settings re-run load onward
        cases = lambda wc: [load_case(CASE_BY_KEY[k]) for k in BATCHES[wc.batch]]
    else:
        cases = lambda wc: [stage_case(k, stage) for k in BATCHES[wc.batch]]
    return {
        "cases": cases,
        "settings": epa_chain.settings_for(stage, EPA),
        "version": EPA_VERSION,
    }


def stage_input(stage):
    """A stage job's input: the user's files for load, the previous stage's manifest for the others."""
    before = epa_chain.previous(stage)
    if before is None:
        return {"sources": lambda wc: batch_sources(wc.batch)}
    return {"upstream": manifest(before)}


# A stage job's scheduling data: one core; memory and run time grow with the batch.
STAGE_RESOURCES = {
    "mem_mb": lambda wc: 1000 + 20 * len(BATCHES[wc.batch]),
    "runtime": lambda wc: 2 + len(BATCHES[wc.batch]) // 20,
}


# Inside a cluster job (a `--mode remote` Snakemake; with the slurm executor, the job-step process
# that runs a submission's jobs) every job of the submission runs in this process, in threads, as a
# local rule, instead of each under `srun` in a Snakemake of its own: one interpreter per submission.
# The slurm executor starts it with --jobs 1; as many jobs as the job has CPUs run side by side (they
# share the worker pool). No effect where the remote process's executor is local. docs/cluster.md.
if snakemake_compat.in_cluster_job(workflow):
    snakemake_compat.run_here(
        workflow,
        [*epa_chain.NAMES, "tables", "provenance", "figures", "paper"],
        epa_cluster.usable_cpus(),
    )


def write_provenance(params, output, log):
    """The provenance rule's body: provenance.json and config.resolved.yaml, then its log. Its
    wall and CPU seconds go to results/benchmarks/provenance.tsv (no benchmark directive: that
    samples the memory of Snakemake's whole process tree, the workers' too)."""
    with epa_jobs.timed(f"{RESULTS}/benchmarks/provenance.tsv"):
        written = epa_provenance.write(
            os.path.dirname(output.provenance),
            epa_provenance.document(
                "grid", params.resolved, params.inputs, workflow_dir=params.workflow_dir
            ),
        )
        epa_files.write_text(log[0], "".join(f"wrote {path}\n" for path in written))


def grid_script(script, threads, **kwargs):
    """A once-per-grid rule's body: scripts/<script>.py's write(**kwargs) in a worker of the pool
    (epa.workflow.jobs.run_script), with ``workers`` (the script's own forked processes) up to the
    rule's threads; in this process's thread (one core, a cluster job's single CPU) it forks none,
    as this process has threads. Its wall and CPU seconds go to results/benchmarks/<script>.tsv.
    """
    n = workers()
    if "workers" in kwargs:
        kwargs["workers"] = min(threads, n) if n > 1 else 1
    epa_jobs.run_script(
        os.path.join(EPICA_DIR, "scripts", f"{script}.py"),
        "write",
        kwargs,
        workers=n,
        timing_path=f"{RESULTS}/benchmarks/{script}.tsv",
    )


def idle_truths():
    """mode ov_eval: the references no case uses (ov_eval lists every reference of the folder)."""
    if EPA["mode"] != "ov_eval":
        return {}
    used = {c.dataset for c in CASES}
    return {ds: str(path) for ds, path in sorted(TRUTH.items()) if ds not in used}


def quick_exit():
    """Let the process end as soon as the run has: about 1.6 s of every run (docs/performance.md).
    The scheduler's last rate-limiter timer would keep the process up to 1 s more
    (snakemake_compat.scheduler_timers), and the garbage collector's pass over everything Snakemake
    built (0.6 s on the example) only delays the exit: nothing after this needs it. onsuccess and
    onerror run in the main workflow only: a host workflow's process is never touched.
    """
    import gc

    epa_jobs.close_pool()
    for timer in snakemake_compat.scheduler_timers():
        timer.cancel()
    gc.freeze()
