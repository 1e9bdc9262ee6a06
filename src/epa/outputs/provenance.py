"""Provenance of a results folder (``provenance.json`` and ``config.resolved.yaml``): what made it.

Everything but the ``volatile`` section is a function of the inputs, the resolved config, the
checkout and the installed environment: two runs on the same machine with the same inputs write the
same bytes outside ``volatile``. ``volatile`` holds what must vary from run to run: the time, the
command line, the host, the working directory (the folder relative input paths are read from) and
the workflow's folder. No table, ``summary.csv`` or case artifact ever holds any of it.
See docs/reproducibility.md.
"""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import json
import math
import os
import platform
import re
import shlex
import stat
import subprocess
import sys
import threading
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from importlib.machinery import PathFinder
from pathlib import Path
from typing import Any

from epa import __version__
from epa.core import runtime

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
    "pyarrow",
    "snakemake",
)
VOLATILE = ("created_utc", "command_line", "host", "workdir", "workflow_dir")
# the environment variables that change which code paths the numbers run on (docs/reproducibility.md)
NUMERIC_ENV = (
    "NPY_DISABLE_CPU_FEATURES",
    "NPY_ENABLE_CPU_FEATURES",
    "OPENBLAS_CORETYPE",
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
)
UNKNOWN = "unknown"  # what could not be read here (no /proc/self/maps, not an OpenBLAS)
COMMAND_ENV = "EPA_COMMAND_LINE"  # the Snakefile puts Snakemake's command line here for the script


def sha256(path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def file_record(path, roots: dict[str, str] | None = None) -> dict:
    """An input file as recorded: its path (as the config gives it), the config folder it came from
    and its path relative to that folder (so that it can be found again under a new root), its size
    and sha256; or missing."""
    place = {"path": str(path), **where(path, roots or {})}
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):  # a device or a FIFO is never read here
            return {**place, "missing": True, "not_a_file": True}
        # a dataset's reference is an input of each of its cases: hashed once per version of it
        # (ctime too: a copy that keeps mtime and size, `cp -p`, cannot set it back)
        key = (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_ctime_ns, st.st_size)
        digest = _HASHED.get(key)
        if digest is None:
            digest = _HASHED[key] = sha256(path)
            while len(_HASHED) > HASHED_MAX:  # (pop: jobs in threads of one process may race)
                _HASHED.pop(next(iter(_HASHED), None), None)
        return {**place, "size": st.st_size, "sha256": digest}
    except (OSError, ValueError):
        return {**place, "missing": True}


# (device, inode, mtime, ctime, size) -> sha256 of a file_record's file (as the parsed-file cache's key)
_HASHED: dict = runtime.register("outputs.provenance.hashed", {})
HASHED_MAX = 4096


def where(path, roots: dict[str, str]) -> dict:
    """``{"folder": key, "relative": path within it}`` for the first of ``roots`` (a config key: its
    folder) that holds ``path`` as written (no ``..``); ``{}`` for none."""
    norm = os.path.normpath(str(path))
    for key, root in roots.items():
        base = os.path.normpath(str(root))
        relative = (
            os.path.relpath(norm, base) if os.path.isabs(norm) == os.path.isabs(base) else ".."
        )
        if relative != "." and not relative.startswith(".."):
            return {"folder": key, "relative": Path(relative).as_posix()}
    return {}


def input_roots(kind: str | None, cfg: dict, case: dict | None = None) -> dict[str, str]:
    """The folders a record's inputs are relative to: a grid's ``truth_dir`` and ``algorithms_dir``;
    a case's reference and estimate folders."""
    if kind == "case" and case:
        return {
            "estimate": os.path.dirname(str(case["estimate"])) or ".",
            "reference": os.path.dirname(str(case["reference"])) or ".",
        }
    if (cfg.get("inputs") or {}).get("estimate"):
        return pattern_roots(cfg["inputs"])
    return {k: str(cfg[k]) for k in ("truth_dir", "algorithms_dir") if cfg.get(k)}


