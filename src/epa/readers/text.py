"""Text trajectory files: TUM, KITTI 3x4, EuRoC/ASL CSV, OpenVINS (TUM + covariance) and any CSV
whose header names its columns. Parsing, format detection and every reader live here.

Every reader returns a :class:`~epa.core.trajectory.Trajectory` in seconds with unit quaternions, or
raises :class:`~epa.core.errors.EpaError` naming the file, the line and what is wrong. A new format is
one reader function registered in ``READERS``.
"""

from __future__ import annotations

import logging
import re
import stat
import sys
import warnings
from pathlib import Path

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory

log = logging.getLogger("epa")

FORMATS = ("auto", "tum", "kitti", "euroc", "openvins", "csv")
TIME_UNITS = ("auto", "s", "ns", "sec_nsec")
# A stamp this large cannot be seconds (it would be ~30,000 years); it is nanoseconds.
NS_THRESHOLD = 1e12
# Farther than this from the origin is no trajectory (the Moon is 4e8 m away); squares of it still fit
# a float64 comfortably, so metrics never overflow.
MAX_POSITION_M = 1e9
# A quaternion printed with 4+ digits is unit to ~1e-4; beyond this it was not meant to be unit.
QUAT_NORM_TOL = 1e-2


# ----------------------------------------------------------------------------- text parsing
class _Table:
    """Numeric rows of a text file. The file line of each row and the raw row text are derived
    only when needed (an error message, the sec.nsec repair), so the common path stays in C."""

    def __init__(
        self,
        path: Path,
        rows: np.ndarray,
        body: str | tuple[bytes, int],
        first_line: int,
        header: list[str] | None,
    ):
        self.path, self.rows, self.header = path, rows, header
        self.notes: list[str] = []  # every interpretation made that the file did not state
        # the file's text from the first data row on (split into lines only when needed); or the
        # file's bytes and where that row starts, decoded only when a line must be named
        self._body, self._first_line = body, first_line

    def data_lines(self) -> tuple[list[str], list[int]]:
        """The data rows' text and their 1-based file line numbers (comments and blanks skipped)."""
        if isinstance(self._body, tuple):
            data, offset = self._body
            self._body = data[offset:].decode("utf-8", errors="replace")
        text, numbers = [], []
        for no, line in enumerate(self._body.splitlines(), start=self._first_line):
            s = line.strip()
            if s and s[0] not in "#%":
                text.append(s)
                numbers.append(no)
        return text, numbers

    def line_of(self, row: int) -> int:
        return self.data_lines()[1][row]

    def fail(self, row: int | None, message: str):
        raise EpaError(
            message, path=str(self.path), line=None if row is None else self.line_of(row)
        )


def _split(line: str) -> list[str]:
    return line.replace(",", " ").replace(";", " ").split()


def _header_names(line: str) -> list[str]:
    """Column names of a header line: comma-separated if it has commas, else whitespace-separated."""
    body = line.lstrip("#%").strip()
    return [h.strip() for h in (body.split(",") if "," in body else body.split()) if h.strip()]


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def read_table(path: Path) -> _Table:
    try:
        if (
            not stat.S_ISREG(path.stat().st_mode) and not path.is_dir()
        ):  # a pipe or /dev/zero would never end
            raise EpaError("not a regular file (a device, pipe or socket)", path=str(path))
        data = path.read_bytes()
    except FileNotFoundError:
        raise EpaError("file not found", path=str(path)) from None
    except IsADirectoryError:
        raise EpaError("is a directory, expected a trajectory file", path=str(path)) from None
    except OSError as exc:
        raise EpaError(f"cannot read: {exc.strerror}", path=str(path)) from None
    _check_text(path, data[:4096])
    whole, refused = _read_in_c(path, data)
    if whole is not None:
        return whole
    try:
        text, raw_bytes = data.decode("utf-8"), data
    except UnicodeDecodeError:  # read as far as it goes; the parse names the line
        text, raw_bytes = data.decode("utf-8", errors="replace"), None
    if text.startswith("\ufeff"):  # a byte-order mark (spreadsheet exports) is not part of the data
        text, raw_bytes = text[1:], None if raw_bytes is None else raw_bytes[3:]
    raw = _head_lines(text, len(text) > HEAD_CHARS)
    found = _scan_header(path, raw)
    if found[0] == len(raw) and len(text) > HEAD_CHARS:  # comments beyond the head: whole file
        raw = text.splitlines(keepends=True)
        found = _scan_header(path, raw)
    return _read_body(path, text, raw, found, raw_bytes, try_c_parser=not refused)


