"""Case discovery in the OpenVINS layout: truth/<dataset>.<ext>, algorithms/<algorithm>/<dataset>/<run>.<ext>.

A run or a reference is a file or a ROS 2 bag folder (holding ``metadata.yaml``); its name without
the extension names it. Side files are never runs: ``<run>_times.txt`` / ``times.txt`` (KITTI
stamps), ``<run>_timing.*`` (per-frame timing), and ``.yaml``, ``.yml``, ``.md``, ``.json`` files.
"""

from __future__ import annotations

import logging
from pathlib import Path

from epa.artifacts.case import Case
from epa.core.errors import EpaError

log = logging.getLogger("epa")
SIDE_FILES = (
    "_times.txt",
    "times.txt",
    "_timing.txt",
    "_timing.csv",
    ".yaml",
    ".yml",
    ".md",
    ".json",
)  # not runs


def _trajectory_files(folder: Path, skipped: list[Path]):
    # a dangling link is kept: its case then fails with "file not found" instead of vanishing
    files = []
    for p in sorted(folder.iterdir()):
        if p.name.startswith("."):
            continue  # hidden (.DS_Store, editor swap files): never data
        if p.is_dir():
            (files if (p / "metadata.yaml").is_file() else skipped).append(
                p
            )  # a ROS 2 bag is a folder
        elif p.name.endswith(SIDE_FILES):
            continue  # a side file by the documented rule: expected, so not worth a warning
        elif p.is_file() or p.is_symlink():
            files.append(p)
        else:
            skipped.append(p)
    return files


def _folders(parent: Path, skipped: list[Path]):
    """The visible sub-folders of ``parent``; a file at this level is noted in ``skipped``."""
    for p in sorted(parent.iterdir()):
        if p.name.startswith("."):
            continue
        if p.is_dir():
            yield p
        else:
            skipped.append(p)


def discover(
    truth_dir, algorithms_dir, *, source: str | None = None
) -> tuple[dict[str, Path], list[Case]]:
    """The reference per dataset and the cases. Everything not taken as a run or a reference (side
    files, stray files and folders at the wrong level, datasets without a reference) is named in a
    warning."""
    truth_dir, algorithms_dir = Path(truth_dir), Path(algorithms_dir)
    for d, key in ((truth_dir, "truth_dir"), (algorithms_dir, "algorithms_dir")):
        if not d.is_dir():
            where = "" if d.is_absolute() else f"; relative paths start at {Path.cwd()}"
            raise EpaError(f"{key} {str(d)!r} is not a folder{where}", path=source or str(d))
    skipped: list[Path] = []
    truth: dict[str, Path] = {}
    for p in _trajectory_files(truth_dir, skipped):
        if p.stem in truth:
            raise EpaError(
                f"two reference files for dataset {p.stem!r} ({truth[p.stem].name}, {p.name})",
                path=str(p),
            )
        truth[p.stem] = p
    cases = []
    for alg in _folders(algorithms_dir, skipped):
        for ds in _folders(alg, skipped):
            if ds.name not in truth:
                log.warning("%s: no reference %s/%s.* - skipped", ds, truth_dir, ds.name)
                continue
            runs: dict[str, Path] = {}
            for run in _trajectory_files(ds, skipped):
                if run.stem in runs:
                    raise EpaError(
                        f"two runs named {run.stem!r} ({runs[run.stem].name}, {run.name}): rename one",
                        path=str(run),
                    )
                runs[run.stem] = run
                cases.append(Case(alg.name, ds.name, run.stem, truth[ds.name], run))
    if skipped:
        shown = ", ".join(str(p) for p in skipped[:5]) + (
            f" and {len(skipped) - 5} more" if len(skipped) > 5 else ""
        )
        log.warning(
            "%d file(s) or folder(s) taken as neither a run nor a reference: %s",
            len(skipped),
            shown,
        )
    if not cases:
        raise EpaError(
            "no estimate matches a reference (expected <algorithm>/<dataset>/<run>.<ext>)",
            path=str(algorithms_dir),
        )
    return truth, cases