def pattern_texts(inputs: dict) -> list[str]:
    """Every path pattern of an ``inputs`` section (``~`` expanded, as discovery reads them)."""
    texts: list[str] = []
    for key in ("reference", "estimate"):
        value = inputs.get(key) or []
        value = [value] if isinstance(value, str) else value
        texts += list(value.values()) if isinstance(value, dict) else value
    return [os.path.expanduser(t) for t in texts]


def pattern_root(text: str) -> str:
    """The folder a pattern's first wildcard is in (``.``: the working directory)."""
    return os.path.normpath(os.path.dirname(text.split("{", 1)[0]) or ".")


def pattern_roots(inputs: dict) -> dict[str, str]:
    """The folders a patterns grid's inputs are relative to: each pattern's root, those inside
    another dropped, named ``root0``, ``root1``, ... in the order of their paths."""
    roots: list[str] = []
    for root in sorted({pattern_root(t) for t in pattern_texts(inputs)}, key=len):
        if not any(where(root + "/x", {"r": outer}) for outer in roots):
            roots.append(root)
    return {f"root{k}": root for k, root in enumerate(sorted(roots))}


def case_inputs(truth, estimate, timing=None) -> list[str]:
    """The files one case reads: each side's file or a ROS 2 bag folder's files, and a timing file."""
    from epa.readers.detect import bag_files

    paths: set[str] = set()
    for p in (truth, estimate):
        try:
            paths.update(str(f) for f in bag_files(p))
        except OSError:  # a name the system refuses: recorded as given (and missing)
            paths.add(str(p))
    if timing:
        paths.add(str(timing))
    return sorted(paths)


def run_timing(cfg: dict, estimate, algorithm: str | None, source: dict | None = None):
    """A run's timing file under ``cfg`` or its own source settings ``source`` (a sheet's row);
    None when it has none or its configured one is missing."""
    from epa import readers
    from epa.core.errors import EpaError

    try:
        opts = source or readers.options(cfg, "estimate", algorithm=algorithm)
        return readers.timing_file(estimate, opts)
    except (EpaError, OSError):
        return None


def grid_inputs(cfg: dict, cases, idle_truths: dict | None = None) -> list[str]:
    """Every file a grid reads: its cases' references, runs, timing files, bag files, and (mode
    ov_eval) the references no run uses."""
    paths: set[str] = set()
    for c in cases:
        timing = run_timing(cfg, c.estimate, c.algorithm, c.estimate_source)
        paths.update(case_inputs(c.truth, c.estimate, timing))
    paths.update(str(p) for p in (idle_truths or {}).values())
    return sorted(paths)


def _run(argv, timeout: float = 20) -> str | None:
    """A command's output, or None when it cannot run or fails."""
    return _output(_start(argv), timeout)


def _start(argv) -> subprocess.Popen | None:
    """A command started (its output read by _output), or None when it cannot run."""
    try:
        return subprocess.Popen(
            argv,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            stdin=subprocess.DEVNULL,
            text=True,
        )
    except (OSError, subprocess.SubprocessError):
        return None


def _output(proc: subprocess.Popen | None, timeout: float = 20) -> str | None:
    """A started command's output, or None when it could not run, fails or times out."""
    if proc is None:
        return None
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.SubprocessError:
        proc.kill()
        proc.communicate()
        return None
    return out.strip() if proc.returncode == 0 else None


def _git(folder, *args) -> subprocess.Popen | None:
    return _start(["git", "-C", str(folder), *args])


def is_checkout(folder) -> bool:
    """Whether ``folder`` is laid out as epica's own checkout: the Snakefile, pyproject.toml and
    the package under src/."""
    folder = Path(folder)
    return all(
        (folder / name).is_file() for name in ("Snakefile", "pyproject.toml", "src/epa/__init__.py")
    )


def source_checkout() -> Path | None:
    """The checkout the running epica comes from (an editable install, or ``src`` on the path);
    None for an installed package (site-packages), whatever repository encloses it."""
    package = Path(__file__).resolve().parents[1]  # <checkout>/src/epa
    root = package.parents[1]
    return root if package.parent.name == "src" and is_checkout(root) else None


