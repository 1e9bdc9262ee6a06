"""Trajectory files as the TUM RGB-D benchmark's scripts read them (``associate.read_file_list``,
``evaluate_rpe.read_trajectory``).

Commas and tabs are spaces; a line starting with ``#`` is a comment; the first value is the stamp.
The lines go into a dict keyed by the stamp's value, so a repeated stamp keeps its last line and the
poses come out by increasing stamp. Where the scripts would stop with a traceback or compute NaN (a
value that is not a number, too few values, a NaN or infinite value the ATE script would use), the
error is one line naming the file and the line.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from epa.core.errors import EpaError


def _rows(path) -> list[tuple[int, list[str]]]:
    """(line number, values) of every line that is not empty or a comment."""
    try:
        text = Path(path).read_text(encoding="latin-1")
    except OSError as exc:
        raise EpaError(f"cannot read the file: {exc.strerror or exc}", path=path) from None
    lines = text.replace(",", " ").replace("\t", " ").split("\n")
    rows = [
        (n, [v.strip() for v in line.split(" ") if v.strip() != ""])
        for n, line in enumerate(lines, 1)
        if len(line) > 0 and line[0] != "#"
    ]
    return [(n, values) for n, values in rows if values]


def _numbers(path, n: int, values: list[str], need: int, what: str) -> list[float]:
    if len(values) < need:
        raise EpaError(f"{len(values)} values, {what} needs {need}", path=path, line=n)
    try:
        return [float(v) for v in values]
    except ValueError:
        bad = next(v for v in values if not _is_number(v))
        raise EpaError(f"{bad!r} is not a number", path=path, line=n) from None


def _is_number(v: str) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True


def _last_of_each(stamps: np.ndarray) -> np.ndarray:
    """Indices of the last row of each stamp value, by increasing stamp (a dict's keys sorted)."""
    _, first_in_reversed = np.unique(stamps[::-1], return_index=True)
    return len(stamps) - 1 - first_in_reversed


def positions(path) -> tuple[np.ndarray, np.ndarray]:
    """The stamps and positions ``evaluate_ate.py`` reads (a line needs a stamp and x y z; later
    values are not read).

    Returns
    -------
    t : ndarray (N,)
    p : ndarray (N, 3)
    """
    rows = [(n, v) for n, v in _rows(path) if len(v) > 1]  # read_file_list keeps these
    values = [_numbers(path, n, v[:4], 4, "a stamp and x y z") for n, v in rows]
    table = np.array(values, dtype=float).reshape(-1, 4)
    bad = ~np.isfinite(table).all(axis=1)
    if bad.any():
        raise EpaError("a NaN or infinite value", path=path, line=rows[int(np.argmax(bad))][0])
    keep = _last_of_each(table[:, 0])
    return table[keep, 0], table[keep, 1:4]


def poses(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The stamps, positions and quaternions (x, y, z, w) ``evaluate_rpe.py`` reads: a line with an
    all-zero quaternion is skipped; a line with a NaN is skipped with the script's warning on stderr.

    Returns
    -------
    t : ndarray (N,)
    p : ndarray (N, 3)
    q : ndarray (N, 4), as written (not normalised)
    """
    rows = _rows(path)
    values = [_numbers(path, n, v, 8, "a stamp, x y z and qx qy qz qw") for n, v in rows]
    has_nan = np.array([any(map(np.isnan, row)) for row in values], dtype=bool)  # any column
    table = np.array([row[:8] for row in values], dtype=float).reshape(-1, 8)
    zero_q = (table[:, 4:8] == 0).all(axis=1)
    for k in np.flatnonzero(has_nan & ~zero_q):
        # the script's own warning, numbering the lines it parsed from 0
        sys.stderr.write(f"Warning: line {k} of file '{path}' has NaNs, skipping line\n")
    table = table[~has_nan & ~zero_q]
    lines = np.array([n for n, _ in rows], dtype=np.int64)[~has_nan & ~zero_q]
    if not np.isfinite(table).all():
        raise EpaError(
            "an infinite value", path=path, line=int(lines[np.argmax(~np.isfinite(table).all(1))])
        )
    keep = _last_of_each(table[:, 0])
    return table[keep, 0], table[keep, 1:4], table[keep, 4:8]
