"""Side files: files beside runs that are never runs nor references (timing files, KITTI times,
notes), by the documented rule and by a configured timing pattern. Every way of finding the inputs
(the OpenVINS layout, path patterns) leaves them out alike."""

from __future__ import annotations

import re
from pathlib import Path

# not runs
SIDE_FILES = (
    "_times.txt",
    "times.txt",
    "_timing.txt",
    "_timing.csv",
    ".yaml",
    ".yml",
    ".md",
    ".json",
)


def _timing_side_files(files: list[Path], pattern: str | None) -> set[Path]:
    """The files a configured timing pattern (``{run}.frames``) names for the runs beside them: side
    files, not runs. Only a file whose ``{run}`` is the name of another file there counts."""
    if not pattern or "/" in pattern or "{run}" not in pattern:
        return set()
    rx = re.compile("^" + re.escape(pattern).replace(re.escape("{run}"), "(.+)") + "$")
    stems: dict[str, list[Path]] = {}
    for p in files:
        stems.setdefault(p.stem if not p.is_dir() else p.name, []).append(p)
    side = set()
    for p in files:
        m = rx.match(p.name)
        if m and any(q != p for q in stems.get(m.group(1), [])):
            side.add(p)
    return side


def is_side_file(path: Path) -> bool:
    """A side file by the documented rule (its name's ending), never a run or a reference."""
    return path.name.endswith(SIDE_FILES)


def timing_side_files(cfg: dict | None, paths, algorithm_of) -> set[str]:
    """Of ``paths`` (found by patterns or a sheet), those a configured timing pattern names for a run
    beside them (:func:`_timing_side_files`, folder by folder and algorithm by algorithm)."""
    groups: dict[tuple[str, str], list[Path]] = {}
    for path in paths:
        groups.setdefault((str(Path(path).parent), algorithm_of(path)), []).append(Path(path))
    side: set[str] = set()
    for (_, algorithm), files in groups.items():
        side |= {str(p) for p in _timing_side_files(files, _timing_pattern(cfg, algorithm))}
    return side


def _timing_pattern(cfg: dict | None, algorithm: str) -> str | None:
    if not cfg:
        return None
    from epa import readers

    return readers.options(cfg, "estimate", algorithm=algorithm).get("timing")