def checkout(folder) -> dict:
    """The workflow's git commit (and whether tracked files differ) when ``folder`` is epica's
    checkout and the root of its git repository; nothing for a folder inside another repository
    (a project's ``.venv``), whose commit is not epica's."""
    return checkout_started(folder)()


def checkout_started(folder) -> Callable[[], dict]:
    """:func:`checkout` as two steps: its git commands start now and their output is read when the
    returned function is called (meanwhile the rest of a record is made). A folder with its own
    ``.git`` runs both commands at once; another runs ``git status`` only if it is the root after
    all (never a status of a large enclosing repository)."""
    if folder is None or not is_checkout(folder):
        return dict
    head = _git(folder, "rev-parse", "--show-toplevel", "HEAD")
    status_args = ("status", "--porcelain", "--untracked-files=no")
    status = _git(folder, *status_args) if (Path(folder) / ".git").exists() else None

    def finish() -> dict:
        lines = (_output(head) or "").splitlines()
        if len(lines) != 2 or Path(lines[0]).resolve() != Path(folder).resolve():
            if status is not None:
                _output(status)
            return {}
        dirty = _output(status if status is not None else _git(folder, *status_args))
        return {"git_commit": lines[1], "git_dirty": bool(dirty)}

    return finish


def environment() -> dict:
    """Python, every runtime dependency's version, the platform and what the numbers ran on
    (deterministic on one machine with one environment)."""
    return {
        "python": {
            "version": platform.python_version(),
            "implementation": platform.python_implementation(),
        },
        "packages": versions(RUNTIME_PACKAGES),
        "platform": {
            "system": platform.system(),
            "release": platform.release(),
            "machine": platform.machine(),
            "platform": platform.platform(),
        },
        "numerics": numerics(),
    }


def versions(names) -> dict[str, str | None]:
    """Each distribution's version as ``importlib.metadata.version`` gives it (None: not installed).
    The plain case (only the path finder lists distributions; the first ``sys.path`` folder holding
    the name holds one ``<name>-<version>.dist-info`` whose METADATA has one unfolded Version line)
    is read directly: importlib.metadata's import (the email package) and its eight searches of
    every path folder were 15-25 ms of every ``epa eval``. Anything else is asked of it."""
    found: dict[str, str | None] = {}
    if all(f is PathFinder or not hasattr(f, "find_distributions") for f in sys.meta_path):
        found.update(_dist_info_versions(names))
    for name in names:
        if name not in found:
            import importlib.metadata

            try:
                found[name] = importlib.metadata.version(name)
            except importlib.metadata.PackageNotFoundError:
                found[name] = None
    return {name: found[name] for name in names}


def _dist_info_versions(names) -> dict[str, str]:
    """The versions of ``names`` read from their dist-info folders where that is plain (above)."""
    wanted: dict[str, list[str]] = {}
    for name in names:
        wanted.setdefault(re.sub(r"[-_.]+", "_", name).lower(), []).append(name)
    found: dict[str, str] = {}
    for entry in sys.path:
        if not wanted:
            break
        try:
            children = os.listdir(entry or ".")
        except OSError:
            if os.path.exists(entry or "."):  # a zip or an unreadable folder: not plain
                return found
            continue
        if entry.lower().endswith(".egg"):
            return found
        hits: dict[str, list[str]] = {}
        for child in children:
            low = child.lower()
            if low.endswith((".dist-info", ".egg-info")):
                key = re.sub(r"[-_.]+", "_", low.rpartition(".")[0].partition("-")[0])
                if key in wanted:
                    hits.setdefault(key, []).append(child)
        for key, folders in hits.items():
            same = wanted.pop(key)
            version = _metadata_version(os.path.join(entry, folders[0]))
            if len(folders) > 1 or not folders[0].lower().endswith(".dist-info") or not version:
                continue  # importlib.metadata decides
            found.update(dict.fromkeys(same, version))
    return found


