"""User-facing errors: one line naming the file, the line (where there is one) and what is wrong."""

from __future__ import annotations

import os


class EpaError(Exception):
    """A user mistake (bad input, impossible setting); reported as one line, never a traceback."""

    def __init__(
        self, message: str, *, path: str | os.PathLike[str] | None = None, line: int | None = None
    ):
        self.message = message
        self.path = None if path is None else str(path)
        self.line = line
        super().__init__(self.one_line())

    def one_line(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path + (f":{self.line}" if self.line is not None else "") + ": "
        return (where + self.message).replace("\n", " ")
