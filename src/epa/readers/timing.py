"""Per-frame timing files: ``<timestamp> <milliseconds>`` text or OpenVINS's timing CSV."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from epa.core import ranks
from epa.core.errors import EpaError
from epa.readers import text


def read_timing(
    path, *, c_parser_min_bytes: int = text.C_PARSER_MIN_BYTES
) -> tuple[np.ndarray, np.ndarray, str]:
    """(stamps in s, frame times in ms, what was read) from ``<timestamp> <milliseconds>`` text or
    OpenVINS's timing CSV (header ``timestamp (sec),...,total``, in seconds: its ``total``)."""
    path = Path(path)
    # the text readers' parsing and one-line errors
    tab = text.read_table(path, c_parser_min_bytes=c_parser_min_bytes)
    header = [h.strip().lower() for h in (tab.header or [])]
    rows = tab.rows
    if "total" in header:
        if len(header) != rows.shape[1]:
            raise EpaError(
                f"the header names {len(header)} columns but the rows have {rows.shape[1]}",
                path=str(path),
            )
        t, ms, what = (
            rows[:, 0],
            rows[:, header.index("total")] * 1000.0,
            "OpenVINS timing CSV (total, s)",
        )
    elif rows.shape[1] == 2:
        t, ms, what = rows[:, 0], rows[:, 1], "<timestamp> <ms>"
    else:
        raise EpaError(
            f"a timing file has 2 columns (<timestamp> <milliseconds>) or an OpenVINS header with"
            f" 'total'; found {rows.shape[1]} columns",
            path=str(path),
        )
    if ranks.median(np.abs(t)) > text.NS_THRESHOLD:
        t, what = t / 1e9, what + ", stamps in ns"
    if (ms < 0).any():
        k = int(np.argmax(ms < 0))
        raise EpaError(f"negative frame time {ms[k]:g} ms", path=str(path), line=tab.line_of(k))
    return t, ms, what
