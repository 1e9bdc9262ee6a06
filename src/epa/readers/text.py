"""Text trajectory files: TUM, KITTI 3x4, EuRoC/ASL CSV, OpenVINS (TUM + covariance) and any CSV
whose header names its columns.

A file is read into a :class:`~epa.readers.table.Table` (here: its parse paths), then built into a
:class:`~epa.core.trajectory.Trajectory` by its format's builder (:mod:`epa.readers.formats`), the
format told by :mod:`epa.readers.detect` when it is not given. Every reader returns seconds with unit
quaternions, or raises :class:`~epa.core.errors.EpaError` naming the file, the line and what is wrong.

The parse paths, fastest first: a parser in C on the file's own bytes (:func:`_read_in_c`):
pyarrow's CSV reader where it is installed (one space, comma or semicolon between fields), else
pandas' C parser (any whitespace); the same parsers on the decoded body (a byte-order mark,
comments beyond the head); numpy's ``loadtxt`` (small files, other separators, comments); and the
line-by-line reader that names a bad line (:func:`_diagnose`). They give the same doubles, bit for
bit.
"""

from __future__ import annotations

import importlib.util
import logging
import stat
import warnings
from pathlib import Path
from typing import NoReturn

import numpy as np

from epa.core import runtime
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers.checks import (
    MAX_POSITION_M,
    Unordered,
    beyond_reach,
    disorder,
    in_order,
    sort_unique,
)
from epa.readers.detect import FORMAT_SETTINGS, check_text, detect_format
from epa.readers.formats import (
    FORMATS,
    NS_THRESHOLD,
    QUAT_NORM_TOL,
    READERS,
    TIME_UNITS,
    kitti_times_for,
    read_euroc,
    read_kitti,
    read_named_csv,
    read_openvins,
    read_tum,
    upper_to_full,
)
from epa.readers.header import scan_header
from epa.readers.table import Table, is_number, split_fields

# the names other modules have used from here since before the split, kept in place
__all__ = [
    "ARROW_IMPORTED_MIN_BYTES",
    "ARROW_MIN_BYTES",
    "C_PARSER_MIN_BYTES",
    "FORMATS",
    "FORMAT_SETTINGS",
    "MAX_POSITION_M",
    "NS_THRESHOLD",
    "QUAT_NORM_TOL",
    "READERS",
    "TIME_UNITS",
    "Table",
    "TableAhead",
    "Unordered",
    "arrow_rows",
    "beyond_reach",
    "detect_format",
    "disorder",
    "frame_rows",
    "in_order",
    "kitti_times_for",
    "parsers_for",
    "read_euroc",
    "read_kitti",
    "read_named_csv",
    "read_openvins",
    "read_table",
    "read_trajectory",
    "read_tum",
    "sort_unique",
    "upper_to_full",
]

log = logging.getLogger(__name__)

# From this size on, a file pyarrow does not take is parsed by pandas' C parser: 3-4x faster than
# numpy's loadtxt (0.10 s against 0.37 s for a 100k-pose TUM file; same doubles, bit for bit), worth
# its 0.2-0.5 s import for a file of about 120,000 poses or more (at 4 MB, a 200 Hz EuRoC reference,
# a loop of `epa eval` spent 0.5 s a case importing it). A caller that has imported pandas passes 0.
C_PARSER_MIN_BYTES = 12_000_000
# From this size on, pyarrow's reader (where installed) is tried first: its import costs 0.04 s, its
# parse 2.5-4 ms a MB against loadtxt's 20-28; in a new process import and parse take 50 ms at 2 MB
# (loadtxt 43-68), 42 at 4 MB (78), 55 at 8 MB (162). Once imported (pandas imports it too), it
# beats loadtxt from about 20 KB on (0.5 ms against 1.8 at 64 KB; 0.6-0.7 against 0.25 at 10 KB).
ARROW_MIN_BYTES = 2_000_000
ARROW_IMPORTED_MIN_BYTES = 32_000
HEAD_CHARS = 1 << 16  # the header is looked for in the first 64 KB, the whole file only if need be


