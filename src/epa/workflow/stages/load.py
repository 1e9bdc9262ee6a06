"""Load: read the reference and the estimate in any supported format, and the run's timing file
(01_load/)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from epa import readers
from epa.artifacts.case import Both, CaseData, Columns, Kept, Record, remember
from epa.artifacts.stage import Stage, Value
from epa.core import runtime
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers import text
from epa.readers import timing as timing_files
from epa.readers.detect import is_bag

NAME = "load"

# reference source -> (Trajectory, notes) parsed from the user's file, shared by a dataset's cases
_LOADED: Kept = runtime.register("workflow.stages.load.loaded", Kept())


def c_parser_min_bytes() -> int:
    """Where the process chose pandas' parser (the workflow's workers preload pandas) it reads
    every file (a 1.1 MB run: 6-7 ms against loadtxt's 21-22); elsewhere only files large enough
    to repay its import (0.5 s)."""
    return 0 if runtime.pandas_parser() else text.C_PARSER_MIN_BYTES


def _read(path, opts: dict, **kwargs) -> Trajectory:
    """A source read with its settings. A KITTI file also keeps its rotation blocks as printed
    (orthonormal to 2e-7 only): the KITTI metric computes on them as the devkit does, and they travel
    in the stage trajectories (``write_tum``'s 9 extra columns). Other formats have none."""
    return readers.read(
        path, {**opts, "kitti_printed": True}, c_parser_min_bytes=c_parser_min_bytes(), **kwargs
    )


def read_ahead(path) -> text.TableAhead | None:
    """The estimate's text started in a second thread while the reference is read, where the process
    runs one case alone (`epa eval`: :func:`epa.core.runtime.spare_thread`) and the file is large
    enough for pyarrow's parse, which releases the GIL (the 100k pair's load 0.15 -> 0.1 s wall);
    None otherwise. A bag is read by its own reader."""
    if not runtime.spare_thread() or is_bag(path):
        return None
    try:
        size = os.stat(path).st_size
    except OSError:  # the reader says what is wrong with it, in its words
        return None
    # without pyarrow the parse would hold the GIL: nothing to gain beside the reference
    if size < text.ARROW_MIN_BYTES or "arrow" not in text.parsers_for(size, c_parser_min_bytes()):
        return None
    return text.TableAhead(Path(path), c_parser_min_bytes())


# (absolute path, mtime, size) -> the text file's table being read (read_ahead_case)
_AHEAD: dict[tuple, text.TableAhead] = runtime.register("workflow.stages.load.ahead", {})


def _file_key(path) -> tuple | None:
    """What a text file read ahead is known by: None for anything but a regular file (a bag folder,
    a pipe, a missing file: the reader reports those in its words, where it always did)."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (os.path.abspath(path), st.st_mtime_ns, st.st_size) if stat.S_ISREG(st.st_mode) else None


def read_ahead_case(ref_path, est_path) -> None:
    """Start reading one case's text files in threads (:func:`epa.readers.text.tables_ahead`: side
    by side, or the reference then the estimate), while the command goes on (`epa eval`: importing
    the metrics, resolving its config, importing its stages: 0.1-0.2 s in which the parse, which
    mostly releases the GIL, is done). The load stage of that case takes them (:func:`run`);
    :func:`forget_ahead` ends what is left. Tables only: each file is read as a source of its
    settings only where it is taken. Files already being read are not read again."""
    keys = [_file_key(path) for path in (ref_path, est_path)]
    if _AHEAD and all(key in _AHEAD for key in keys if key is not None):
        return
    forget_ahead()
    files: dict[tuple, Path] = {}  # the text files, each once
    for path, key in zip((ref_path, est_path), keys):
        if key is not None and not is_bag(path):
            files.setdefault(key, Path(path))
    _AHEAD.update(zip(files, text.tables_ahead(list(files.values()), c_parser_min_bytes())))


def _take_ahead(path) -> text.TableAhead | None:
    """The table of ``path`` read ahead; None where the file changed since (forget_ahead drops it)."""
    key = _file_key(path)
    return _AHEAD.pop(key, None) if key is not None else None


def forget_ahead() -> None:
    """Wait for the tables read ahead and none taken, and drop them."""
    while _AHEAD:
        _AHEAD.popitem()[1].join()


def load_reference(
    ref_path, cfg: dict, opts: dict | None = None, *, table: text.TableAhead | None = None
) -> tuple[Trajectory, list[str]]:
    """``table``: the file's table already started (:class:`epa.readers.text.TableAhead`)."""
    notes: list[str] = []
    opts = readers.options(cfg, "reference") if opts is None else opts
    return _read(ref_path, opts, notes=notes, table=table), notes


def compute(
    ref_path,
    est_path,
    cfg: dict,
    reference: tuple[Trajectory, list[str]] | None = None,
    *,
    ref_opts: dict | None = None,
    est_opts: dict | None = None,
    est_table: text.TableAhead | None = None,
):
    """Read the reference (unless already read: ``reference``, as load_reference returns it) and the
    estimate, each with its source settings (:func:`epa.readers.options`). ``ref_notes`` /
    ``est_notes`` in the record list what was inferred rather than read. ``est_table``: the
    estimate's text already being read (:func:`read_ahead`)."""
    ref_opts = readers.options(cfg, "reference") if ref_opts is None else ref_opts
    est_opts = readers.options(cfg, "estimate") if est_opts is None else est_opts
    ref, ref_notes = load_reference(ref_path, cfg, ref_opts) if reference is None else reference
    # KITTI estimates rarely ship their own times file: they are index-aligned with the reference's.
    est_times = None
    if not is_bag(est_path):
        est_times = text.kitti_times_for(Path(est_path)) or (
            None if is_bag(ref_path) else text.kitti_times_for(Path(ref_path))
        )
    est_notes: list[str] = []
    est = _read(est_path, est_opts, notes=est_notes, kitti_times=est_times, table=est_table)
    info = {
        "ref_file": Path(ref_path).name,
        "est_file": Path(est_path).name,
        "est_path": str(est_path),
        "n_ref": len(ref),
        "n_est": len(est),
        "ref_length_m": ref.length(),
        "est_length_m": est.length(),
        "ref_span_s": [float(ref.t[0]), float(ref.t[-1])],
        "est_span_s": [float(est.t[0]), float(est.t[-1])],
        "ref_notes": ref_notes,
        "est_notes": est_notes,
    }
    # the settings each side was read with
    info["sources"] = {"reference": ref_opts, "estimate": est_opts}
    info["covariance"] = est.cov_rot is not None
    timing = None
    try:  # a bad timing file costs the case its efficiency, not its accuracy: the efficiency stage reports it
        timing_path = readers.timing_file(est_path, est_opts)
        if timing_path is not None:
            t, ms, what = timing_files.read_timing(
                timing_path, c_parser_min_bytes=c_parser_min_bytes()
            )
            timing = {"t": t, "frame_ms": ms}
            info["timing"] = {"file": timing_path.name, "read_as": what, "frames": int(len(t))}
    except EpaError as exc:
        info["timing_error"] = {"path": exc.path, "line": exc.line, "message": exc.message}
    return ref, est, info, timing


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    case, folder = data.folder.case, data.folder
    if case is None or case.truth is None or case.estimate is None:
        raise TypeError("the load stage runs on a case folder that knows its case and both files")
    ref_opts = case.truth_source or readers.options(cfg, "reference")
    est_opts = case.estimate_source or readers.options(cfg, "estimate")
    try:
        st = os.stat(case.truth)
    except OSError:  # the reader says what is wrong with it, in its words
        st = None
    source = st and (os.path.abspath(case.truth), st.st_mtime_ns, st.st_size, repr(ref_opts))
    parse_reference = bool(source) and source not in _LOADED
    ref_table, est_table = _take_ahead(case.truth), _take_ahead(case.estimate)
    if est_table is None and parse_reference:
        est_table = read_ahead(case.estimate)
    try:
        if parse_reference:
            remember(_LOADED, source, load_reference(case.truth, cfg, ref_opts, table=ref_table))
        ref, est, info, timing = compute(
            case.truth,
            case.estimate,
            cfg,
            reference=_LOADED.get(source) if source else None,
            ref_opts=ref_opts,
            est_opts=est_opts,
            est_table=est_table,
        )
    finally:  # an error before a table was taken (or one not needed): its thread ends here
        for table in (ref_table, est_table):
            if table is not None:
                table.join()
    if case.settings_record:  # what this case ran with beside the grid's settings
        info["settings"] = case.settings_record
    data.loaded, data.load_record, data.timing = (ref, est), info, timing
    if write_arrays:
        # the efficiency stage reads the run's timing from here, never from the user's folder
        if timing is not None:
            folder.write_table(NAME, "timing.csv", timing)
        else:
            folder.remove(NAME, "timing.csv")
        folder.write_shared_tum(NAME, "ref.tum", ref, source or None)
        folder.write_tum(NAME, "est.tum", est)
    folder.write_record(NAME, "load.json", info)


def _timing(data: CaseData) -> Columns | None:
    """{t, frame_ms} of the run's timing file as load read it, or None without one"""
    return data.f.table(NAME, "timing.csv") if data.f.has(NAME, "timing.csv") else None


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("load",),  # the sources' settings travel with each case
    records=("load.json",),
    arrays=("ref.tum", "est.tum", "timing.csv"),
    values=(
        Value("loaded", Both, lambda s: (s.f.tum(NAME, "ref.tum"), s.f.tum(NAME, "est.tum"))),
        Value("load_record", Record, lambda s: s.f.record(NAME, "load.json")),
        Value("timing", Columns | None, _timing),
    ),
)
