"""Stage artifacts: atomic writes (no half-written file is ever taken as done), JSON, CSV, TUM
and the writers of every trajectory format the readers take (:mod:`epa.readers`)."""

from __future__ import annotations

import errno
import itertools
import json
import math
import os
import random
import re
import tempfile
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from epa.core import runtime
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers import text
from epa.readers.text import FORMATS, upper_to_full

# ----------------------------------------------------------------------------- artifacts
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def _atomic_write(path, write) -> None:
    """Write via a temporary file and rename, so no half-written file is ever taken as done. A path
    that cannot be written (a file where a folder should be, no permission, a full disk) is one line
    naming it. ``write``: the text (or bytes) itself, or a function writing to the open text file."""
    path = Path(path)
    try:
        fd, tmp = _temporary(path)
    except OSError as exc:
        raise EpaError(f"cannot write: {_why(exc, path)}", path=str(path)) from None
    try:
        if isinstance(write, (str, bytes, Iterator)):  # without a Python file object
            try:
                os.fchmod(fd, _MODE)
                # the whole text at once, or its blocks (bytes-like) one after another
                blocks = [write] if isinstance(write, (str, bytes)) else write
                for block in blocks:
                    data = memoryview(block.encode("utf-8") if isinstance(block, str) else block)
                    while data:
                        data = data[os.write(fd, data) :]
            finally:
                os.close(fd)
        else:
            with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
                os.fchmod(fd, _MODE)
                write(fh)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise EpaError(f"cannot write: {_why(exc, path)}", path=str(path)) from None
        raise


# the temporary is made 0600, as mkstemp makes it, then given this mode: results are for the group
_MODE = 0o666 & ~_UMASK
_NAME_CHARS = "abcdefghijklmnopqrstuvwxyz0123456789_"  # tempfile's, so _TEMPORARY matches both
_OPEN_FLAGS = (
    os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
)


def _temporary(path: Path) -> tuple[int, str]:
    """mkstemp's temporary beside ``path`` (``.<name>.<8 random characters>``, mode 0600, never an
    existing file), without mkstemp's per-call overhead; the folder is made only when missing (a
    stage writes a few files into each of a case's folders: one mkdir a folder, not one a file).
    random's module functions, as tempfile's names: reseeded in a forked child."""
    prefix = os.path.join(path.parent, "." + path.name + ".")
    made = False
    for _ in range(tempfile.TMP_MAX):
        tmp = prefix + "".join(random.choices(_NAME_CHARS, k=8))
        try:
            return os.open(tmp, _OPEN_FLAGS, 0o600), tmp
        except FileExistsError:
            continue
        except FileNotFoundError:
            if made:
                raise
            path.parent.mkdir(parents=True, exist_ok=True)
            made = True
    raise FileExistsError(errno.EEXIST, "no usable temporary name found")


# A temporary of _atomic_write is "." + the artifact's name + "." + mkstemp's 8 random characters
# (CPython's tempfile alphabet); one of case.link is "." + the name + ".link".
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.(?:[a-z0-9_]{8}|link)")


def remove_temporaries(folder, names) -> list[str]:
    """Remove the temporaries a killed write left in ``folder`` for the artifacts ``names`` (a
    temporary is never taken as done, but would stay); only those names, never another file. One
    listing of the folder (none when it does not exist). Returns the names removed."""
    names = set(names)
    try:
        with os.scandir(folder) as entries:
            stale = sorted(
                e.name
                for e in entries
                if e.name.startswith(".")
                and (m := _TEMPORARY.fullmatch(e.name)) is not None
                and m["name"] in names
                and e.is_file(follow_symlinks=False)
            )
    except (FileNotFoundError, NotADirectoryError):
        return []
    for name in stale:
        try:
            os.unlink(os.path.join(folder, name))
        except FileNotFoundError:  # gone meanwhile
            pass
    return stale


def _why(exc: OSError, path: Path) -> str:
    """The reason, with the path part that is in the way (a file where a folder is needed)."""
    where = next((p for p in path.parents if p.exists() and not p.is_dir()), None)
    if where is not None:
        return f"{where} is a file, not a folder"
    return exc.strerror or type(exc).__name__


def write_text(path, text: str) -> None:
    _atomic_write(path, text)


def write_bytes(path, data: bytes) -> None:
    _atomic_write(path, data)