# ----------------------------------------------------------------------------- text parsing
def read_table(path: Path, *, c_parser_min_bytes: int = C_PARSER_MIN_BYTES) -> Table:
    """The numeric rows of a text file, its header and where each row is, for the builders.
    ``c_parser_min_bytes``: files of this size or larger are parsed by pandas' C parser (importing
    pandas), where it takes them whole; smaller ones by numpy's loadtxt. Same doubles either way."""
    try:
        # a pipe or /dev/zero would never end
        if not stat.S_ISREG(path.stat().st_mode) and not path.is_dir():
            raise EpaError("not a regular file (a device, pipe or socket)", path=str(path))
        data = path.read_bytes()
    except FileNotFoundError:
        raise EpaError("file not found", path=str(path)) from None
    except IsADirectoryError:
        raise EpaError("is a directory, expected a trajectory file", path=str(path)) from None
    except OSError as exc:
        raise EpaError(f"cannot read: {exc.strerror}", path=str(path)) from None
    check_text(path, data[:4096])
    parsers = parsers_for(len(data), c_parser_min_bytes)
    whole, refused = _read_in_c(path, data, parsers) if parsers else (None, False)
    if whole is not None:
        return whole
    try:
        text, raw_bytes = data.decode("utf-8"), data
    except UnicodeDecodeError:  # read as far as it goes; the parse names the line
        text, raw_bytes = data.decode("utf-8", errors="replace"), None
    if text.startswith("\ufeff"):  # a byte-order mark (spreadsheet exports) is not part of the data
        text, raw_bytes = text[1:], None if raw_bytes is None else raw_bytes[3:]
    raw = _head_lines(text, len(text) > HEAD_CHARS)
    found = scan_header(path, raw)
    if found[0] == len(raw) and len(text) > HEAD_CHARS:  # comments beyond the head: whole file
        raw = text.splitlines(keepends=True)
        found = scan_header(path, raw)
    return _read_body(path, text, raw, found, raw_bytes, parsers=() if refused else parsers)


class TableAhead(runtime.Background[Table]):
    """:func:`read_table` of a file started in a thread, for a caller with a spare core
    (:func:`epa.core.runtime.spare_thread`): reading the bytes, pyarrow's parse and numpy's copies
    release the GIL, so it runs beside the caller's own work (`epa eval`: the estimate's 15 MB parse
    beside the reference's). :meth:`result` waits for it and gives the table, or raises its error
    as read_table would have raised it there. ``after``: a table read first, in this order (so each
    file gets the parser it would get read after it: :func:`parsers_for`)."""

    def __init__(
        self,
        path: Path,
        c_parser_min_bytes: int = C_PARSER_MIN_BYTES,
        after: TableAhead | None = None,
    ) -> None:
        self.path = path

        def read() -> Table:
            if after is not None:
                after.join()
            return read_table(path, c_parser_min_bytes=c_parser_min_bytes)

        super().__init__(read, "epa-read-ahead")


def tables_ahead(
    paths: list[Path], c_parser_min_bytes: int = C_PARSER_MIN_BYTES
) -> list[TableAhead]:
    """:class:`TableAhead` of each of ``paths`` (regular files), each in a thread of its own where
    every one is pyarrow's to parse whatever is read first (two 15 MB files: 0.03-0.05 s less where
    two cores are free), else one after another in the order given (each file's parser as reading
    them in that order would choose it)."""
    sizes = []
    for path in paths:
        try:
            sizes.append(path.stat().st_size)
        except OSError:  # gone since: its reader says so, in order
            sizes.append(0)
    alone = all("arrow" in parsers_for(size, c_parser_min_bytes) for size in sizes)
    tables: list[TableAhead] = []
    for path in paths:
        after = None if alone or not tables else tables[-1]
        tables.append(TableAhead(path, c_parser_min_bytes, after=after))
    return tables


# whether pyarrow is installed (looked up once, 0.1 ms) and whether epa has imported it (only when a
# file needs it): the parser follows from these and the file's size, never from what else the
# process happens to have imported
_ARROW: dict[str, bool] = runtime.register("readers.text.arrow", {})


def use_arrow() -> bool:
    """Import pyarrow's reader now, for a process that reads many artifacts (the workflow's
    workers, the tables script): from ARROW_IMPORTED_MIN_BYTES on it is then tried first, not only
    after a first file of ARROW_MIN_BYTES (a grid of short cases never has one, and read its 32 KB
    to 2 MB artifacts with pandas or loadtxt, 1.5-6x slower). False where it is not installed."""
    try:
        import pyarrow.csv  # noqa: F401
    except ImportError:
        return False
    _ARROW["imported"] = True
    return True


def parsers_for(size: int, pandas_min_bytes: int) -> tuple[str, ...]:
    """The parsers in C worth their cost for a file of ``size`` bytes, in the order tried: "arrow"
    (where installed; from 32 KB on once epa imported it, else from 2 MB on), then "pandas" (from
    ``pandas_min_bytes`` on). None of them: numpy's loadtxt. The same doubles whichever parses."""
    if "installed" not in _ARROW:
        _ARROW["installed"] = importlib.util.find_spec("pyarrow") is not None
    least = ARROW_IMPORTED_MIN_BYTES if _ARROW.get("imported") else ARROW_MIN_BYTES
    arrow = _ARROW["installed"] and size >= least
    return ("arrow",) * bool(arrow) + ("pandas",) * (size >= pandas_min_bytes)


