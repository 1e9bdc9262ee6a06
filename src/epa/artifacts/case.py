"""One case: its identity (:class:`Case`), its folder on disk (:class:`CaseFolder`: the paths, typed
readers and writers, failure markers) and the typed view of its artifacts that stages, reports and
tables share (:class:`CaseData`: each artifact read once, or taken from the stage that just made it).

A case folder is ``<results>/cases/<algorithm>/<dataset>/<run>/<NN_stage>/<file>``. A failed stage
writes a failure marker into each of its artifacts (JSON: ``{"status": "failed", "reason": ...}``;
text: a first line ``# epa-failed: <reason>``), so a file opened by hand says why.
"""

from __future__ import annotations

import json
import os
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from epa.artifacts import files
from epa.artifacts.stage import Value
from epa.artifacts.stage import folder as stage_folder
from epa.core import runtime
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory

FAILED_PREFIX = "# epa-failed: "
_ESCAPE = json.encoder.encode_basestring_ascii  # json.dumps' text of a str

# The types of the values the stages hand on
Record = dict[str, Any]  # a stage's JSON record
Columns = dict[str, np.ndarray]  # a CSV table's columns
Both = tuple[Trajectory, Trajectory]  # (reference, estimate)
Indices = tuple[np.ndarray, np.ndarray]  # (i_ref, i_est) of matched poses


@dataclass(frozen=True)
class Case:
    """A case's identity and inputs: the reference and estimate files and each side's source
    settings (:func:`epa.readers.options`; None: the ``load`` section's)."""

    algorithm: str
    dataset: str
    run: str
    truth: Path | None = None
    estimate: Path | None = None
    truth_source: dict | None = None
    estimate_source: dict | None = None
    # the case's own settings beside the grid's (epa.workflow.overrides.CaseSettings.record)
    settings_record: dict | None = None

    @property
    def key(self) -> str:
        return f"{self.algorithm}/{self.dataset}/{self.run}"

    @classmethod
    def from_key(cls, key: str, **inputs) -> Case:
        """A key is three plain names (discovery makes them from file names), so nothing built from
        it escapes the results folder."""
        parts = key.split("/")
        if len(parts) != 3 or any(not plain_name(p) for p in parts):
            raise EpaError(f"case {key!r} is not <algorithm>/<dataset>/<run> with plain names")
        algorithm, dataset, run = parts
        return cls(algorithm, dataset, run, **inputs)

    @classmethod
    def unchecked(cls, key: str) -> Case:
        """The identity of a key that may not be plain (its failure is marked under its own name;
        never used for a path)."""
        algorithm, dataset, run = (key.split("/", 2) + ["", ""])[:3]
        return cls(algorithm, dataset, run)


def plain_name(name: str) -> bool:
    """A name that is one path component everywhere (no ``/`` or ``\\``, not ``.`` or ``..``)."""
    return name not in ("", ".", "..") and "/" not in name and "\\" not in name


# ----------------------------------------------------------------------------- reading once
# Every case of a dataset holds the same reference. A worker writes it once and hard-links it into
# the other cases, and parses a file once per inode (an atomic rewrite makes a new inode, so a
# cached parse is never stale). Measured: this halves the workflow's cost on 200 Hz references.
class Kept(OrderedDict):
    """A least-recently-used cache (:func:`remember`) that knows the array bytes it holds."""

    def __init__(self):
        super().__init__()
        self.sizes: dict = {}

    def clear(self) -> None:
        super().clear()
        self.sizes.clear()


# (device, inode, mtime, size) -> Trajectory
_PARSED: Kept = runtime.register("artifacts.case.parsed", Kept())
# At least CACHE_MAX entries are kept (a few hundred MB at most for 200 Hz references); beyond, up
# to CACHE_MOST as long as they hold at most CACHE_BYTES: a large grid's batch visits each of its
# datasets in turn (10,000 cases: 100 datasets, a few hundred files between two cases of one), and
# with 64 entries every reference was read and parsed again by each stage (load, sync on).
CACHE_MAX = 64
CACHE_MOST = 1024
CACHE_BYTES = 128 << 20
# reference source -> the file this process wrote it to
_WRITTEN: dict = runtime.register("artifacts.case.written", {})


def remember(cache: OrderedDict, key, value):
    """Keep ``value`` in a least-recently-used ``cache``: CACHE_MAX entries, and more (see there) in
    a :class:`Kept`."""
    cache[key] = value
    cache.move_to_end(key)
    sizes = getattr(cache, "sizes", None)
    if sizes is None:
        while len(cache) > CACHE_MAX:
            cache.popitem(last=False)
        return value
    sizes[key] = nbytes(value)
    while len(cache) > CACHE_MAX and (len(cache) > CACHE_MOST or sum(sizes.values()) > CACHE_BYTES):
        sizes.pop(cache.popitem(last=False)[0], None)
    return value


