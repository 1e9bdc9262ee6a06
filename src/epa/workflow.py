"""Glue for rule scripts: logging to the rule's log, and a user mistake recorded as the case's
failure (every output written as a failure marker, passed on downstream) instead of a crash."""

from __future__ import annotations

import logging
import sys
from contextlib import contextmanager
from pathlib import Path

from epa import io
from epa.errors import EpaError

FAILED_PREFIX = "# epa-failed: "
USER_INPUTS = {"truth", "estimate"}  # the user's own files, never failure markers


def failure_of(path) -> str | None:
    """The recorded reason if this stage artifact is a failure marker, else None."""
    path = Path(path)
    with open(path, encoding="utf-8", errors="replace") as fh:
        head = fh.read(4096)
    if path.suffix == ".json":
        if '"status": "failed"' in head:
            return io.read_json(path).get("reason", "failed")
        return None
    if head.startswith(FAILED_PREFIX):
        return head[len(FAILED_PREFIX):].splitlines()[0]
    return None


def write_failure(paths, reason: str) -> None:
    for p in paths:
        if str(p).endswith(".json"):
            io.write_json(p, {"status": "failed", "reason": reason})
        else:
            io.write_text(p, FAILED_PREFIX + reason + "\n")


def _setup_logging(log_path) -> logging.Logger:
    logger = logging.getLogger("epa")
    logger.handlers.clear()
    handler = logging.FileHandler(log_path, mode="w") if log_path else logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logging.captureWarnings(True)
    return logger


@contextmanager
def stage(smk, *, check_inputs: bool = True):
    """Run one rule's body. An EpaError (user mistake) becomes this case's recorded failure;
    a bug keeps its traceback and fails the job."""
    logger = _setup_logging(smk.log[0] if len(smk.log) else None)
    for name, path in (smk.input.items() if check_inputs else ()):
        if name not in USER_INPUTS:
            reason = failure_of(path)
            if reason is not None:  # an upstream stage failed: pass its reason on, nothing to compute
                logger.error("case failed upstream: %s", reason)
                write_failure(list(smk.output), reason)
                sys.exit(0)
    try:
        yield logger
    except EpaError as exc:
        reason = f"{smk.rule}: {exc.one_line()}"
        logger.error("case failed: %s", reason)
        write_failure(list(smk.output), reason)