HEAD_CHARS = 1 << 16


def _head_lines(text: str, cut: bool) -> list[str]:
    """The header is in the first lines: only those are split (the whole file only on error).
    ``cut``: the file goes on beyond ``text[:HEAD_CHARS]``, whose last line may be incomplete."""
    raw = text[:HEAD_CHARS].splitlines(keepends=True)
    return raw[:-1] if cut else raw


def _read_in_c(path: Path, data: bytes) -> tuple[_Table | None, bool]:
    """A file the C parser takes whole, read without decoding or copying its body (0.4 s of a
    million-pose file's 1.3 s): only the head is decoded, to find the header; the body's text is
    decoded only if a later check names a line. (None, refused) wherever the general path must
    decide (a byte-order mark, comments beyond the head, a body the C parser refused: ``refused``,
    so that it is not parsed again), which then reads the file as before and says what is wrong."""
    if not _c_parser_wanted(len(data)) or data.startswith(b"\xef\xbb\xbf"):
        return None, False
    head = data[:HEAD_CHARS]
    try:
        head_text = head.decode("utf-8")
    except UnicodeDecodeError as exc:  # a character cut by the head's end is fine; else not here
        if len(data) <= HEAD_CHARS or exc.start < len(head) - 3:
            return None, False
        head_text = head[: exc.start].decode("utf-8")
    raw = _head_lines(head_text, len(data) > HEAD_CHARS)
    start, header, header_line = _scan_header(path, raw)
    if start == len(raw) or (";" in raw[start] and "," in raw[start]):
        return None, False
    offset = len("".join(raw[:start]).encode("utf-8"))
    rows = _c_parser_rows(data, offset, len(_split(raw[start])))
    if rows is None:
        return None, True
    tab = _Table(path, np.zeros((0, 0)), (data, offset), start + 1, header)
    return _checked(tab, rows, header, header_line), False


def _scan_header(path: Path, raw: list[str]):
    """(first data line index, header names, header line) of a file's lines: leading comments and
    blank lines, and one uncommented header line; the last of them names the columns."""
    header: list[str] | None = None
    start, header_line = len(raw), None
    for k, line in enumerate(raw):
        s = line.strip()
        if not s:
            continue
        if s[0] not in "#%" and not _split(s):
            raise EpaError("a row of empty fields", path=str(path), line=k + 1)
        if s[0] in "#%":
            header = _header_names(s)
            continue
        if not _is_number(_split(s)[0]):
            if (
                header_line is not None
            ):  # two header rows (units, a pasted file): not a guess we make
                raise EpaError(
                    f"not a number: {_split(s)[0]!r} (a second header line; line {header_line} was"
                    " taken as the header)",
                    path=str(path),
                    line=k + 1,
                )
            header, header_line = _header_names(s), k + 1
            continue
        return k, header, header_line
    return start, header, header_line