def nbytes(value) -> int:
    """The bytes of the arrays in a cached value (a trajectory, a tuple holding some)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, (tuple, list)):
        return sum(nbytes(v) for v in value)
    if isinstance(value, Trajectory):
        return sum(
            nbytes(getattr(value, f))
            for f in ("t", "p", "q", "cov_rot", "cov_pos", "cov_ros", "r_printed")
        )
    return 0


def read_tum_cached(path) -> Trajectory:
    st = os.stat(path)
    key = (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size)
    if key in _PARSED:
        _PARSED.move_to_end(key)
        return _PARSED[key]
    return remember(_PARSED, key, files.read_tum_file(path))


def link(src, dst) -> bool:
    """Hard-link ``src`` to ``dst`` (replacing it); False where the file system cannot."""
    dst = Path(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name("." + dst.name + ".link")
    try:
        if tmp.exists():
            os.unlink(tmp)
        os.link(src, tmp)
        os.replace(tmp, dst)
        if os.path.lexists(tmp):  # dst was src already (a re-run): rename() then does nothing
            os.unlink(tmp)
        return True
    except OSError:
        return False


# ----------------------------------------------------------------------------- failure markers
def read_record(path) -> tuple[dict, str | None]:
    """A stage's JSON record and, if it is a failure marker, the recorded reason (read once)."""
    data = files.read_json(path)
    return data, (data.get("reason", "failed") if data.get("status") == "failed" else None)


def failure_of(path) -> str | None:
    """The recorded reason if this artifact is a failure marker, else None."""
    path = Path(path)
    if path.suffix == ".json":
        return read_record(path)[1]
    with open(path, encoding="utf-8", errors="replace") as fh:
        head = fh.read(4096)
    if head.startswith(FAILED_PREFIX):
        return head[len(FAILED_PREFIX) :].splitlines()[0]
    return None


# ----------------------------------------------------------------------------- the folder
class CaseFolder:
    """Paths of one case's artifacts, ``<root>/<NN_stage>/<file>``, and their typed I/O."""

    def __init__(self, root, case: Case | None = None):
        self.root = Path(root)
        self.case = case

    @classmethod
    def of(cls, results_dir, case: Case) -> CaseFolder:
        return cls(Path(results_dir) / "cases" / case.key, case)

    def path(self, stage: str, name: str) -> Path:
        return self.root / stage_folder(stage) / name

    def log(self, stage: str) -> Path:
        return self.root / "logs" / f"{stage}.log"

    def has(self, stage: str, name: str) -> bool:
        return self.path(stage, name).exists()

    # readers
    def record(self, stage: str, name: str) -> dict:
        return files.read_json(self.path(stage, name))

    def record_or_failure(self, stage: str, name: str) -> tuple[dict, str | None]:
        return read_record(self.path(stage, name))

    def tum(self, stage: str, name: str) -> Trajectory:
        return read_tum_cached(self.path(stage, name))

    def table(self, stage: str, name: str) -> dict:
        return files.read_csv(self.path(stage, name))

    def pairs(self, stage: str):
        """(i_ref, i_est) of ``<stage>/pairs.csv``."""
        return files.read_pair_indices(self.path(stage, "pairs.csv"))

    # writers: every file is written to a temporary name and renamed
    def write_record(self, stage: str, name: str, record: dict) -> None:
        files.write_json(self.path(stage, name), record)

    def write_tum(self, stage: str, name: str, traj: Trajectory) -> None:
        files.write_tum(self.path(stage, name), traj)

    def write_shared_tum(self, stage: str, name: str, traj: Trajectory, source) -> None:
        """A trajectory every case of a dataset shares: written once per process, then linked."""
        path = self.path(stage, name)
        prev = _WRITTEN.get(source)
        if source is not None and prev is not None and os.path.exists(prev) and link(prev, path):
            return
        files.write_tum(path, traj)
        _WRITTEN[source] = str(path)

    def write_table(self, stage: str, name: str, columns: dict) -> None:
        files.write_csv(self.path(stage, name), columns)

    def write_pairs(self, stage: str, i_ref, i_est, t_ref, t_est) -> None:
        files.write_pair_indices(self.path(stage, "pairs.csv"), i_ref, i_est, t_ref, t_est)

    def link(self, from_stage: str, name: str, to_stage: str) -> bool:
        """``to_stage``'s ``name`` is ``from_stage``'s (a stage that changes nothing links it)."""
        return link(self.path(from_stage, name), self.path(to_stage, name))

    def write_text(self, stage: str, name: str, text: str) -> None:
        files.write_text(self.path(stage, name), text)

    def write_optional_table(self, stage: str, name: str, columns: dict | None) -> None:
        """The table, or no file at all (and none left from a previous run) when there is none."""
        if columns:
            self.write_table(stage, name, columns)
        else:
            self.remove(stage, name)

    def remove(self, stage: str, name: str) -> None:
        """Remove an artifact a previous run left (one this run does not write)."""
        path = self.path(stage, name)
        if path.exists():
            os.unlink(path)

    def remove_folder(self, stage: str, name: str) -> None:
        """Remove a folder of artifacts a previous run left, with the files in it."""
        path = self.path(stage, name)
        if path.is_dir():
            for f in path.iterdir():
                os.unlink(f)
            path.rmdir()

    def remove_temporaries(self, stage: str, names) -> list[str]:
        """Remove the temporaries of the artifacts ``names`` a killed write left in the stage's
        folder (:func:`epa.artifacts.files.remove_temporaries`); returns their names."""
        return files.remove_temporaries(self.root / stage_folder(stage), names)

    def document(self, records) -> dict:
        """The records ``records`` ((stage, file name) pairs) of the case as one document, by stage
        name, those present (``epa eval``'s metrics.json, the per-case report's: the stages
        declaring a ``result``, :data:`epa.workflow.chain.DOCUMENT`)."""
        doc = {}
        for stage, name in records:
            path = self.path(stage, name)
            if path.exists():
                doc[stage] = files.read_json(path)
        return doc

    def document_text(self, records) -> tuple[dict, str]:
        """:meth:`document` and the text :func:`epa.artifacts.files.write_json` writes of it,
        composed of the records' texts (each written by write_json: its text is what write_json
        writes of it read back) instead of encoded again (a third of the report's JSON time)."""
        doc, parts = {}, []
        for stage, name in records:
            try:
                with open(self.path(stage, name), encoding="utf-8") as fh:
                    text = fh.read()
            except FileNotFoundError:
                continue
            doc[stage] = json.loads(text)
            # nested one level deeper: every newline of write_json's text is its layout's (a
            # string's own are escaped)
            parts.append(_ESCAPE(stage) + ": " + text.replace("\n", "\n  "))
        return doc, "{\n  " + ",\n  ".join(parts) + "\n}" if parts else "{}"

    def write_failure(self, stage: str, names, reason: str) -> None:
        for name in names:
            if name.endswith(".json"):
                self.write_record(stage, name, {"status": "failed", "reason": reason})
            else:
                files.write_text(self.path(stage, name), FAILED_PREFIX + reason + "\n")


