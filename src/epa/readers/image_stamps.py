"""A file of image stamps (the ETH3D protocol's ``rgb.txt``): the stamp first on each line,
separated from the rest by whitespace or a comma; lines starting with ``#`` and blank lines skipped.
Seconds (``rgb.txt``) or integer nanoseconds (EuRoC's ``cam0/data.csv``, ORB-SLAM3's ground truth
with its zero fraction), as the setting says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from epa.core.errors import EpaError

UNITS = ("s", "ns")
_FIRST = re.compile(r"[\s,]")


def _nanoseconds(token: str) -> int:
    """An integer of nanoseconds, also printed with a zero fraction (ORB-SLAM3's ``.0000000000``)."""
    whole, _, fraction = token.partition(".")
    if fraction.strip("0"):
        raise ValueError(token)
    return int(whole)


def read_image_stamps(path, unit: str = "s") -> np.ndarray:
    """The stamps of a file of image stamps, in seconds, sorted as the file has them.

    Nanoseconds are divided exactly (Python integers: the nearest double, as a seconds file of the
    same digits reads). Raises EpaError naming the file and line of a stamp that is not a number,
    of a stamp before the one above it, or for a file without stamps.
    """
    path = Path(path)
    if unit not in UNITS:
        raise EpaError(f"image stamps unit {unit!r}: choose one of {', '.join(UNITS)}", path=path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise EpaError(
            f"cannot read the image stamps: {err.__class__.__name__}", path=path
        ) from None
    stamps, lines = [], []
    for number, line in enumerate(text.splitlines(), 1):  # one stamp a line: the reader's loop
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        token = _FIRST.split(line.strip(), maxsplit=1)[0]
        try:
            stamps.append(float(token) if unit == "s" else _nanoseconds(token) / 10**9)
        except ValueError:
            what = "a number" if unit == "s" else "an integer of nanoseconds"
            raise EpaError(f"image stamp {token!r} is not {what}", path=path, line=number) from None
        lines.append(number)
    if not stamps:
        raise EpaError("no image stamps", path=path)
    t = np.array(stamps)
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise EpaError("image stamp is not finite", path=path, line=lines[bad])
    back = np.flatnonzero(np.diff(t) < 0)
    if len(back):
        raise EpaError(
            "image stamp before the one above it (the stamps must be sorted)",
            path=path,
            line=lines[int(back[0]) + 1],
        )
    return t