def _read_body(
    path: Path, text: str, raw: list[str], found, raw_bytes=None, try_c_parser: bool = True
) -> _Table:
    """``raw_bytes``: the file's bytes as ``text`` decodes (None after a decoding error): the C
    parser takes the body's bytes from it, not re-encoded from the text (0.2 s a million poses)."""
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
    tab = _Table(path, np.zeros((0, 0)), body_text, start + 1, header)
    rows = None
    if try_c_parser and _c_parser_wanted(len(body_text)):  # (a body is encoded only if so)
        data, offset = (
            (body_text.encode("utf-8"), 0)
            if raw_bytes is None
            else (raw_bytes, len(head.encode("utf-8")))
        )
        rows = _c_parser_rows(data, offset, len(_split(first)))
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
            warnings.simplefilter(
                "ignore", UserWarning
            )  # "input contained no data": reported below
            # one comment character keeps numpy on its C path; "%" comments are rare, so pay only then
            comments = ("#", "%") if "%" in text else "#"
            rows = np.loadtxt(parse, ndmin=2, dtype=float, comments=comments)
    except ValueError:
        _diagnose(tab)
    return _checked(tab, rows, header, header_line)


def _checked(tab: _Table, rows: np.ndarray, header, header_line) -> _Table:
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


# From this size on, a body is parsed by pandas' C parser: 3-4x faster than numpy's loadtxt
# (0.10 s against 0.37 s for a 100k-pose TUM file; same doubles, bit for bit), worth its 0.5 s
# import for a file of about 120,000 poses or more (at 4 MB, a 200 Hz EuRoC reference, a loop of
# `epa eval` spent 0.5 s a case importing it); once pandas is imported (the workflow's workers
# preload it), for every file.
C_PARSER_MIN_CHARS = 12_000_000


def _c_parser_wanted(size: int) -> bool:
    return size >= C_PARSER_MIN_CHARS or "pandas" in sys.modules


def _c_parser_rows(data: bytes, offset: int, width: int) -> np.ndarray | None:
    """Rows of ``width`` whitespace-separated numbers, ``data[offset:]`` parsed at once in C (without
    copying it), or None where the line-by-line reader must decide (and say which line is wrong):
    other separators or comments, a line with another number of fields, or anything that is not a
    finite number."""
    if not _c_parser_wanted(len(data) - offset):
        return None
    if offset >= len(data) or width == 0 or any(data.find(c, offset) >= 0 for c in b",;#%"):
        return None
    import io

    import pandas as pd

    for sep in (" ", r"\s+"):  # one space (most files: the fastest path), else any whitespace
        body = io.BytesIO(data)  # shares the bytes; the parser reads from the body's start
        body.seek(offset)
        try:
            frame = pd.read_csv(body, sep=sep, header=None, dtype=float, engine="c")
        except (ValueError, pd.errors.ParserError):
            continue
        if frame.shape[1] != width:
            continue
        rows = frame_rows(frame)
        # a short line reads as NaN: the line-by-line reader names it
        if np.isfinite(rows).all():
            return rows
    return None


def frame_rows(frame) -> np.ndarray:
    """A pandas frame's numbers, row-major as the rest expects (numpy's sums over a column depend on
    the memory layout), filled column by column: one copy where to_numpy() and a contiguous copy of
    it were two (0.4 s and 160 MB for a million poses with covariance)."""
    rows = np.empty(frame.shape)
    for k in range(frame.shape[1]):
        rows[:, k] = frame.iloc[:, k].to_numpy()
    return rows


# Files that are not text trajectories, by their first bytes: say what they are.
_MAGIC = {
    b"\x1f\x8b": "gzip-compressed (decompress it first)",
    b"PK\x03\x04": "a zip archive (extract it first)",
    b"#ROSBAG": "a ROS 1 bag (give it as a bag source with a topic)",
    b"SQLite format 3": "an SQLite database (a ROS 2 bag's .db3: give the bag folder with a topic)",
    b"\x89MCAP": "an MCAP file (give it as a bag source with a topic)",
    b"\xff\xfe": "UTF-16 text (save it as UTF-8)",
    b"\xfe\xff": "UTF-16 text (save it as UTF-8)",
}


