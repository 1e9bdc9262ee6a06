"""Running one stage over a batch of cases: what a workflow job does (see docs/performance.md).

- Batching: up to ``grid.max_batches`` cases, each case is its own batch; beyond, cases are spread
  over ``max_batches`` batches by a stable hash of their name, so the job count stays bounded and an
  added case changes one batch.
- Isolation: a user mistake or a bug in one case is that case's recorded failure (markers in its
  artifacts, the traceback in its log); the batch's other cases go on. A stage that failed upstream
  passes the reason on. The batch's manifest (the job's only declared output) records each case.
- Parallelism: a job's work runs in a pool of worker processes that live as long as the Snakemake
  process (numpy and epa imported once per worker, never once per job); one core runs it in the
  calling thread.

No snakemake import here: the rules call :func:`run_job` with plain values.
"""

from __future__ import annotations

import ast
import logging
import re
import sys
import threading
import time
import traceback
import warnings
import zlib
from contextlib import contextmanager
from multiprocessing import context
from pathlib import Path
from typing import Any

from epa.artifacts import files
from epa.artifacts.case import Case, CaseFolder
from epa.core import runtime
from epa.core.errors import EpaError
from epa.readers import text
from epa.workflow import chain, overrides

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- batches
def batches(keys: list[str], max_batches: int) -> dict[str, list[str]]:
    """Batch id -> case keys. A case is its own batch (id = its key, made safe for a Snakemake path
    pattern) while the grid is small."""
    if len(keys) <= max_batches:
        return {_batch_id(key): [key] for key in keys}
    out: dict[str, list[str]] = {}
    for key in keys:
        out.setdefault(f"batch{zlib.crc32(key.encode()) % max_batches:04d}", []).append(key)
    return dict(sorted(out.items()))


def _batch_id(key: str) -> str:
    """The case key, unless it holds characters Snakemake would read as a pattern ({ }) or that a
    shell or a cluster would trip on; then a readable stand-in with a hash of the key."""
    safe = re.sub(r"[^A-Za-z0-9._/+-]", "_", key)
    return key if safe == key else f"{safe}~{zlib.crc32(key.encode()):08x}"


# ----------------------------------------------------------------------------- per-case logs
class _ThreadFileHandler(logging.Handler):
    """Sends each record to the log file of the case the current thread is working on."""

    def __init__(self):
        super().__init__()
        self.local = threading.local()
        self.setFormatter(logging.Formatter("%(levelname)s %(message)s"))

    def emit(self, record):
        fh = getattr(self.local, "fh", None)
        if fh is not None:
            fh.write(self.format(record) + "\n")


_HANDLER = _ThreadFileHandler()


_INSIDE: dict[str, Any] = {"n": 0, "saved": None}  # saved: [(logger, propagate, level)]
_INSIDE_LOCK = threading.Lock()


def _reset_logging() -> None:
    """Leave every case log still open: the logging setup from before the first is restored."""
    while _INSIDE["n"] > 0:
        _leave_logging()


runtime.register("workflow.jobs.inside", reset=_reset_logging)


def _enter_logging() -> None:
    """While any thread is inside a case log, epa's records and Python warnings go to the case logs
    only (not the terminal); the previous logging setup is restored when the last one leaves."""
    with _INSIDE_LOCK:
        _INSIDE["n"] += 1
        if _INSIDE["n"] > 1:
            return
        loggers = [logging.getLogger(name) for name in ("epa", "py.warnings")]
        _INSIDE["saved"] = [(lg, lg.propagate, lg.level) for lg in loggers]
        for lg in loggers:
            lg.addHandler(_HANDLER)
            lg.propagate = False
        loggers[0].setLevel(logging.INFO)
        logging.captureWarnings(True)


def _leave_logging() -> None:
    with _INSIDE_LOCK:
        _INSIDE["n"] -= 1
        if _INSIDE["n"] > 0:
            return
        for lg, propagate, level in _INSIDE["saved"]:
            lg.removeHandler(_HANDLER)
            lg.propagate, lg.level = propagate, level
        logging.captureWarnings(False)