def _metadata_version(folder: str) -> str | None:
    """The Version header of a dist-info folder's METADATA as email's compat32 parser reads it, when
    the header lines up to it are plain ``Name: value`` lines (None otherwise)."""
    try:
        with open(os.path.join(folder, "METADATA"), encoding="utf-8") as fh:
            head = [fh.readline() for _ in range(8)]
    except (OSError, ValueError):
        return None
    for k, line in enumerate(head[:-1]):
        if not _HEADER.match(line):
            return None
        if line.partition(":")[0].lower() == "version":
            if head[k + 1][:1] in (" ", "\t"):  # folded onto the next line
                return None
            return line.partition(":")[2].lstrip(" \t").rstrip("\r\n") or None
    return None


_HEADER = re.compile(r"[\x21-\x39\x3b-\x7e]+:")  # email.feedparser's header line, without "From "


def numerics() -> dict:
    """What the numbers ran on, so that a difference between two machines can be explained: the
    CPU, the SIMD targets numpy dispatched to, numpy's BLAS/LAPACK and the OpenBLAS core type and
    threads it runs with, the FFT, and the environment variables that steer them. 1.6-2.1 ms
    measured with numpy loaded (which loads ctypes): no other import, no library loaded."""
    import numpy

    build = numpy.show_config(mode="dicts").get("Build Dependencies", {})
    blas, lapack = build.get("blas", {}), build.get("lapack", {})
    runtime = _openblas(blas)
    blas_record = {**_library(blas), **runtime}
    lapack_record = _library(lapack)
    if lapack.get("name") == blas.get("name"):  # numpy's LAPACK is its BLAS library's
        lapack_record.update(runtime)
    return {
        "cpu": {"model": _cpu_model(), "machine": platform.machine()},
        "simd": _simd(),
        "blas": blas_record,
        "lapack": lapack_record,
        # epica's FFT (Step 1's cross-correlation) is numpy.fft: pocketfft, compiled into numpy
        "fft": {"library": "numpy.fft", "backend": "pocketfft", "numpy": numpy.__version__},
        # scipy's own OpenBLAS as built: epica calls no scipy BLAS routine (scipy.special and
        # scipy.stats only), and it is loaded only once they are, so its core is not probed
        "scipy_blas": _library(_scipy_build().get("blas", {})),
        "env": {name: os.environ.get(name) for name in NUMERIC_ENV},
    }


