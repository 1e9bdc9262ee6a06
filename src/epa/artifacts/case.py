"""One case: its identity (:class:`Case`), its folder on disk (:class:`CaseFolder`: the paths, typed
readers and writers, failure markers) and the typed view of its artifacts that stages, reports and
tables share (:class:`CaseData`: each artifact read once, or taken from the stage that just made it).

A case folder is ``<results>/cases/<algorithm>/<dataset>/<run>/<NN_stage>/<file>``. A failed stage
writes a failure marker into each of its artifacts (JSON: ``{"status": "failed", "reason": ...}``;
text: a first line ``# epa-failed: <reason>``), so a file opened by hand says why.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from epa.artifacts import files
from epa.core import runtime
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory

# The folder of each stage, in the order the stages run (the stage modules say what each writes).
FOLDERS = {
    "load": "01_load",
    "crop": "02_crop",
    "sync": "03_sync",
    "calibrate": "04_calibrate",
    "align": "05_align",
    "metrics": "06_metrics",
    "drift": "07_drift",
    "consistency": "08_consistency",
    "efficiency": "09_efficiency",
    "report": "10_report",
}
FAILED_PREFIX = "# epa-failed: "


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
# (device, inode, mtime, size) -> Trajectory
_PARSED: OrderedDict = runtime.register("artifacts.case.parsed", OrderedDict())
CACHE_MAX = 64  # a few hundred MB at most for 200 Hz references, far less for most grids
# reference source -> the file this process wrote it to
_WRITTEN: dict = runtime.register("artifacts.case.written", {})


def remember(cache: OrderedDict, key, value):
    """Keep ``value`` in a least-recently-used ``cache`` of at most CACHE_MAX entries."""
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > CACHE_MAX:
        cache.popitem(last=False)
    return value


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
        return self.root / FOLDERS[stage] / name

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
        return files.remove_temporaries(self.root / FOLDERS[stage], names)

    def write_failure(self, stage: str, names, reason: str) -> None:
        for name in names:
            if name.endswith(".json"):
                self.write_record(stage, name, {"status": "failed", "reason": reason})
            else:
                files.write_text(self.path(stage, name), FAILED_PREFIX + reason + "\n")


# ----------------------------------------------------------------------------- the typed view
def _slot(name: str, read):
    """A property holding a stage's value: the one a stage set in this process, else ``read(self)``
    from the case folder (once)."""
    attr = "_" + name

    def get(self):
        if attr not in self.__dict__:
            self.__dict__[attr] = read(self)
        return self.__dict__[attr]

    def set_(self, value):
        self.__dict__[attr] = value

    return property(get, set_, doc=read.__doc__)


def _matched(stage):
    def read(self):
        ref, est = self.cropped
        i_ref, i_est = self.sync_pairs if stage == "sync" else self.calibrate_pairs
        return ref.select(i_ref), est.select(i_est)

    read.__doc__ = f"(ref, est) of the cropped trajectories matched by {stage}/pairs.csv"
    return read


class CaseData:
    """What each stage produced for one case, typed. ``epa eval`` runs every stage in one process
    and the values pass in memory; a workflow job runs one stage and the values it needs are read
    from the previous stages' artifacts, each at most once."""

    def __init__(self, folder: CaseFolder):
        self.folder = folder

    f = property(lambda self: self.folder)

    def known(self, name: str) -> bool:
        """Whether ``name`` is already in memory (set by a stage or read before)."""
        return "_" + name in self.__dict__

    def forget(self, *names: str) -> None:
        """Let values go that no later stage reads (read again from the case folder if one did)."""
        for name in names:
            self.__dict__.pop("_" + name, None)

    # load
    loaded = _slot("loaded", lambda s: (s.f.tum("load", "ref.tum"), s.f.tum("load", "est.tum")))
    load_record = _slot("load_record", lambda s: s.f.record("load", "load.json"))

    def _timing(self):
        """{t, frame_ms} of the run's timing file as load read it, or None without one"""
        return self.f.table("load", "timing.csv") if self.f.has("load", "timing.csv") else None

    timing = _slot("timing", _timing)
    # crop
    cropped = _slot("cropped", lambda s: (s.f.tum("crop", "ref.tum"), s.f.tum("crop", "est.tum")))
    crop_record = _slot("crop_record", lambda s: s.f.record("crop", "crop.json"))
    # sync
    sync_record = _slot("sync_record", lambda s: s.f.record("sync", "sync.json"))
    sync_pairs = _slot("sync_pairs", lambda s: s.f.pairs("sync"))
    sync_matched = _slot("sync_matched", _matched("sync"))
    # calibrate
    calibrate_record = _slot(
        "calibrate_record", lambda s: s.f.record("calibrate", "calibrate.json")
    )
    calibrate_pairs = _slot("calibrate_pairs", lambda s: s.f.pairs("calibrate"))
    matched = _slot("matched", _matched("calibrate"))

    def _calibrated(self):
        """(ref, est) matched, the estimate with Step 2's extrinsic applied when the plan applies it"""
        ref, est = self.matched
        if self.calibrate_record["plan"]["apply_extrinsic"]:
            est = self.f.tum("calibrate", "est.tum")
        return ref, est

    calibrated = _slot("calibrated", _calibrated)
    # align
    transform = _slot("transform", lambda s: s.f.record("align", "transform.json"))
    aligned = _slot("aligned", lambda s: s.f.tum("align", "aligned.tum"))
    # metrics
    metrics_record = _slot("metrics_record", lambda s: s.f.record("metrics", "metrics.json"))
    ape = _slot("ape", lambda s: s.f.table("metrics", "ape.csv"))
    rpe_segments = _slot("rpe_segments", lambda s: s.f.table("metrics", "rpe_segments.csv"))
    rpe_time = _slot("rpe_time", lambda s: s.f.table("metrics", "rpe_time.csv"))
    # drift
    drift_record = _slot("drift_record", lambda s: s.f.record("drift", "drift.json"))
    fail_segments = _slot("fail_segments", lambda s: s.f.table("drift", "fail_segments.csv"))
    # consistency, efficiency
    consistency_record = _slot(
        "consistency_record", lambda s: s.f.record("consistency", "consistency.json")
    )
    efficiency_record = _slot(
        "efficiency_record", lambda s: s.f.record("efficiency", "efficiency.json")
    )

    def _nees(self):
        """08_consistency/nees.csv, or {} without covariance"""
        return (
            self.f.table("consistency", "nees.csv") if self.f.has("consistency", "nees.csv") else {}
        )

    nees = _slot("nees", _nees)
