"""The workflow's terminal: epa's warnings on stderr while Snakemake parses and runs the workflow (and
the scripts run alone), printed as Python's last-resort handler prints them. The library itself
attaches no handler (epa/__init__.py), so a notebook calling epa.evaluate sees nothing unless it
configures logging."""

from __future__ import annotations

import logging
import sys


class _Terminal(logging.Handler):
    """A warning goes to stderr only when no other handler would take it: not inside a case log
    (epa.workflow.jobs attaches its own and stops propagation), not where the host configured
    logging of its own."""

    def emit(self, record: logging.LogRecord) -> None:
        logger: logging.Logger | None = logging.getLogger(record.name)
        while logger is not None:
            if any(
                h is not self and not isinstance(h, logging.NullHandler) for h in logger.handlers
            ):
                return
            if not logger.propagate:
                break
            logger = logger.parent
        try:
            sys.stderr.write(self.format(record) + "\n")
        except Exception:  # noqa: BLE001 - a closed stream must not end the run
            self.handleError(record)


def show_warnings() -> None:
    """Print epa's warnings on stderr (once per process, however often it is called)."""
    epa = logging.getLogger("epa")
    if not any(isinstance(h, _Terminal) for h in epa.handlers):
        epa.addHandler(_Terminal(logging.WARNING))