def _jsonable(obj):
    """Plain JSON values. ±inf is the string "inf" / "-inf" (a ratio with a zero denominator, e.g.
    Step 1's peak_ratio); NaN is refused: a quantity without samples is None with a reason in its
    record, so a NaN here is a bug to fix where it was made (json.dump's allow_nan=False then names
    no key, :func:`_nan_keys` does)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else obj if np.isnan(obj) else str(float(obj))
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def _nan_keys(obj, where: str = "") -> list[str]:
    """The dotted keys of every NaN in a JSON-able value (for the error message only)."""
    if isinstance(obj, dict):
        return [
            p for k, v in obj.items() for p in _nan_keys(v, f"{where}.{k}" if where else str(k))
        ]
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [p for k, v in enumerate(obj) for p in _nan_keys(v, f"{where}[{k}]")]
    return [where] if isinstance(obj, (np.floating, float)) and np.isnan(obj) else []


def write_json(path, data: dict) -> None:
    """JSON every reader parses: ±inf as strings, and a NaN refused (ValueError naming its keys)
    instead of written as the NaN token no JSON parser takes, or as a null without a reason."""
    try:
        text = _indented(data, "\n")
    except _Unusual:  # json.dumps' own path decides (and names a NaN's keys)
        text = _dumps_checked(path, data)
    _atomic_write(path, text)


def _dumps_checked(path, data) -> str:
    doc = _jsonable(data)
    try:
        return json.dumps(doc, indent=2, sort_keys=False, allow_nan=False)
    except ValueError:
        keys = _nan_keys(doc)
        raise ValueError(
            f"{Path(path).name}: NaN at {', '.join(keys[:5])}{' ...' if len(keys) > 5 else ''}"
            " (a quantity without samples is None with a reason, never NaN)"
        ) from None


class _Unusual(Exception):
    """A value :func:`_indented` leaves to json.dumps (a NaN, a key that is no str, another type)."""


_ESCAPE = json.encoder.encode_basestring_ascii


def _indented(obj, nl: str) -> str:
    """``json.dumps(_jsonable(obj), indent=2)``'s text, 3-4x faster: json's indented encoder is its
    pure-Python one, one generator per value (records were a third of the report stage's time).
    ``nl``: a newline and the current indent. Raises _Unusual for anything but plain values, numpy
    scalars and arrays (NaN included), which the caller hands to json.dumps."""
    t = type(obj)
    if t is float or t is np.float64:
        if math.isfinite(obj):  # (inf - inf would warn: numpy scalars)
            return float.__repr__(float(obj))
        if obj != obj:
            raise _Unusual
        return '"inf"' if obj > 0 else '"-inf"'
    if t is str:
        return _ESCAPE(obj)
    if t is int:
        return int.__repr__(obj)
    if obj is None:
        return "null"
    if t is bool:
        return "true" if obj else "false"
    if t is dict:
        if not obj:
            return "{}"
        inner = nl + "  "
        items = []
        for k, v in obj.items():
            if type(k) is not str:
                raise _Unusual
            items.append(_ESCAPE(k) + ": " + _indented(v, inner))
        return "{" + inner + ("," + inner).join(items) + nl + "}"
    if t is list or t is tuple:
        if not obj:
            return "[]"
        inner = nl + "  "
        return "[" + inner + ("," + inner).join([_indented(v, inner) for v in obj]) + nl + "]"
    if t is np.ndarray:
        return _indented(obj.tolist(), nl)
    if isinstance(obj, np.integer):
        return int.__repr__(int(obj))
    if isinstance(obj, np.bool_):
        return "true" if obj else "false"
    if isinstance(obj, np.floating):
        return _indented(float(obj), nl)
    raise _Unusual


def read_json(path) -> dict:
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


TUM_HEADER = "# t x y z qx qy qz qw"
_UPPER = ([0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2])  # 11 12 13 22 23 33
EUROC_HEADER = (
    "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
)
COV_HEADER = [
    "pr11",
    "pr12",
    "pr13",
    "pr22",
    "pr23",
    "pr33",
    "pt11",
    "pt12",
    "pt13",
    "pt22",
    "pt23",
    "pt33",
]


# Stage artifacts are lossless (each number's text reads back as the same double: pyarrow's
# shortest text where installed, exact_rows; else %.17g): the next stage reads exactly what this one
# computed, so the workflow and the in-memory `epa eval` give identical results.
EXACT = "%.17g"


def exact_rows(data: np.ndarray, delimiter: str) -> Iterator | None:
    """The rows of a 2-D float table as text by pyarrow's CSV writer, in blocks (bytes-like; a
    million rows are not held as text at once): each number the shortest text that reads back as
    the same double (``0.1``, not ``%.17g``'s ``0.10000000000000001``), ``nan``, ``inf`` and ``-0``
    as ``%.17g`` writes them. 3-5x faster than formatting with ``%`` (a quarter of the workflow's
    stage time was that formatting) and shorter to read; None without pyarrow or for a table
    without columns (the caller formats with ``%.17g``: the same doubles)."""
    data = np.asarray(data, dtype=float)  # a float32 column's shortest text is not its double's
    if data.ndim != 2 or data.shape[1] == 0:
        return None
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:
        return None
    options = pacsv.WriteOptions(include_header=False, delimiter=delimiter, quoting_style="none")
    names = [f"c{k}" for k in range(data.shape[1])]

    def blocks():
        for lo in range(0, len(data), ARROW_ROWS_PER_BLOCK):
            block = data[lo : lo + ARROW_ROWS_PER_BLOCK]
            sink = pa.BufferOutputStream()
            # each column from its buffer: pa.table or pa.array of an ndarray imports pandas (to
            # check for a frame), 0.25-0.5 s in a process without it (the tables rule, `epa eval`)
            columns = [
                pa.Array.from_buffers(pa.float64(), len(block), [None, pa.py_buffer(column)])
                for column in np.ascontiguousarray(block.T)
            ]
            batch = pa.RecordBatch.from_arrays(columns, names=names)
            pacsv.write_csv(batch, sink, write_options=options)
            yield sink.getvalue()

    return blocks()


ARROW_ROWS_PER_BLOCK = 65536  # about 10-25 MB of text at a time


def savetxt(fh, data, fmt: str = EXACT, delimiter: str = " ", header: str = "", comments="# "):
    """np.savetxt's bytes for a table of floats, 4-5x faster: the rows are formatted by one ``%``
    per block of rows instead of one Python call and one write per row (measured on the example:
    40 % of a stage job was np.savetxt)."""
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    if data.ndim != 2 or data.shape[1] == 0:
        return np.savetxt(fh, data, fmt=fmt, delimiter=delimiter, header=header, comments=comments)
    if header:
        fh.write(comments + header.replace("\n", "\n" + comments) + "\n")
    row = delimiter.join([fmt] * data.shape[1]) + "\n"
    for lo in range(0, len(data), ROWS_PER_BLOCK):
        block = data[lo : lo + ROWS_PER_BLOCK]
        fh.write((row * len(block)) % tuple(block.ravel().tolist()))


ROWS_PER_BLOCK = 8192  # a few MB of text at a time


def _write_table(path, data, delimiter: str, header: str, comments: str, fmt: str = EXACT) -> None:
    """A stage's table artifact: its header line, then its rows, exact (:func:`exact_rows`) where
    pyarrow is installed and ``fmt`` is EXACT, else formatted by :func:`savetxt` (the same header)."""
    rows = exact_rows(data, delimiter) if fmt == EXACT else None
    if rows is None:
        _atomic_write(
            path, lambda fh: savetxt(fh, data, fmt, delimiter, header=header, comments=comments)
        )
    else:
        _atomic_write(path, itertools.chain([(comments + header + "\n").encode()], rows))


def _cov_columns(traj: Trajectory) -> np.ndarray | None:
    """The orientation then position covariance upper triangles (N, 12), or None without covariance."""
    if traj.cov_rot is None or traj.cov_pos is None:
        return None
    return np.column_stack(
        [traj.cov_rot[:, _UPPER[0], _UPPER[1]], traj.cov_pos[:, _UPPER[0], _UPPER[1]]]
    )


# A KITTI file's rotation blocks as printed, row-major (Trajectory.r_printed), after the other columns.
PRINTED_HEADER = ["r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"]
_WIDTH = {8: (False, False), 20: (True, False), 17: (False, True), 29: (True, True)}


def write_tum(path, traj: Trajectory) -> None:
    """A stage's trajectory artifact: TUM, plus the orientation and position covariance upper
    triangles (the OpenVINS layout, 20 columns) when the trajectory has covariance, plus the 9
    printed rotation entries when it keeps a KITTI file's (17 or 29 columns)."""
    cov = _cov_columns(traj)
    printed = None if traj.r_printed is None else traj.r_printed.reshape(len(traj), 9)
    extra = [c for c in (cov, printed) if c is not None]
    data = np.column_stack([traj.t, traj.p, traj.q] + extra)
    header = " ".join(
        [TUM_HEADER[2:]]
        + ([] if cov is None else COV_HEADER)
        + ([] if printed is None else PRINTED_HEADER)
    )
    _write_table(path, data, " ", header, "# ")


def write_trajectory(path, traj: Trajectory, fmt: str) -> None:
    """Write a trajectory in one of the formats the readers take (lossless ``%.17g`` numbers):
    ``tum``; ``euroc`` (integer nanoseconds, ``qw`` first); ``kitti`` (3x4 poses, stamps in
    ``<name>_times.txt`` beside it, evo's naming); ``openvins`` (TUM + the orientation and position
    covariance upper triangles; only for a trajectory with covariance); ``csv`` (named columns, with
    covariance columns when it has them); ``position`` (``t x y z``, any trajectory's positions). A
    position-only trajectory is written as ``position`` or ``csv`` (``t,x,y,z``) only."""
    path = Path(path)
    if fmt == "position" or (fmt == "csv" and traj.position_only):
        return _write_positions(path, traj, fmt)
    if traj.position_only and fmt in FORMATS:  # never a NaN quaternion in a file for a user
        raise EpaError(
            f"this trajectory is position-only (no orientation) and the {fmt} format holds"
            " orientations; write position (t x y z) or csv",
            path=str(path),
        )
    cov = _cov_columns(traj)
    # never invent an uncertainty the estimator did not report
    if fmt == "openvins" and cov is None:
        raise EpaError(
            "the OpenVINS format holds covariance and this trajectory has none; write tum or csv",
            path=str(path),
        )
    # write_tum adds the covariance columns (OpenVINS's layout) when there are some
    if fmt in ("tum", "openvins"):
        return write_tum(path, traj)
    if fmt == "kitti":
        m = np.concatenate([traj.r_as_printed, traj.p[:, :, None]], axis=2).reshape(len(traj), 12)
        _atomic_write(path.with_name(path.stem + "_times.txt"), lambda fh: savetxt(fh, traj.t))
        return _atomic_write(path, lambda fh: savetxt(fh, m))
    if fmt == "euroc":
        ns = np.round(traj.t * 1e9).astype(np.int64)
        rows = np.column_stack([traj.p, traj.q[:, [3, 0, 1, 2]]])
        return _atomic_write(
            path,
            lambda fh: fh.write(
                EUROC_HEADER
                + "\n"
                + "".join(
                    f"{a}," + ",".join(EXACT % v for v in row) + "\n" for a, row in zip(ns, rows)
                )
            ),
        )
    data = np.column_stack([traj.t, traj.p, traj.q] + ([] if cov is None else [cov]))
    if fmt == "csv":
        names = ["t", "x", "y", "z", "qx", "qy", "qz", "qw"] + ([] if cov is None else COV_HEADER)
        return _atomic_write(
            path,
            lambda fh: savetxt(fh, data, delimiter=",", header=",".join(names), comments=""),
        )
    raise EpaError(
        f"unknown format {fmt!r}; choose one of {', '.join(FORMATS[1:])}", path=str(path)
    )


def _write_positions(path: Path, traj: Trajectory, fmt: str) -> None:
    """``t x y z`` rows (``position``), or the same under a ``t,x,y,z`` header (``csv``)."""
    data = np.column_stack([traj.t, traj.p])
    if fmt == "csv":
        return _atomic_write(
            path, lambda fh: savetxt(fh, data, delimiter=",", header="t,x,y,z", comments="")
        )
    return _atomic_write(path, lambda fh: savetxt(fh, data))


# pandas' C parser costs about 1 ms a call, loadtxt about 0.25 ms plus 3.5 ms per 100 KB: the same
# doubles, so the faster one for the file's size. pyarrow's reader (text.parsers_for: where installed,
# from 32 KB on once imported, as in the workers, whose pandas imports it) is tried before either:
# 0.6 ms a call, 1.4-2x faster than pandas' (2.5 ms against 4.0 at 1 MB, 34 against 47 at 8 MB).
PANDAS_FROM_BYTES = 64_000


def _numbers(path, delimiter: str, skip: int) -> np.ndarray:
    """The numbers of an artifact this project wrote (``#`` comments, ``skip`` header lines): by
    pyarrow's reader or pandas' C parser where the process chose it (workflow workers preload
    pandas; 3-4x faster than loadtxt on large files, the same doubles) and the file is not small,
    else by numpy."""
    size = os.path.getsize(path)
    # pandas only where the process chose it (size + 1: never)
    parsers = text.parsers_for(size, PANDAS_FROM_BYTES if runtime.pandas_parser() else size + 1)
    rows = _arrow_numbers(path, delimiter, skip) if "arrow" in parsers else None
    if rows is not None:
        return rows
    if "pandas" in parsers:
        import pandas as pd

        try:
            frame = pd.read_csv(
                path, sep=delimiter, header=None, skiprows=skip, comment="#", dtype=float
            )
        except pd.errors.EmptyDataError:  # a header and no rows is an empty table
            return np.zeros((0, 0))
        return text.frame_rows(frame)  # row-major, like loadtxt's
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a header and no rows: an empty table
        return np.loadtxt(
            path,
            delimiter=delimiter if delimiter != " " else None,
            skiprows=skip,
            ndmin=2,
            comments="#",
        )


def _arrow_numbers(path, delimiter: str, skip: int) -> np.ndarray | None:
    """pyarrow's rows of an artifact after its ``skip`` lines and leading ``#`` lines, or None where
    another parser must decide (a comment further on, no rows, a value that is not finite)."""
    with open(path, "rb") as fh:
        data = fh.read()
    offset = 0
    for _ in range(skip):
        offset = data.find(b"\n", offset) + 1 or len(data)
    while data.startswith(b"#", offset):
        offset = data.find(b"\n", offset) + 1 or len(data)
    end = data.find(b"\n", offset)
    if offset >= len(data) or data.find(b"#", offset) >= 0:
        return None
    width = data.count(delimiter.encode(), offset, end if end >= 0 else len(data)) + 1
    return text.arrow_rows(data, offset, width, delimiter)


def read_tum_file(path) -> Trajectory:
    """Read a TUM artifact this project wrote (no detection, no repair)."""
    rows = _numbers(path, " ", skip=0)
    cov, printed = _WIDTH.get(rows.shape[1], (False, False))  # the columns write_tum wrote
    extra: dict[str, np.ndarray] = {}
    if cov:
        extra.update(cov_rot=upper_to_full(rows[:, 8:14]), cov_pos=upper_to_full(rows[:, 14:20]))
    if printed:
        extra["r_printed"] = np.ascontiguousarray(rows[:, -9:]).reshape(len(rows), 3, 3)
    # arrays of their own: views would keep the whole table for as long as the trajectory is cached
    t, p, q = (np.ascontiguousarray(rows[:, k]) for k in (0, slice(1, 4), slice(4, 8)))
    return Trajectory(t, p, q, **extra)


def write_pair_indices(path, i_ref, i_est, t_ref, t_est) -> None:
    """Matched pairs as row indices into the cropped reference and estimate (02_crop/*.tum, first
    pose = 0), with both stamps for reading by eye."""
    write_csv(path, {"i_ref": i_ref, "i_est": i_est, "t_ref": t_ref[i_ref], "t_est": t_est[i_est]})


def read_pair_indices(path) -> tuple[np.ndarray, np.ndarray]:
    cols = read_csv(path)
    return cols["i_ref"].astype(np.intp), cols["i_est"].astype(np.intp)


def write_csv(path, columns: dict[str, np.ndarray], fmt: str = EXACT) -> None:
    names = list(columns)
    data = (
        np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
        if names
        else np.zeros((0, 0))
    )
    _write_table(path, data.reshape(-1, len(names)), ",", ",".join(names), "", fmt)


def read_csv(path) -> dict[str, np.ndarray]:
    kept = getattr(_ONCE, "kept", None)
    if kept is None:
        return _read_csv(path)
    st = os.stat(path)
    key = (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size)  # a rewrite is another file
    if key not in kept:
        kept[key] = _read_csv(path, read_only=True)
    return dict(kept[key])


def _read_csv(path, read_only: bool = False) -> dict[str, np.ndarray]:
    with open(path, encoding="utf-8") as fh:
        names = fh.readline().strip().split(",")
    rows = _numbers(path, ",", skip=1)
    if rows.size == 0:
        rows = np.zeros((0, len(names)))
    if read_only:
        rows.setflags(write=False)  # and so every column (a view)
    return {n: rows[:, k] for k, n in enumerate(names)}


# The tables read while tables_once() is active in this thread, by file (read-only: no reader changes
# what another reads). The report stage reads 06_metrics/rpe_segments.csv twice (its RPE box
# bundle and its grid samples).
_ONCE = threading.local()


@contextmanager
def tables_once():
    """While inside, :func:`read_csv` parses each file once (this thread; nested: the outer scope)."""
    if getattr(_ONCE, "kept", None) is not None:
        yield
        return
    _ONCE.kept = {}
    try:
        yield
    finally:
        _ONCE.kept = None