def _cpu_model() -> str:
    """The first "model name" of /proc/cpuinfo (Linux), the CPU brand string (macOS), else
    ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() == "model name":
                    return value.strip()
    except OSError:
        pass
    if sys.platform == "darwin":
        brand = _run(["sysctl", "-n", "machdep.cpu.brand_string"], timeout=5)
        if brand:
            return brand
    return platform.processor() or UNKNOWN


def _simd() -> dict:
    """numpy's SIMD: the baseline it was compiled for and the dispatch targets it found on this CPU
    (``numpy.show_runtime()``'s found and not found); NPY_DISABLE_CPU_FEATURES turns targets off."""
    try:  # by name: the module moved between numpy 1 and 2, and neither has a stub
        umath = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:  # numpy 1.26
        umath = importlib.import_module("numpy.core._multiarray_umath")
    dispatch, features = umath.__cpu_dispatch__, umath.__cpu_features__
    return {
        "baseline": list(umath.__cpu_baseline__),
        "dispatched": [f for f in dispatch if features.get(f)],
        "not_found": [f for f in dispatch if not features.get(f)],
    }


def _library(build: Mapping[str, Any]) -> dict:
    """A BLAS or LAPACK as numpy or scipy was built with it: its name and version."""
    return {"name": build.get("name"), "version": build.get("version")}


def _scipy_build() -> dict:
    """scipy's build dependencies from its generated ``__config__.py``, without importing scipy
    (8 ms, and then scipy is imported in every process that writes a record)."""
    module = sys.modules.get("scipy.__config__")
    if module is None:
        try:
            spec = importlib.util.find_spec("scipy")
            origin = spec and spec.submodule_search_locations
            if not origin:
                return {}
            path = Path(list(origin)[0]) / "__config__.py"
            config = importlib.util.spec_from_file_location("_epa_scipy_config", path)
            if config is None or config.loader is None:  # not a file Python can load
                return {}
            module = importlib.util.module_from_spec(config)
            config.loader.exec_module(module)
        except Exception:  # another layout of scipy's: its BLAS is then not recorded
            return {}
    return module.CONFIG.get("Build Dependencies", {})


def _openblas(build: Mapping[str, Any]) -> dict:
    """The core type, thread count and configuration numpy's OpenBLAS runs with (chosen at load time
    from the CPU and OPENBLAS_CORETYPE), read through ctypes from the library already loaded:
    /proc/self/maps lists it; its symbols are numpy's build's family (scipy-openblas64: the
    ``scipy_`` prefix and ``64_`` suffix), so scipy's own copy, loaded or not, is never read.
    "unknown" without /proc/self/maps (macOS) or an OpenBLAS."""
    unknown = {"core": UNKNOWN, "threads": UNKNOWN, "config": UNKNOWN}
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            paths = sorted(
                {
                    fields[5].strip()
                    for fields in (line.split(maxsplit=5) for line in fh)
                    if len(fields) == 6 and "openblas" in fields[5].lower()
                }
            )
    except OSError:
        return unknown
    import ctypes

    handles = []
    for path in paths:
        try:  # RTLD_NOLOAD: a handle to a library already there, never a new one
            handles.append(ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_NOW | os.RTLD_LOCAL))
        except (OSError, AttributeError):
            continue
    scipy_built = str(build.get("name", "")).startswith("scipy-openblas")
    ilp64 = "USE64BITINT" in str(build.get("openblas configuration", ""))
    prefixes = ("scipy_", "") if scipy_built else ("", "scipy_")
    suffixes = ("64_", "64", "") if ilp64 else ("", "64_", "64")
    for prefix in prefixes:
        for suffix in suffixes:
            for handle in handles:
                try:
                    corename = getattr(handle, f"{prefix}openblas_get_corename{suffix}")
                    config = getattr(handle, f"{prefix}openblas_get_config{suffix}")
                    threads = getattr(handle, f"{prefix}openblas_get_num_threads{suffix}")
                except AttributeError:
                    continue
                corename.restype = config.restype = ctypes.c_char_p
                threads.restype = ctypes.c_int
                return {
                    "core": corename().decode(errors="replace"),
                    "threads": threads(),
                    "config": config().decode(errors="replace").strip(),
                }
    return unknown


def config_yaml(cfg: dict) -> str:
    """The resolved config as YAML (every setting, defaults included; keys in the schema's order)."""
    head = (
        "# Every setting of this run, defaults included (epica resolved them). Regenerate with\n"
        "# `epa verify RESULTS_DIR` or `snakemake --cores 2 --configfile config.resolved.yaml`.\n"
    )
    data = json.loads(json.dumps(cfg))
    text = _plain_yaml(data)
    if text is None:
        import yaml

        text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)
    return head + text


# A string PyYAML writes unquoted, in the few forms a config's names and paths take: no spaces,
# quotes, colons or other indicators, not read back as another type (a number, a date, a YAML 1.1
# boolean or null word, .inf; "..." ends a document), so never folded at the line width or quoted.
_PLAIN = re.compile(r"[A-Za-z/_][A-Za-z0-9_./-]*|\.(?:[A-Za-z/.][A-Za-z0-9_./-]*)?")
_WORDS = {"y", "n", "yes", "no", "true", "false", "on", "off", "null", "nan", "inf", ".nan", ".inf"}


