"""The stage chain, defined once: what each stage reads, computes and writes for one case.

``epa eval`` runs :func:`run_case` (every stage in one process, values passed in memory); the
workflow runs one stage for a batch of cases per job (:mod:`epa.workflow.jobs`), each stage reading the
previous stage's artifacts from the case folder. Both call the same :data:`STAGES` entries, so the
command line and the workflow write the same ``metrics.json``.

A failed stage writes a failure marker into each of its artifacts (JSON: ``{"status": "failed",
"reason": ...}``; text: a first line ``# epa-failed: <reason>``), so a file opened by hand says why.
"""

from __future__ import annotations

import logging
import os
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from epa import readers
from epa.artifacts import files as io
from epa.core.errors import EpaError
from epa.metrics import consistency
from epa.steps import align as alignment
from epa.steps import calibrate as calibration
from epa.workflow import pipeline

log = logging.getLogger("epa")

FAILED_PREFIX = "# epa-failed: "


@dataclass(frozen=True)
class Stage:
    name: str
    folder: str
    records: tuple[str, ...]  # small JSON artifacts (always written)
    tables: tuple[str, ...]  # per-pose / per-pair artifacts: the workflow's next stage reads them;
    # `epa eval` passes the values in memory and writes these only on request
    settings: tuple[str, ...]  # top-level config keys the stage reads: a change re-runs it onward
    run: Callable  # (case: CaseFolder, values: dict, cfg: dict, write_tables: bool) -> None

    def artifacts(self) -> tuple[str, ...]:
        return self.records + self.tables


class CaseFolder:
    """Paths of one case's artifacts: ``<root>/<NN_stage>/<file>``."""

    def __init__(
        self,
        root,
        truth=None,
        estimate=None,
        truth_source: dict | None = None,
        estimate_source: dict | None = None,
    ):
        self.root = Path(root)
        self.truth, self.estimate = truth, estimate
        # each side's source settings (epa.readers.options); None: the load section's
        self.truth_source, self.estimate_source = truth_source, estimate_source

    def path(self, stage: str, name: str) -> Path:
        return self.root / BY_NAME[stage].folder / name

    def log(self, stage: str) -> Path:
        return self.root / "logs" / f"{stage}.log"


def case_dir(results_dir, key: str) -> Path:
    """Where a case's artifacts live: ``<results_dir>/cases/<algorithm>/<dataset>/<run>``. A key is
    three plain names (discovery makes them from file names), so nothing escapes ``results_dir``."""
    parts = key.split("/")
    if len(parts) != 3 or any(part in ("", ".", "..") or "\\" in part for part in parts):
        raise EpaError(f"case {key!r} is not <algorithm>/<dataset>/<run> with plain names")
    return Path(results_dir) / "cases" / key


# ----------------------------------------------------------------------------- failure markers
def read_record(path) -> tuple[dict, str | None]:
    """A stage's JSON record and, if it is a failure marker, the recorded reason (read once)."""
    data = io.read_json(path)
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


def write_failure(case: CaseFolder, stage: Stage, reason: str, *, tables: bool = True) -> None:
    for name in stage.artifacts() if tables else stage.records:
        path = case.path(stage.name, name)
        if name.endswith(".json"):
            io.write_json(path, {"status": "failed", "reason": reason})
        else:
            io.write_text(path, FAILED_PREFIX + reason + "\n")


# ----------------------------------------------------------------------------- shared files
# Every case of a dataset holds the same reference. A worker writes it once and hard-links it into
# the other cases, and parses a file once per inode (an atomic rewrite makes a new inode, so a
# cached parse is never stale). Measured: this halves the workflow's cost on 200 Hz references.
_PARSED: OrderedDict = (
    OrderedDict()
)  # (device, inode, mtime, size) -> Trajectory, least recent first
_PARSED_MAX = 64  # a few hundred MB at most for 200 Hz references, far less for most grids
_WRITTEN: dict = {}  # reference source -> the file this process wrote it to
_LOADED: OrderedDict = (
    OrderedDict()
)  # reference source -> (Trajectory, load info) parsed from the user's file


