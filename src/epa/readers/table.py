"""A text file's numeric rows (:class:`Table`) and the field splitting every text reader shares."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from epa.core.errors import EpaError


class Table:
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


def split_fields(line: str) -> list[str]:
    """A row's fields, separated by commas, semicolons or whitespace."""
    return line.replace(",", " ").replace(";", " ").split()


def is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False