def _check_text(path: Path, head: bytes) -> None:
    for magic, what in _MAGIC.items():
        if head.startswith(magic):
            raise EpaError(f"{what}, not a text trajectory file", path=str(path))
    if b"\x00" in head or head.decode("utf-8", errors="replace").count("\ufffd") > 8:
        raise EpaError("binary data, not a text trajectory file", path=str(path))


def _diagnose(tab: _Table):
    """The numeric parse failed: find the first offending line, slowly, for the error message."""
    data, numbers = tab.data_lines()
    width = len(_split(data[0]))
    for s, no in zip(data, numbers):
        toks = _split(s)
        for tok in toks:  # a word says more than a column count ("oops", a pasted header)
            if not _is_number(tok):
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


# ----------------------------------------------------------------------------- column naming
def _norm_name(name: str) -> str:
    name = re.sub(r"\[.*?\]|\(.*?\)", "", name.lower()).strip().lstrip("#").strip()
    return name.replace(" ", "_")


_TIME_NAMES = {
    "t",
    "time",
    "timestamp",
    "timestamps",
    "stamp",
    "timestamp_kf",
    "sec",
    "time_s",
    "timestamp_ns",
}
_POS_RE = re.compile(r"^(?:p_rs_r_|p_|pos_|position_|t|p)?([xyz])$")
_QUAT_RE = re.compile(r"^(?:q_rs_|q_|q|quat_|orientation_|rot_)([xyzw])$")
_COV_NAMES = {
    "rot": (
        ["pr11", "pr12", "pr13", "pr22", "pr23", "pr33"],
        ["qrr", "qrp", "qry", "qpp", "qpy", "qyy"],
    ),
    "pos": (
        ["pt11", "pt12", "pt13", "pt22", "pt23", "pt33"],
        ["pxx", "pxy", "pxz", "pyy", "pyz", "pzz"],
    ),
}


def _named_columns(header: list[str] | None, width: int) -> dict | None:
    """Map a header to column indices, or None when it does not name a full pose."""
    if not header or len(header) != width:
        return None
    names = [_norm_name(h) for h in header]
    cols: dict = {}
    for k, n in enumerate(names):
        if "t" not in cols and (n in _TIME_NAMES or n.startswith("timestamp")):
            cols["t"] = k
            continue
        m = _QUAT_RE.match(n)
        if m and n not in ("x", "y", "z") and "q" + m.group(1) not in cols:
            cols["q" + m.group(1)] = k
            continue
        m = _POS_RE.match(n)
        if m and "p" + m.group(1) not in cols:
            cols["p" + m.group(1)] = k
    if not {"t", "px", "py", "pz", "qx", "qy", "qz", "qw"} <= cols.keys():
        return None
    cols["ns"] = any("[ns]" in h.lower() or h.lower().endswith("_ns") for h in header)
    for kind, alternatives in _COV_NAMES.items():
        for names6 in alternatives:
            if all(c in names for c in names6):
                cols["cov_" + kind] = [names.index(c) for c in names6]
    return cols


def upper_to_full(u: np.ndarray) -> np.ndarray:
    """(N, 6) upper triangles (11 12 13 22 23 33) -> (N, 3, 3) symmetric matrices."""
    idx = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
    return u[:, idx]


