"""A text file's header: which leading lines are comments and a header, and which pose columns the
header's names name (time, position, quaternion, covariance)."""

from __future__ import annotations

import re
from pathlib import Path

from epa.core.errors import EpaError
from epa.readers.table import is_number, split_fields


def header_names(line: str) -> list[str]:
    """Column names of a header line: comma-separated if it has commas, else whitespace-separated."""
    body = line.lstrip("#%").strip()
    return [h.strip() for h in (body.split(",") if "," in body else body.split()) if h.strip()]


def scan_header(path: Path, raw: list[str]):
    """(first data line index, header names, header line) of a file's lines: leading comments and
    blank lines, and one uncommented header line; the last of them names the columns."""
    header: list[str] | None = None
    start, header_line = len(raw), None
    for k, line in enumerate(raw):
        s = line.strip()
        if not s:
            continue
        if s[0] not in "#%" and not split_fields(s):
            raise EpaError("a row of empty fields", path=str(path), line=k + 1)
        if s[0] in "#%":
            header = header_names(s)
            continue
        if not is_number(split_fields(s)[0]):
            if header_line is not None:  # two header rows (units, a pasted file): no guess
                raise EpaError(
                    f"not a number: {split_fields(s)[0]!r} (a second header line; line {header_line}"
                    " was taken as the header)",
                    path=str(path),
                    line=k + 1,
                )
            header, header_line = header_names(s), k + 1
            continue
        return k, header, header_line
    return start, header, header_line


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


def named_columns(header: list[str] | None, width: int) -> dict | None:
    """Map a header to column indices, or None when it does not name a full pose."""
    if not header or len(header) != width:
        return None
    names = [_norm_name(h) for h in header]
    cols = _pose_names(names)
    if not {"t", "px", "py", "pz", "qx", "qy", "qz", "qw"} <= cols.keys():
        return None
    cols["ns"] = _in_ns(header)
    for kind, alternatives in _COV_NAMES.items():
        for names6 in alternatives:
            if all(c in names for c in names6):
                cols["cov_" + kind] = [names.index(c) for c in names6]
    return cols


def position_columns(header: list[str] | None, width: int) -> dict | None:
    """Map a header naming exactly time and x, y, z (a position-only source) to column indices, or
    None. Any other column (an orientation, a speed) is not a position-only header: never guessed."""
    if not header or len(header) != width or width != 4:
        return None
    cols = _pose_names([_norm_name(h) for h in header])
    if set(cols) != {"t", "px", "py", "pz"}:
        return None
    return {**cols, "ns": _in_ns(header)}


def _in_ns(header: list[str]) -> bool:
    return any("[ns]" in h.lower() or h.lower().endswith("_ns") for h in header)


def _pose_names(names: list[str]) -> dict:
    """The time, position and quaternion columns that normalised header ``names`` name."""
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
    return cols