def _head_lines(text: str, cut: bool) -> list[str]:
    """The header is in the first lines: only those are split (the whole file only on error).
    ``cut``: the file goes on beyond ``text[:HEAD_CHARS]``, whose last line may be incomplete."""
    raw = text[:HEAD_CHARS].splitlines(keepends=True)
    return raw[:-1] if cut else raw


def _read_in_c(path: Path, data: bytes, parsers: tuple[str, ...]) -> tuple[Table | None, bool]:
    """A file the C parser takes whole, read without decoding or copying its body (0.4 s of a
    million-pose file's 1.3 s): only the head is decoded, to find the header; the body's text is
    decoded only if a later check names a line. (None, refused) wherever the general path must
    decide (a byte-order mark, comments beyond the head, a body the C parser refused: ``refused``,
    so that it is not parsed again), which then reads the file as before and says what is wrong.
    ``parsers``: as :func:`parsers_for` returns them."""
    if data.startswith(b"\xef\xbb\xbf"):
        return None, False
    head = data[:HEAD_CHARS]
    try:
        head_text = head.decode("utf-8")
    except UnicodeDecodeError as exc:  # a character cut by the head's end is fine; else not here
        if len(data) <= HEAD_CHARS or exc.start < len(head) - 3:
            return None, False
        head_text = head[: exc.start].decode("utf-8")
    raw = _head_lines(head_text, len(data) > HEAD_CHARS)
    start, header, header_line = scan_header(path, raw)
    if start == len(raw) or (";" in raw[start] and "," in raw[start]):
        return None, False
    offset = len("".join(raw[:start]).encode("utf-8"))
    rows = _c_parser_rows(data, offset, len(split_fields(raw[start])), parsers)
    if rows is None:
        return None, True
    tab = Table(path, np.zeros((0, 0)), (data, offset), start + 1, header)
    return _checked(tab, rows, header, header_line), False


def _read_body(
    path: Path,
    text: str,
    raw: list[str],
    found,
    raw_bytes=None,
    parsers: tuple[str, ...] = (),
) -> Table:
    """``raw_bytes``: the file's bytes as ``text`` decodes (None after a decoding error): the C
    parser takes the body's bytes from it, not re-encoded from the text (0.2 s a million poses).
    ``parsers``: the parsers in C to try (:func:`parsers_for`), none: numpy's."""
    start, header, header_line = found
    head = "".join(raw[:start])
    body_text = text[len(head) :]
    first = raw[start] if start < len(raw) else ""
    if ";" in first and "," in first:
        raise EpaError(
            "fields separated by ';' with ',' inside: decimal commas are not supported (export"
            " with '.' as the decimal separator)",
            path=str(path),
            line=start + 1,
        )
    tab = Table(path, np.zeros((0, 0)), body_text, start + 1, header)
    rows = None
    if parsers:  # (a body is encoded only if so)
        data, offset = (
            (body_text.encode("utf-8"), 0)
            if raw_bytes is None
            else (raw_bytes, len(head.encode("utf-8")))
        )
        rows = _c_parser_rows(data, offset, len(split_fields(first)), parsers)
    if rows is not None:
        return _checked(tab, rows, header, header_line)
    body = body_text.splitlines()
    parse = (
        [line.replace(",", " ").replace(";", " ") for line in body]
        if ("," in first or ";" in first)
        else body
    )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": said below
            # one comment character keeps numpy on its C path; "%" comments are rare, so pay only then
            comments = ("#", "%") if "%" in text else "#"
            rows = np.loadtxt(parse, ndmin=2, dtype=float, comments=comments)
    except ValueError:
        _diagnose(tab)
    return _checked(tab, rows, header, header_line)


def _checked(tab: Table, rows: np.ndarray, header, header_line) -> Table:
    path = tab.path
    if rows.size == 0:
        raise EpaError("no data rows (the file is empty or holds only comments)", path=str(path))
    if header_line is not None and len(header) != rows.shape[1]:
        raise EpaError(
            f"the header names {len(header)} columns but the rows have {rows.shape[1]}",
            path=str(path),
            line=header_line,
        )
    bad = ~np.isfinite(rows)
    if bad.any():
        tab.fail(int(np.argmax(bad.any(axis=1))), "non-finite value (nan or inf)")
    tab.rows = rows
    return tab