# ----------------------------------------------------------------------------- readers
def _finish(
    tab: _Table,
    t: np.ndarray,
    p: np.ndarray,
    q_xyzw: np.ndarray,
    *,
    time_unit: str,
    header_ns: bool = False,
    on_unsorted: str = "error",
    cov_rot=None,
    cov_pos=None,
) -> Trajectory:
    if time_unit == "sec_nsec":
        t = _sec_nsec(tab)
    elif time_unit == "ns" or (
        time_unit == "auto" and (header_ns or np.median(np.abs(t)) > NS_THRESHOLD)
    ):
        if time_unit == "auto" and not header_ns:  # decided by the median: all must agree
            _check_one_unit(tab, t, ns=True)
            tab.notes.append("stamps read as nanoseconds (above 1e12, so not seconds)")
        t = t / 1e9
    elif time_unit == "auto":
        _check_one_unit(tab, t, ns=False)
    _check_positions(tab, p)
    norms = np.linalg.norm(q_xyzw, axis=1)
    zero = norms < 1e-6
    if zero.any():
        tab.fail(int(np.argmax(zero)), "zero quaternion")
    off = np.abs(norms - 1).max()
    if (
        off > QUAT_NORM_TOL
    ):  # printed quaternions are unit to their digits; far off hints at wrong columns
        tab.notes.append(
            f"quaternions normalised (norm off by up to {off:.3g}; check the column order)"
        )
    q = q_xyzw / norms[:, None]
    traj = Trajectory(t, p, q, cov_rot=cov_rot, cov_pos=cov_pos)
    return _check_order(traj, tab, on_unsorted)


def _check_one_unit(tab: _Table, t: np.ndarray, *, ns: bool) -> None:
    """Stamps whose unit was told from their median: every one must be in that unit (a mix of
    seconds and nanoseconds would be sorted into nonsense)."""
    odd = (np.abs(t) <= NS_THRESHOLD) if ns else (np.abs(t) > NS_THRESHOLD)
    if odd.any():
        k = int(np.argmax(odd))
        if ns:
            tab.fail(
                k,
                f"timestamp {float(t[k])!r} is in seconds but most stamps are nanoseconds: the file mixes"
                " units (set load.time_unit if every stamp is in one unit)",
            )
        tab.fail(
            k,
            f"timestamp {float(t[k]):.0f} is in nanoseconds but most stamps are seconds: the file mixes units",
        )


def beyond_reach(p: np.ndarray) -> int | None:
    """The first pose farther than MAX_POSITION_M from the origin, or None."""
    huge = np.abs(p).max(axis=1, initial=0) > MAX_POSITION_M
    return int(np.argmax(huge)) if huge.any() else None


def _check_positions(tab: _Table, p: np.ndarray) -> None:
    k = beyond_reach(p)
    if k is not None:
        tab.fail(
            k,
            f"position {np.abs(p[k]).max():.3g} m is beyond {MAX_POSITION_M:.0e} m (a diverged or corrupt row)",
        )


def _sec_nsec(tab: _Table) -> np.ndarray:
    """Stamps written as sec.nsec with nsec not zero-padded (e.g. OKVIS): sec + int(frac)/1e9."""
    tokens = [_split(line)[0] for line in tab.data_lines()[0]]
    out = np.empty(len(tokens))
    for k, tok in enumerate(tokens):
        sec, _, frac = tok.partition(".")
        if not sec.isdigit() or (frac and not frac.isdigit()):
            tab.fail(k, f"timestamp {tok!r} is not of the form sec.nsec")
        out[k] = int(sec) + (int(frac) / 1e9 if frac else 0.0)
    return out


def disorder(t: np.ndarray) -> tuple[int, str] | None:
    """The first stamp that repeats or goes backwards, and which; None when strictly increasing."""
    dt = np.diff(t)
    if not (dt <= 0).any():
        return None
    k = int(np.argmax(dt <= 0)) + 1
    return k, "repeats" if dt[k - 1] == 0 else "goes backwards"


def sort_unique(traj: Trajectory) -> tuple[Trajectory, str]:
    """Sorted by stamp, the first of each repeat kept, and the note saying so."""
    order = np.argsort(traj.t, kind="stable")
    keep = np.concatenate([[True], np.diff(traj.t[order]) > 0])
    n_back, n_dup = int((np.diff(traj.t) < 0).sum()), int((~keep).sum())
    return traj.select(order[keep]), (
        f"{n_back} backward and {n_dup} repeated timestamps: sorted, kept the first of each repeat"
    )


class Unordered(Exception):
    """Stamps that repeat or go backwards where the rule is to stop: the first one (k) and which."""

    def __init__(self, k: int, what: str):
        super().__init__(what)
        self.k, self.what = k, what