def _plain_yaml(data) -> str | None:
    """``yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)`` for a mapping of
    mappings, lists of scalars and scalars whose strings are ``_PLAIN``, without importing PyYAML
    (about 20 ms of every ``epa eval``); None for anything else (PyYAML writes that).
    tests/test_provenance.py compares the two on the configs and on random documents."""

    def scalar(v) -> str | None:
        if v is None:
            return "null"
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int):
            return str(v)
        if isinstance(v, float):
            if v != v or v in (math.inf, -math.inf):
                return None
            text = repr(v).lower()
            return text.replace("e", ".0e", 1) if "." not in text and "e" in text else text
        if (
            isinstance(v, str)
            and _PLAIN.fullmatch(v)
            and v.lower() not in _WORDS
            and v[:3] != "..."
        ):
            return v
        return None

    lines: list[str] = []

    def mapping(node: dict, indent: str) -> bool:
        for key, value in node.items():
            name = scalar(key) if isinstance(key, str) and len(key) < 100 else None
            if name is None:
                return False
            if isinstance(value, dict) and value:
                lines.append(f"{indent}{name}:")
                if not mapping(value, indent + "  "):
                    return False
            elif isinstance(value, list) and value:
                lines.append(f"{indent}{name}:")
                items = [scalar(v) for v in value]
                if None in items:
                    return False
                lines.extend(f"{indent}- {item}" for item in items)
            else:
                text = "{}" if value == {} else "[]" if value == [] else scalar(value)
                if text is None:
                    return False
                lines.append(f"{indent}{name}: {text}")
        return True

    if not isinstance(data, dict) or not data or not mapping(data, ""):
        return None
    return "\n".join(lines) + "\n"


def document(kind: str, cfg: dict, inputs, **options) -> dict:
    """The provenance record: ``kind`` is ``grid`` (a workflow's results) or ``case`` (``epa eval``);
    ``options``: those of :func:`document_started`."""
    return document_started(kind, cfg, inputs, **options)()


def document_started(
    kind: str,
    cfg: dict,
    inputs,
    *,
    workflow_dir=None,
    command_line: str | None = None,
    workdir=None,
    extra: dict | None = None,
) -> Callable[[], dict]:
    """:func:`document` in two steps: the environment is read and the inputs hashed in a thread
    (waiting for ``uname -p``, which ``platform.platform()`` runs, reading files and hashing
    release the GIL: 20-40 ms of ``epa eval``) and git runs while the caller goes on (``epa eval``:
    loading the inputs); the returned function waits for them and gives the record, the same as
    :func:`document`'s (the config as it is now, the time now)."""
    roots = input_roots(kind, cfg, (extra or {}).get("case"))
    paths = sorted(set(map(str, inputs)))
    found: dict[str, Any] = {}
    failed: list[BaseException] = []

    def read() -> None:
        try:
            git = checkout_started(workflow_dir)  # (starting git here spares the caller 5-10 ms)
            found["env"] = environment()
            found["inputs"] = [file_record(p, roots) for p in paths]
            found["git"] = git()
        except BaseException as exc:  # raised in the caller's thread, by finish
            failed.append(exc)

    reading = threading.Thread(target=read, name="epa-provenance", daemon=True)
    reading.start()
    extra, cfg = copy.deepcopy(extra or {}), copy.deepcopy(cfg)
    volatile = {
        "created_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command_line": command_line
        or os.environ.get(COMMAND_ENV)
        or shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "host": _host(),
        "workdir": str(Path(workdir or os.getcwd()).resolve()),
        "workflow_dir": None if workflow_dir is None else str(Path(workflow_dir).resolve()),
    }

    def finish() -> dict:
        reading.join()
        if failed:
            raise failed[0]
        return {
            "format": FORMAT,
            "kind": kind,
            "epica": {"version": __version__, **found["git"]},
            **found["env"],
            **extra,
            "config": cfg,
            "config_file": CONFIG,
            "inputs": found["inputs"],
            "volatile": volatile,
        }

    return finish


def _host() -> str:
    """``socket.gethostname()``: on a POSIX system the kernel's node name, which ``os.uname`` reads
    without importing socket."""
    if hasattr(os, "uname"):
        return os.uname().nodename
    import socket

    return socket.gethostname()


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