# ----------------------------------------------------------------------------- the typed view
class CaseData:
    """What each stage produced for one case: the values the stages hand on
    (:class:`epa.artifacts.stage.Value`). ``epa eval`` runs every stage in one process and the
    values pass in memory; a workflow job runs one stage and the values it reads are read from the
    previous stages' artifacts, each at most once.

    The fields are those the stages declare: :func:`data_class` makes the class with them (the
    chain's is :data:`epa.workflow.chain.CaseData`), each annotated with its value's type. Reading
    or setting a name no stage declares is an AttributeError; so is reading, while
    :meth:`readable` limits it, a value the running stage does not declare it reads."""

    VALUES: ClassVar[dict[str, Value]] = {}
    # the (stage, record) pairs of the case's document (CaseFolder.document)
    DOCUMENT: ClassVar[tuple[tuple[str, str], ...]] = ()

    def __init__(self, folder: CaseFolder):
        object.__setattr__(self, "folder", folder)
        object.__setattr__(self, "_store", {})
        object.__setattr__(self, "_readable", None)

    folder: CaseFolder

    @property
    def f(self) -> CaseFolder:
        return self.folder

    def __getattr__(self, name: str) -> Any:  # only names not found otherwise: the values
        value = type(self).VALUES.get(name)
        if value is None or name.startswith("_"):
            raise AttributeError(f"no stage hands on a value {name!r}")
        readable = self.__dict__["_readable"]
        if readable is not None and name not in readable:
            raise AttributeError(f"{name!r} is not among the values this stage declares it reads")
        store = self.__dict__["_store"]
        if name not in store:
            store[name] = value.read(self)
        return store[name]

    def __setattr__(self, name: str, value: Any) -> None:
        if name not in type(self).VALUES:
            raise AttributeError(f"no stage hands on a value {name!r}")
        self.__dict__["_store"][name] = value

    def readable(self, names: frozenset[str] | None) -> None:
        """Let only ``names`` be read from now on (None: any value)."""
        self.__dict__["_readable"] = names

    def known(self, name: str) -> bool:
        """Whether ``name`` is already in memory (set by a stage or read before)."""
        return name in self.__dict__["_store"]

    def document(self) -> dict:
        """The case's records as one document (:meth:`CaseFolder.document` of :attr:`DOCUMENT`)."""
        return self.folder.document(type(self).DOCUMENT)

    def forget(self, *names: str) -> None:
        """Let values go that no later stage reads (read again from the case folder if one did)."""
        for name in names:
            self.__dict__["_store"].pop(name, None)


def data_class(values: Iterable[Value], document=()) -> type[CaseData]:
    """A :class:`CaseData` whose fields are ``values``, each annotated with its type; ``document``:
    its :attr:`~CaseData.DOCUMENT`."""
    table: dict[str, Value] = {}
    for value in values:
        if value.name in table or value.name == "folder" or hasattr(CaseData, value.name):
            raise ValueError(f"value {value.name!r}: handed on twice, or a name CaseData uses")
        table[value.name] = value
    namespace = {
        "VALUES": table,
        "DOCUMENT": tuple(document),
        "__annotations__": {name: v.type for name, v in table.items()},
        "__doc__": CaseData.__doc__,
        "__module__": __name__,
    }
    return type("CaseData", (CaseData,), namespace)