def in_order(traj: Trajectory, on_unsorted: str) -> tuple[Trajectory, str | None]:
    """The trajectory under the ``unsorted`` rule, and the note of what was done (None: in order).
    ``sort``: sorted, the first of each repeat kept. ``keep`` (as evo reads files): repeated stamps
    stay in file order (stamps that go backwards still stop). Otherwise raises :class:`Unordered`."""
    bad = disorder(traj.t)
    if bad is None:
        return traj, None
    if on_unsorted == "keep" and not (np.diff(traj.t) < 0).any():
        return (
            traj,
            f"{int((np.diff(traj.t) == 0).sum())} repeated timestamps kept (unsorted: keep)",
        )
    if on_unsorted != "sort":
        raise Unordered(*bad)
    return sort_unique(traj)


def _check_order(traj: Trajectory, tab: _Table, on_unsorted: str) -> Trajectory:
    try:
        traj, note = in_order(traj, on_unsorted)
    except Unordered as bad:
        tab.fail(
            bad.k,
            f"timestamp {float(traj.t[bad.k])!r} {bad.what} (set load.unsorted: sort to sort and drop"
            " duplicates)",
        )
    if note is not None:
        tab.notes.append(note)
    return traj


def read_tum(tab: _Table, *, time_unit="auto", on_unsorted="error", **_) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] != 8:
        tab.fail(0, f"TUM needs 8 columns (t x y z qx qy qz qw), found {rows.shape[1]}")
    return _finish(
        tab, rows[:, 0], rows[:, 1:4], rows[:, 4:8], time_unit=time_unit, on_unsorted=on_unsorted
    )


def read_openvins(tab: _Table, *, time_unit="auto", on_unsorted="error", **_) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] != 20:
        tab.fail(0, f"OpenVINS needs 20 columns (TUM + 12 covariance), found {rows.shape[1]}")
    return _finish(
        tab,
        rows[:, 0],
        rows[:, 1:4],
        rows[:, 4:8],
        time_unit=time_unit,
        on_unsorted=on_unsorted,
        cov_rot=upper_to_full(rows[:, 8:14]),
        cov_pos=upper_to_full(rows[:, 14:20]),
    )


def read_euroc(tab: _Table, *, time_unit="auto", on_unsorted="error", **_) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] < 8:
        tab.fail(
            0, f"EuRoC CSV needs at least 8 columns (t x y z qw qx qy qz), found {rows.shape[1]}"
        )
    q = rows[:, [5, 6, 7, 4]]
    return _finish(tab, rows[:, 0], rows[:, 1:4], q, time_unit=time_unit, on_unsorted=on_unsorted)


def read_named_csv(tab: _Table, *, time_unit="auto", on_unsorted="error", **_) -> Trajectory:
    cols = _named_columns(tab.header, tab.rows.shape[1])
    if cols is None:
        raise EpaError(
            "the header does not name time, x, y, z, qx, qy, qz, qw columns"
            f" (header: {', '.join(tab.header or ['none'])})",
            path=str(tab.path),
        )
    rows = tab.rows
    cov = {
        k: upper_to_full(rows[:, cols["cov_" + k]]) for k in ("rot", "pos") if "cov_" + k in cols
    }
    return _finish(
        tab,
        rows[:, cols["t"]],
        rows[:, [cols["px"], cols["py"], cols["pz"]]],
        rows[:, [cols["qx"], cols["qy"], cols["qz"], cols["qw"]]],
        time_unit=time_unit,
        header_ns=cols["ns"],
        on_unsorted=on_unsorted,
        cov_rot=cov.get("rot"),
        cov_pos=cov.get("pos"),
    )