def _remember(cache: OrderedDict, key, value):
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > _PARSED_MAX:
        cache.popitem(last=False)
    return value


def _read_tum(path):
    st = os.stat(path)
    key = (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size)
    if key in _PARSED:
        _PARSED.move_to_end(key)
        return _PARSED[key]
    return _remember(_PARSED, key, io.read_tum_file(path))


def _link(src, dst) -> bool:
    """Hard-link ``src`` to ``dst`` (replacing it); False where the file system cannot."""
    dst = Path(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name("." + dst.name + ".link")
    try:
        if tmp.exists():
            os.unlink(tmp)
        os.link(src, tmp)
        os.replace(tmp, dst)
        return True
    except OSError:
        return False


def _write_reference(path, ref, source_key) -> None:
    prev = _WRITTEN.get(source_key)
    if prev is not None and os.path.exists(prev) and _link(prev, path):
        return
    io.write_tum(path, ref)
    _WRITTEN[source_key] = str(path)


# ----------------------------------------------------------------------------- stage bodies
# Each body takes its inputs from ``values`` (filled by the previous stage in this process) or, when
# absent, from the previous stage's artifacts; it leaves its own outputs in ``values``.
def _trajectories(case, values, stage):
    if stage not in values:
        values[stage] = (
            _read_tum(case.path(stage, "ref.tum")),
            _read_tum(case.path(stage, "est.tum")),
        )
    return values[stage]


def _pair_indices(case, values, stage):
    key = stage + "/pairs"
    if key not in values:
        values[key] = io.read_pair_indices(case.path(stage, "pairs.csv"))
    return values[key]


def _matched(case, values, stage):
    """(ref, est) matched by ``<stage>/pairs.csv``: row k pairs ref[i_ref[k]] with est[i_est[k]] of
    the cropped trajectories."""
    key = stage + "/matched"
    if key not in values:
        ref, est = _trajectories(case, values, "crop")
        i_ref, i_est = _pair_indices(case, values, stage)
        values[key] = (ref.select(i_ref), est.select(i_est))
    return values[key]


def _record(case, values, stage, name):
    key = f"{stage}/{name}"
    if key not in values:
        values[key] = io.read_json(case.path(stage, name))
    return values[key]


def _load(case, values, cfg, write_tables):
    ref_opts = case.truth_source or readers.options(cfg, "reference")
    est_opts = case.estimate_source or readers.options(cfg, "estimate")
    try:
        st = os.stat(case.truth)
    except OSError:  # the reader says what is wrong with it, in its words
        st = None
    source = st and (os.path.abspath(case.truth), st.st_mtime_ns, st.st_size, repr(ref_opts))
    if source and source not in _LOADED:
        _remember(_LOADED, source, pipeline.load_reference(case.truth, cfg, ref_opts))
    ref, est, info, timing = pipeline.load(
        case.truth,
        case.estimate,
        cfg,
        reference=_LOADED.get(source) if source else None,
        ref_opts=ref_opts,
        est_opts=est_opts,
    )
    values["load"], values["load/load.json"], values["load/timing"] = (ref, est), info, timing
    if write_tables:
        # the efficiency stage reads the run's timing from here, never from the user's folder
        timing_path = case.path("load", "timing.csv")
        if timing is not None:
            io.write_csv(timing_path, timing)
        elif timing_path.exists():
            os.unlink(timing_path)
        _write_reference(case.path("load", "ref.tum"), ref, source)
        io.write_tum(case.path("load", "est.tum"), est)
    io.write_json(case.path("load", "load.json"), info)


def _crop(case, values, cfg, write_tables):
    if write_tables and not pipeline.crops(cfg) and "load" not in values:
        # nothing to cut: the loaded files are the cropped ones (linked, not read and rewritten)
        info = pipeline.crop_info(cfg, _record(case, values, "load", "load.json"))
        if all(_link(case.path("load", n), case.path("crop", n)) for n in ("ref.tum", "est.tum")):
            io.write_json(case.path("crop", "crop.json"), info)
            return
    ref, est, info = pipeline.crop(*_trajectories(case, values, "load"), cfg)
    values["crop"], values["crop/crop.json"] = (ref, est), info
    if write_tables:
        io.write_tum(case.path("crop", "ref.tum"), ref)
        io.write_tum(case.path("crop", "est.tum"), est)
    io.write_json(case.path("crop", "crop.json"), info)


def _sync(case, values, cfg, write_tables):
    ref, est = _trajectories(case, values, "crop")
    (i_ref, i_est), info, curve = pipeline.sync_stage(ref, est, cfg)
    values["sync/pairs"], values["sync/sync.json"] = (i_ref, i_est), info
    values["sync/matched"] = (ref.select(i_ref), est.select(i_est))
    io.write_json(case.path("sync", "sync.json"), info)
    if write_tables:
        io.write_pair_indices(case.path("sync", "pairs.csv"), i_ref, i_est, ref.t, est.t)
        io.write_csv(case.path("sync", "xcorr.csv"), curve or {"lag_s": [], "corr": []})


def _calibrate(case, values, cfg, write_tables):
    ref, est = _matched(case, values, "sync")
    ref, est, info, pairs = pipeline.calibrate_stage(
        ref,
        est,
        cfg,
        _record(case, values, "sync", "sync.json"),
        cropped=lambda: _trajectories(case, values, "crop"),
    )
    values["calibrate"], values["calibrate/calibrate.json"] = (ref, est), info
    values["calibrate/pairs"] = pairs if pairs is not None else _pair_indices(case, values, "sync")
    io.write_json(case.path("calibrate", "calibrate.json"), info)
    if write_tables:
        dst = case.path("calibrate", "pairs.csv")
        if pairs is not None or not _link(
            case.path("sync", "pairs.csv"), dst
        ):  # re-associated, or no links
            ref_c, est_c = _trajectories(case, values, "crop")
            i_ref, i_est = pairs if pairs is not None else _pair_indices(case, values, "sync")
            io.write_pair_indices(dst, i_ref, i_est, ref_c.t, est_c.t)
        corrected = case.path("calibrate", "est.tum")
        if info["plan"]["apply_extrinsic"]:
            io.write_tum(corrected, est)  # the matched estimate with the extrinsic applied
        elif corrected.exists():
            os.unlink(corrected)


def _calibrated(case, values):
    if "calibrate" not in values:
        ref, est = _matched(case, values, "calibrate")
        if _record(case, values, "calibrate", "calibrate.json")["plan"]["apply_extrinsic"]:
            est = _read_tum(case.path("calibrate", "est.tum"))
        values["calibrate"] = (ref, est)
    return values["calibrate"]


def _align(case, values, cfg, write_tables):
    ref, est = _calibrated(case, values)
    aligned, info = pipeline.align_stage(
        ref, est, cfg, _record(case, values, "calibrate", "calibrate.json")
    )
    values["align"], values["align/transform.json"] = (ref, aligned), info
    io.write_json(case.path("align", "transform.json"), info)
    if write_tables:  # row k is matched with row k of 04_calibrate/pairs.csv
        io.write_tum(case.path("align", "aligned.tum"), aligned)


def _metrics(case, values, cfg, write_tables):
    if "align" not in values:
        values["align"] = (
            _matched(case, values, "calibrate")[0],
            _read_tum(case.path("align", "aligned.tum")),
        )
    ref, est = values["align"]
    summary, tables = pipeline.metrics_stage(ref, est, cfg)
    record = pipeline.case_record(
        _record(case, values, "load", "load.json"),
        _record(case, values, "sync", "sync.json"),
        _record(case, values, "calibrate", "calibrate.json"),
        _record(case, values, "align", "transform.json"),
        summary,
    )
    values["metrics"], values["metrics/metrics.json"] = tables, record
    if write_tables:
        for name in ("ape", "rpe_segments", "rpe_time"):
            io.write_csv(case.path("metrics", name + ".csv"), tables[name])
    kitti_table = case.path("metrics", "kitti_segments.csv")
    if write_tables and "kitti_segments" in tables:
        io.write_csv(kitti_table, tables["kitti_segments"])
    elif kitti_table.exists():  # from a run with metrics.kitti on
        os.unlink(kitti_table)
    io.write_json(case.path("metrics", "metrics.json"), record)


def _drift(case, values, cfg, write_tables):
    if "metrics" not in values:
        values["metrics"] = {
            name: io.read_csv(case.path("metrics", name + ".csv"))
            for name in ("ape", "rpe_segments", "rpe_time")
        }
    summary, artifacts = pipeline.drift_stage(values["metrics"], cfg)
    values["drift/drift.json"] = summary
    values["drift"] = artifacts
    if write_tables:
        for name in ("fail_segments", "pose_valid", "rpe_segments_valid", "rpe_time_valid"):
            io.write_csv(case.path("drift", name + ".csv"), artifacts[name])
    io.write_json(case.path("drift", "drift.json"), summary)


def _calibration_steps(case, values):
    """What Steps 2 and 3 did to the estimate: the applied extrinsic (or None) and the alignment."""
    calib = _record(case, values, "calibrate", "calibrate.json")
    ext = (
        calibration.Extrinsic.from_dict(calib["extrinsic"])
        if calib["plan"]["apply_extrinsic"]
        else None
    )
    return ext, alignment.Similarity.from_dict(_record(case, values, "align", "transform.json"))


def _consistency(case, values, cfg, write_tables):
    ref_m, est_m = _matched(
        case, values, "calibrate"
    )  # the estimate as read: its covariance is in its own frames
    extrinsic, align = _calibration_steps(case, values)
    summary, table = consistency.evaluate(ref_m, est_m, align, extrinsic)
    if summary.get("available") is False and summary.get("reason"):
        log.info("consistency: %s", summary["reason"])
    _store(case, values, "consistency", summary, table, write_tables)


def _efficiency(case, values, cfg, write_tables):
    load = _record(case, values, "load", "load.json")
    if load.get("timing_error"):
        err = load["timing_error"]
        raise EpaError(err["message"], path=err["path"], line=err["line"])
    timing = values.get("load/timing")
    if timing is None and "load" not in values and case.path("load", "timing.csv").exists():
        timing = io.read_csv(case.path("load", "timing.csv"))
    if timing is None:
        summary, table = {"available": False, "reason": "no timing file for this run"}, {}
    else:
        if "metrics" not in values:
            values["metrics"] = {"ape": io.read_csv(case.path("metrics", "ape.csv"))}
        if "calibrate/matched" in values or "calibrate" in values:
            t_est = _matched(case, values, "calibrate")[1].t
        else:  # the matched estimate stamps, without parsing a trajectory
            t_est = io.read_csv(case.path("calibrate", "pairs.csv"))["t_est"]
        length = _record(case, values, "metrics", "metrics.json")["est_length_m"]
        dataset = Path(load["ref_file"]).stem  # discovery names a dataset by its reference's stem
        summary, table = pipeline.efficiency_stage(
            t_est, values["metrics"]["ape"], length, (timing["t"], timing["frame_ms"]), dataset, cfg
        )
    _store(case, values, "efficiency", summary, table, write_tables)


def _store(case, values, stage, summary, table, write_tables):
    """A stage with one record and one optional table (none without covariance / timing)."""
    st = BY_NAME[stage]
    record, table_path = st.records[0], case.path(stage, st.tables[0])
    values[f"{stage}/{record}"], values[stage] = summary, table
    if write_tables and table:
        io.write_csv(table_path, table)
    elif table_path.exists():
        os.unlink(table_path)
    io.write_json(case.path(stage, record), summary)


def _report(case, values, cfg, write_tables):
    """10_report/: documents, figures and the case zip, from the artifacts (so only where they are written)."""
    if not cfg["report"]["per_case"] or not write_tables:
        summary = {
            "available": False,
            "reason": "report.per_case is off" if write_tables else "no artifacts written",
        }
    else:
        from epa.outputs import report

        summary = {
            "available": True,
            **report.write_case_report(case, "/".join(case.root.parts[-3:]), cfg),
        }
    values["report/report.json"] = summary
    io.write_json(case.path("report", "report.json"), summary)


STAGES: tuple[Stage, ...] = (
    Stage(
        "load", "01_load", ("load.json",), ("ref.tum", "est.tum", "timing.csv"), ("load",), _load
    ),
    Stage("crop", "02_crop", ("crop.json",), ("ref.tum", "est.tum"), ("crop",), _crop),
    Stage("sync", "03_sync", ("sync.json",), ("pairs.csv", "xcorr.csv"), ("mode", "sync"), _sync),
    Stage(
        "calibrate",
        "04_calibrate",
        ("calibrate.json",),
        ("pairs.csv", "est.tum"),
        ("mode", "sync", "calibrate"),
        _calibrate,
    ),
    Stage("align", "05_align", ("transform.json",), ("aligned.tum",), ("mode", "align"), _align),
    Stage(
        "metrics",
        "06_metrics",
        ("metrics.json",),
        ("ape.csv", "rpe_segments.csv", "rpe_time.csv", "kitti_segments.csv"),
        ("metrics",),
        _metrics,
    ),
    Stage(
        "drift",
        "07_drift",
        ("drift.json",),
        ("fail_segments.csv", "pose_valid.csv", "rpe_segments_valid.csv", "rpe_time_valid.csv"),
        ("drift", "metrics"),
        _drift,
    ),
    # consistency and efficiency report "available": false when there is no covariance / timing
    Stage("consistency", "08_consistency", ("consistency.json",), ("nees.csv",), (), _consistency),
    Stage(
        "efficiency",
        "09_efficiency",
        ("efficiency.json",),
        ("frames.csv",),
        ("efficiency",),
        _efficiency,
    ),
    Stage("report", "10_report", ("report.json",), (), ("report",), _report),
)
BY_NAME = {s.name: s for s in STAGES}
NAMES = tuple(s.name for s in STAGES)


def settings_for(stage: str, cfg: dict) -> dict:
    """The part of a resolved config one stage reads (what the workflow puts in the rule's params)."""
    return {k: cfg[k] for k in BY_NAME[stage].settings}


def previous(stage: str) -> str | None:
    k = NAMES.index(stage)
    return NAMES[k - 1] if k else None


def run_stage(
    stage: str,
    case: CaseFolder,
    cfg: dict,
    values: dict | None = None,
    *,
    write_tables: bool = True,
) -> None:
    """One stage for one case. Raises EpaError for a user mistake; any other exception is a bug."""
    st = BY_NAME[stage]
    st.run(case, {} if values is None else values, settings_for(stage, cfg), write_tables)


def run_case(
    ref_path,
    est_path,
    out_dir,
    cfg: dict,
    *,
    write_tables: bool = False,
    on_stage: Callable[[str], None] | None = None,
    ref_source: dict | None = None,
    est_source: dict | None = None,
) -> dict:
    """Every stage for one case in this process (``epa eval``); returns metrics.json and drift.json.
    A user mistake raises EpaError after the failed stage's markers are written."""
    case = CaseFolder(out_dir, ref_path, est_path, ref_source, est_source)
    values: dict = {}
    for st in STAGES:
        if on_stage is not None:
            on_stage(st.name)
        try:
            run_stage(st.name, case, cfg, values, write_tables=write_tables)
        except EpaError as exc:
            write_failure(case, st, f"{st.name}: {exc.one_line()}", tables=write_tables)
            if exc.path is None:  # a stage's finding about the case: name the estimate it is about
                raise EpaError(f"{st.name}: {exc.message}", path=str(est_path)) from None
            raise
    return {
        "metrics": values["metrics/metrics.json"],
        "drift": values["drift/drift.json"],
        "consistency": values["consistency/consistency.json"],
        "efficiency": values["efficiency/efficiency.json"],
    }


def clear_tables(case: CaseFolder) -> None:
    """Remove table artifacts a previous run left (``epa eval`` without them must not leave stale ones)."""
    for st in STAGES:
        for name in st.tables:
            p = case.path(st.name, name)
            if p.exists():
                os.unlink(p)