@contextmanager
def case_log(path):
    """Log records of this thread go to ``path`` (replaced) while inside."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        _enter_logging()
        _HANDLER.local.fh = fh
        try:
            yield
        finally:
            _HANDLER.local.fh = None
            _leave_logging()


# ----------------------------------------------------------------------------- one stage, many cases
def run_cases(
    stage: str, cases: list[dict], results_dir, cfg: dict, upstream: dict[str, str]
) -> dict[str, dict]:
    """Run ``stage`` on each case ({key, truth, estimate, truth_source, estimate_source}, and where
    the case has settings of its own: ``settings``, the sections of ``cfg`` it replaces, and for
    the load stage ``settings_record``, what it records of them); never raises for a case's
    failure. ``upstream``: key -> reason for cases whose previous stage failed. Returns key ->
    status."""
    status: dict[str, dict] = {}
    artifacts = chain.BY_NAME[stage].artifacts
    _enter_logging()  # once a batch: each case's own (case_log) is then a count (0.1 ms a case)
    try:
        for c in cases:
            _run_case(stage, c, results_dir, cfg, upstream, artifacts, status)
    finally:
        _leave_logging()
    return status


def _run_case(stage, c, results_dir, cfg, upstream, artifacts, status) -> None:
    """One case of :func:`run_cases`: its status into ``status``."""
    key = c["key"]
    inputs = ("truth", "estimate", "truth_source", "estimate_source", "settings_record")
    try:
        case = CaseFolder.of(results_dir, Case.from_key(key, **{k: c.get(k) for k in inputs}))
    except EpaError as exc:  # a name that is no plain name: this case fails, nothing is written
        status[key] = {"status": "failed", "reason": f"{stage}: {exc.one_line()}"}
        return
    reason = upstream.get(key)
    with case_log(case.log(stage)):
        stale = case.remove_temporaries(stage, artifacts)
        if stale:
            log.info("removed what a killed run left: %s", ", ".join(stale))
        if reason is not None:
            log.error("case failed upstream: %s", reason)
        else:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("always")  # every case logs its own warnings
                    case_cfg = overrides.case_config(cfg, c.get("settings"))
                    chain.run_stage(stage, chain.CaseData(case), case_cfg)
            except EpaError as exc:
                reason = f"{stage}: {exc.one_line()}"
                log.error("case failed: %s", reason)
            except Exception as exc:  # a bug: this case's failure, not the grid's
                reason = f"internal error: {type(exc).__name__}: {exc}".replace("\n", " ")
                log.error("%s", traceback.format_exc().rstrip())
                log.error("case failed: %s", reason)
    if reason is None:
        status[key] = {"status": "ok"}
    else:
        chain.write_failure(case, stage, reason)
        status[key] = {"status": "failed", "reason": reason}


def read_manifest(path) -> dict[str, dict]:
    return files.read_json(path)["cases"]


def upstream_failures(manifest_path) -> dict[str, str]:
    if manifest_path is None:
        return {}
    return {k: v["reason"] for k, v in read_manifest(manifest_path).items() if v["status"] != "ok"}


# ----------------------------------------------------------------------------- worker pool
_POOL = None
_POOL_LOCK = threading.Lock()


class EpaWorker(context.ForkServerProcess):
    """A pool worker."""

    def run(self):
        # pandas is preloaded in the forkserver (_context): pyarrow's reader (which pandas imports,
        # where installed) or its C parser reads every file here
        runtime.use_pandas_parser()
        text.use_arrow()  # preloaded in the forkserver too: every artifact from 32 KB on
        super().run()


class EpaContext(context.ForkServerContext):
    # forkserver: Snakemake's process has threads, which fork() must not copy
    Process = EpaWorker


def _context():
    ctx = EpaContext()
    # pandas: its C parser reads the artifacts (epa.artifacts.files); imported once here, and
    # pyarrow's reader, tried first where installed (a preload that is not installed is skipped)
    ctx.set_forkserver_preload(["epa.workflow.jobs", "pandas", "pyarrow.csv", *_main_imports()])
    return ctx


def _main_imports() -> list[str]:
    """The modules the parent's main script imports, for the fork server to import once.

    multiprocessing runs the parent's main script again in every worker it starts, so that
    functions defined there can be unpickled. Under the ``snakemake`` console script that script
    imports Snakemake's whole command line (1.3 s of CPU per worker). Imported once in the fork
    server, each worker forked from it runs the script's few remaining lines only. None where the
    main module was run as a module (``python -m snakemake``: multiprocessing leaves it alone)."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if path is None or getattr(main, "__spec__", None) is not None:
        return []
    try:
        tree = ast.parse(Path(path).read_bytes())
    except (OSError, SyntaxError, ValueError):  # not Python source (a frozen or binary launcher)
        return []
    names: list[str] = []
    for node in tree.body:  # the top level only: what running the script imports for certain
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.append(node.module)
    return names