def read_kitti(
    tab: _Table,
    *,
    times: np.ndarray | None = None,
    rate: float = 10.0,
    keep_printed: bool = False,
    **_,
) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] != 12:
        tab.fail(0, f"KITTI needs 12 columns (3x4 row-major pose), found {rows.shape[1]}")
    n = len(rows)
    if times is None:
        t = np.arange(n) / float(rate)
    else:
        if len(times) != n:
            raise EpaError(f"times file has {len(times)} stamps for {n} poses", path=str(tab.path))
        t = np.asarray(times, float)
    m = rows.reshape(n, 3, 4)
    r = m[:, :, :3]
    det = np.linalg.det(r)
    bad = np.abs(det - 1) > 1e-2
    if bad.any():
        tab.fail(int(np.argmax(bad)), f"rotation block is not a rotation (det = {det[bad][0]:.4g})")
    # Project onto SO(3): KITTI files print about 7 digits, so R^T R is only approximately I.
    _check_positions(tab, m[:, :, 3])
    traj = Trajectory(
        t,
        m[:, :, 3].copy(),
        geometry.rot_to_quat(geometry.nearest_rotation(r)),
        r_printed=r.copy() if keep_printed else None,
    )
    return _check_order(traj, tab, "error")


READERS = {
    "tum": read_tum,
    "openvins": read_openvins,
    "euroc": read_euroc,
    "csv": read_named_csv,
    "kitti": read_kitti,
}


FORMAT_SETTINGS = "load.truth_format / load.estimate_format"


def detect_format(path: Path, tab: _Table) -> str:
    """The format when the file says it unambiguously; otherwise an error naming what was found.

    A header naming time, position and quaternion columns means ``csv``. A header of the file's
    width that names them otherwise (``t_s``, a byte-order mark, another language) is not guessed
    at. Without such a header: ``.csv`` with 8+ columns is EuRoC (``qw`` first), else 8 columns
    TUM, 12 KITTI, 20 OpenVINS."""
    width = tab.rows.shape[1]
    if _named_columns(tab.header, width) is not None:
        return "csv"
    if tab.header and len(tab.header) == width and not all(_is_number(h) for h in tab.header):
        raise EpaError(
            f"cannot tell the columns from the header ({', '.join(tab.header)}): name them t (or"
            " timestamp), x, y, z, qx, qy, qz, qw, or set " + FORMAT_SETTINGS,
            path=str(path),
        )
    if path.suffix.lower() == ".csv" and width >= 8:
        return "euroc"
    by_width = {8: "tum", 12: "kitti", 20: "openvins"}
    if width in by_width:
        return by_width[width]
    raise EpaError(
        f"cannot tell the format from {width} columns: expected 8 (TUM), 12 (KITTI),"
        f" 20 (OpenVINS) or a CSV header naming the columns; set {FORMAT_SETTINGS}",
        path=str(path),
    )


def kitti_times_for(path: Path) -> Path | None:
    """evo's naming: ``X_times.txt`` beside ``X.txt``; else ``times.txt`` in the same folder."""
    for cand in (path.with_name(path.stem + "_times.txt"), path.with_name("times.txt")):
        try:
            if cand.is_file():
                return cand
        except OSError:  # an unusable path (too long): the trajectory's own read reports it
            return None
    return None


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
) -> Trajectory:
    """Read any supported trajectory file into seconds and unit quaternions. Every interpretation the
    file did not state (detected format, nanoseconds, sorting, KITTI times) is logged as a warning
    and appended to ``notes``. ``kitti_printed`` also keeps KITTI's printed rotation blocks (evo's
    commands compute on them)."""
    path = Path(path)
    if fmt not in FORMATS:
        raise EpaError(
            f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}", path=str(path)
        )
    tab = read_table(path)
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
            times = read_table(tpath).rows[:, 0]
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
    )
    if len(traj) < 2:
        raise EpaError(f"only {len(traj)} pose(s); at least 2 are needed", path=str(path))
    for note in tab.notes:
        log.warning("%s: %s", path, note)
    if notes is not None:
        notes.extend(detected + tab.notes)
    return traj