def _c_parser_rows(
    data: bytes, offset: int, width: int, parsers: tuple[str, ...]
) -> np.ndarray | None:
    """Rows of ``width`` numbers, ``data[offset:]`` parsed at once in C (without copying it), or
    None where the line-by-line reader must decide (and say which line is wrong): comments, a line
    with another number of fields or separator, or anything that is not a finite number.
    ``parsers`` in order: "arrow", pyarrow's reader (where installed; one space, comma or semicolon
    between fields, as the first row has them), "pandas", pandas' C parser (whitespace only): the
    same doubles, bit for bit."""
    if offset >= len(data) or width == 0:
        return None
    rows = None
    if "arrow" in parsers:  # it refuses a comment, a separator other than the first row's
        end = data.find(b"\n", offset)
        first = data[offset : end if end >= 0 else len(data)]
        rows = arrow_rows(
            data, offset, width, "," if b"," in first else ";" if b";" in first else " "
        )
    if rows is None and "pandas" in parsers and all(data.find(c, offset) < 0 for c in b",;#%"):
        rows = _pandas_rows(data, offset, width)
    return rows


def arrow_rows(data: bytes, offset: int, width: int, delimiter: str = " ") -> np.ndarray | None:
    """``data[offset:]``'s rows of ``width`` numbers by pyarrow's CSV reader, fields separated by one
    ``delimiter``, no quotes, no comments (its import costs 0.04 s where pandas' costs 0.2-0.35 s;
    it parses 1.4-2x faster than pandas). None where pyarrow is not installed, or refuses the body
    (runs of spaces, tabs, a short line, a word: another parser then decides), or reads a value that
    is not finite ("nan", "1e500", and "nan(1)", which the others refuse)."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:
        return None
    _ARROW["imported"] = True
    names = [f"c{k}" for k in range(width)]
    try:
        table = pacsv.read_csv(
            pa.BufferReader(pa.py_buffer(data).slice(offset)),  # shares the bytes
            read_options=pacsv.ReadOptions(column_names=names, use_threads=False),
            parse_options=pacsv.ParseOptions(
                delimiter=delimiter, quote_char=False, escape_char=False
            ),
            convert_options=pacsv.ConvertOptions(
                column_types=dict.fromkeys(names, pa.float64()),
                null_values=[],  # an empty field or "NA" is refused, not a null
                strings_can_be_null=False,
            ),
        )
    except (pa.ArrowException, ValueError):
        return None
    if table.num_rows == 0 or any(c.null_count for c in table.columns):
        return None
    # the float64 buffers as they are (to_numpy() would import pandas), copied row-major a batch of
    # rows at a time (each in cache, as frame_rows), stacked then transposed: 0.05 s for a million
    # 20-column rows where stacking along the rows took 0.1 s
    rows = np.empty((table.num_rows, width))
    start = 0
    for batch in table.to_batches():
        stop = start + batch.num_rows
        columns = [
            np.frombuffer(c.buffers()[1], np.float64, count=len(c), offset=c.offset * 8)
            for c in batch.columns
        ]
        rows[start:stop] = np.stack(columns).T
        start = stop
    return rows if np.isfinite(rows).all() else None


def _pandas_rows(data: bytes, offset: int, width: int) -> np.ndarray | None:
    """pandas' C parser: one space between fields, else any whitespace (runs of spaces, tabs,
    leading or trailing blanks)."""
    import io

    import pandas as pd

    for sep in (" ", r"\s+"):  # one space (most files: the fastest path), else any whitespace
        body = io.BytesIO(data)  # shares the bytes; the parser reads from the body's start
        body.seek(offset)
        try:
            # quoting off (3, csv.QUOTE_NONE): a quoted number is refused, as loadtxt refuses it
            frame = pd.read_csv(body, sep=sep, header=None, dtype=float, engine="c", quoting=3)
        except (ValueError, pd.errors.ParserError):
            continue
        if frame.shape[1] != width:
            continue
        rows = frame_rows(frame)
        # a short line reads as NaN: the line-by-line reader names it
        if np.isfinite(rows).all():
            return rows
    return None


FRAME_CHUNK = 16384  # rows per block in frame_rows: a few MB, in cache


def frame_rows(frame) -> np.ndarray:
    """A pandas frame's numbers, row-major as the rest expects (numpy's sums over a column depend on
    the memory layout): one copy where to_numpy() and a contiguous copy of it were two (0.4 s and
    160 MB for a million poses with covariance), made block by block of rows (each column's stretch
    stacked in cache: 2.5x faster than writing whole columns into strided memory)."""
    columns = [frame.iloc[:, k].to_numpy() for k in range(frame.shape[1])]
    rows = np.empty(frame.shape)
    for start in range(0, len(rows), FRAME_CHUNK):
        stop = start + FRAME_CHUNK
        rows[start:stop] = np.stack([c[start:stop] for c in columns], axis=1)
    return rows


def _diagnose(tab: Table) -> NoReturn:
    """The numeric parse failed: find the first offending line, slowly, for the error message."""
    data, numbers = tab.data_lines()
    width = len(split_fields(data[0]))
    for s, no in zip(data, numbers):
        toks = split_fields(s)
        for tok in toks:  # a word says more than a column count ("oops", a pasted header)
            if not is_number(tok):
                raise EpaError(f"not a number: {tok!r}", path=str(tab.path), line=no)
        if len(toks) != width:
            raise EpaError(
                f"expected {width} columns like the first data row, found {len(toks)}",
                path=str(tab.path),
                line=no,
            )
    first = _separator(data[0])
    for s, no in zip(data, numbers):  # the rows parse alone but not together: mixed separators
        if first == "spaces" and _separator(s) != first:  # (commas first: every row's are read)
            raise EpaError(
                f"fields separated by {_separator(s)} where the first data row (line {numbers[0]})"
                f" separates them by {first}: use one separator throughout",
                path=str(tab.path),
                line=no,
            )
    for s, no in zip(data, numbers):  # else the first row numpy itself refuses, with its reason
        try:
            np.loadtxt([s], ndmin=2, dtype=float, comments=("#", "%"))
        except ValueError as exc:
            reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else "unreadable"
            raise EpaError(f"cannot read the row: {reason}", path=str(tab.path), line=no) from None
    raise EpaError("could not parse the numeric rows", path=str(tab.path))


def _separator(line: str) -> str:
    return "';'" if ";" in line else ("','" if "," in line else "spaces")


# ----------------------------------------------------------------------------- trajectories
def read_trajectory(
    path,
    fmt: str = "auto",
    *,
    time_unit: str = "auto",
    on_unsorted: str = "error",
    kitti_rate: float = 10.0,
    kitti_times=None,
    kitti_printed: bool = False,
    notes: list | None = None,
    c_parser_min_bytes: int = C_PARSER_MIN_BYTES,
    printed_quaternions: bool = False,
    table: TableAhead | None = None,
) -> Trajectory:
    """Read any supported trajectory file into seconds and unit quaternions. Every interpretation the
    file did not state (detected format, nanoseconds, sorting, KITTI times) is logged as a warning
    and appended to ``notes``. ``kitti_printed`` also keeps KITTI's printed rotation blocks (evo's
    commands compute on them). ``c_parser_min_bytes``: as :func:`read_table`'s.
    ``printed_quaternions``: the quaternions as the file prints them, not normalised (a second read
    of a file for the ETH3D protocol: its notes are not logged again). ``table``: the file's
    :func:`read_table` already started (:class:`TableAhead` of ``path``), taken instead of reading."""
    path = Path(path)
    if fmt not in FORMATS:
        raise EpaError(
            f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}", path=str(path)
        )
    tab = (
        read_table(path, c_parser_min_bytes=c_parser_min_bytes) if table is None else table.result()
    )
    detected = []  # a detected format is a note, not a warning: it is routine
    if fmt == "auto":
        fmt = detect_format(path, tab)
        detected.append(
            f"format {fmt} ({tab.rows.shape[1]} columns{', header names them' if fmt == 'csv' else ''})"
        )
    times = None
    if fmt == "kitti":
        tpath = Path(kitti_times) if kitti_times else kitti_times_for(path)
        if tpath is not None:
            times = read_table(tpath, c_parser_min_bytes=c_parser_min_bytes).rows[:, 0]
            tab.notes.append(f"KITTI stamps from {tpath.name}")
        else:
            tab.notes.append(f"KITTI stamps at {kitti_rate} Hz (no times file; load.kitti_rate)")
    traj = READERS[fmt](
        tab,
        time_unit=time_unit,
        on_unsorted=on_unsorted,
        times=times,
        rate=kitti_rate,
        keep_printed=kitti_printed,
        printed_quaternions=printed_quaternions,
    )
    if len(traj) < 2:
        raise EpaError(f"only {len(traj)} pose(s); at least 2 are needed", path=str(path))
    for note in () if printed_quaternions else tab.notes:
        log.warning("%s: %s", path, note)
    if notes is not None:
        notes.extend(detected + tab.notes)
    return traj