def close_pool() -> None:
    """Let the workers go (they are idle once the run has ended)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is not None:
            _POOL.shutdown(wait=True)
            _POOL = None


runtime.register("workflow.jobs.pool", reset=close_pool)


def _pool(workers: int):
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or getattr(_POOL, "_broken", False):
            from concurrent.futures import ProcessPoolExecutor

            _POOL = ProcessPoolExecutor(
                max_workers=workers, mp_context=_context(), initializer=runtime.keep_freed_memory
            )
        return _POOL


def call(workers: int, fn, *args):
    if workers <= 1:
        return fn(*args)
    return _pool(workers).submit(fn, *args).result()


def _run_cases_timed(*args):
    """:func:`run_cases` and the CPU seconds it took in the process that ran it (a worker)."""
    t0 = time.process_time()
    out = run_cases(*args)
    return out, time.process_time() - t0


def run_job(
    stage: str,
    cases: list[dict],
    results_dir,
    cfg: dict,
    manifest,
    upstream_manifest=None,
    log_path=None,
    workers: int = 1,
    timing_path=None,
) -> dict[str, dict]:
    """One workflow job: ``stage`` for a batch of cases, then the batch manifest (written last,
    atomically, so a killed job leaves no manifest and is re-run). ``timing_path``: the job's wall
    and CPU seconds, as a Snakemake benchmark file (its ``s`` and ``cpu_time`` columns)."""
    from concurrent.futures.process import BrokenProcessPool

    wall0, cpu = time.perf_counter(), float("nan")
    for path in (manifest, log_path, timing_path):  # a killed job's temporaries of these
        if path is not None:
            files.remove_temporaries(Path(path).parent, [Path(path).name])
    upstream = upstream_failures(upstream_manifest)
    try:
        status, cpu = call(workers, _run_cases_timed, stage, cases, results_dir, cfg, upstream)
    except BrokenProcessPool:
        # a worker died (out of memory, a crash in C): retry case by case, record the one that dies
        status = {}
        for c in cases:
            try:
                status.update(call(workers, run_cases, stage, [c], results_dir, cfg, upstream))
            except BrokenProcessPool:
                reason = "internal error: the worker process died (out of memory or a crash)"
                run_cases(stage, [c], results_dir, cfg, {c["key"]: reason})
                status[c["key"]] = {"status": "failed", "reason": reason}
    failed = {k: v["reason"] for k, v in status.items() if v["status"] != "ok"}
    if log_path is not None:
        lines = [f"{stage}: {len(status) - len(failed)} ok, {len(failed)} failed"]
        lines += [f"failed {k}: {r}" for k, r in failed.items()]
        files.write_text(log_path, "\n".join(lines) + "\n")
    if timing_path is not None:
        write_timing(timing_path, time.perf_counter() - wall0, cpu)
    files.write_json(manifest, {"stage": stage, "cases": status})
    return status


# ----------------------------------------------------------------------------- once-per-grid scripts
def script_function(path, name: str):
    """``name`` of the script at ``path`` (scripts/tables.py, ...), imported once per process under
    a name of its own (never ``__main__``: its command line does not run)."""
    path = Path(path)
    module_name = f"epica_script_{path.stem}"
    module = sys.modules.get(module_name)
    if module is None:
        import importlib.util

        spec = importlib.util.spec_from_file_location(module_name, path)
        if spec is None or spec.loader is None:
            raise ImportError(f"cannot import {path}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[module_name]
            raise
    return getattr(module, name)


def write_timing(timing_path, wall: float, cpu: float) -> None:
    """A job's wall and CPU seconds as a Snakemake benchmark file (its ``s`` and ``cpu_time``)."""
    files.write_text(timing_path, f"s\tcpu_time\n{wall:.4f}\t{cpu:.4f}\n")


@contextmanager
def timed(timing_path):
    """The wall seconds of what runs inside and the CPU seconds of this thread, as a Snakemake
    benchmark file (its ``s`` and ``cpu_time`` columns), for a job that runs in the job's thread."""
    files.remove_temporaries(Path(timing_path).parent, [Path(timing_path).name])
    wall0, cpu0 = time.perf_counter(), time.thread_time()
    yield
    write_timing(timing_path, time.perf_counter() - wall0, time.thread_time() - cpu0)


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its children that have ended (a script's forked workers)."""
    import resource

    own, children = (
        resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
    )
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _run_script_timed(path: str, name: str, kwargs: dict):
    cpu0 = _cpu_seconds()
    out = script_function(path, name)(**kwargs)
    return out, _cpu_seconds() - cpu0


def run_script(path, name: str, kwargs: dict, workers: int = 1, timing_path=None):
    """A once-per-grid rule's body (tables, figures, paper): the script's function ``name`` called
    with ``kwargs`` in a worker of the pool, whose imports (numpy, pandas, pyarrow, epa's tables and
    figures, matplotlib where a report drew) are warm, instead of a new Python for each rule (0.3-0.9
    s of the serial tail each). With one worker it runs in the calling thread, where the CPU seconds
    of ``timing_path`` (wall and CPU, as a stage job's) are the whole process's."""
    wall0 = time.perf_counter()
    if timing_path is not None:
        files.remove_temporaries(Path(timing_path).parent, [Path(timing_path).name])
    out, cpu = call(workers, _run_script_timed, str(path), name, dict(kwargs))
    if timing_path is not None:
        write_timing(timing_path, time.perf_counter() - wall0, cpu)
    return out
