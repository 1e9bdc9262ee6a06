"""Case discovery in the OpenVINS layout: truth/<dataset>.<ext>, algorithms/<algorithm>/<dataset>/<run>.<ext>.

A run or a reference is a file or a ROS 2 bag folder (holding ``metadata.yaml``); its name without
the extension names it. Side files are never runs: ``<run>_times.txt`` / ``times.txt`` (KITTI
stamps), ``<run>_timing.*`` (per-frame timing), the files a configured timing pattern
(``sources.algorithms.<alg>.timing``) names for the runs beside them, and ``.yaml``, ``.yml``,
``.md``, ``.json`` files.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from epa.artifacts.case import Case, plain_name
from epa.core.errors import EpaError

log = logging.getLogger("epa")
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


def _trajectory_files(folder: Path, skipped: list[Path], timing: str | None = None):
    # a dangling link is kept: its case then fails with "file not found" instead of vanishing
    files: list[Path] = []
    for p in sorted(folder.iterdir()):
        if p.name.startswith("."):
            continue  # hidden (.DS_Store, editor swap files): never data
        if p.is_dir():
            # a ROS 2 bag is a folder
            (files if (p / "metadata.yaml").is_file() else skipped).append(p)
        elif p.name.endswith(SIDE_FILES):
            continue  # a side file by the documented rule: expected, so not worth a warning
        elif p.is_file() or p.is_symlink():
            files.append(p)
        else:
            skipped.append(p)
    side = _timing_side_files(files, timing)
    return [p for p in files if p not in side]


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
    truth_dir, algorithms_dir, *, source: str | None = None, cfg: dict | None = None
) -> tuple[dict[str, Path], list[Case]]:
    """The reference per dataset and the cases. Everything not taken as a run or a reference (side
    files, stray files and folders at the wrong level, datasets without a reference, empty dataset
    folders) is named in a warning. With the settings ``cfg``: a configured timing pattern's files
    are side files, and a ``sources``/``efficiency`` entry naming no algorithm or dataset of the
    grid is a warning. A run whose name is no plain name (a backslash) stays a case, which fails
    alone with a warning here."""
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
    cases: list[Case] = []
    algorithms = []
    for alg in _folders(algorithms_dir, skipped):
        algorithms.append(alg.name)
        timing = _timing_pattern(cfg, alg.name)
        n_cases = len(cases)
        for ds in _folders(alg, skipped):
            if ds.name not in truth:
                log.warning("%s: no reference %s/%s.* - skipped", ds, truth_dir, ds.name)
                continue
            runs: dict[str, Path] = {}
            found = _trajectory_files(ds, skipped, timing)
            if not found:
                log.warning("%s: no run in this dataset folder - skipped", ds)
            for run in found:
                if run.stem in runs:
                    raise EpaError(
                        f"two runs named {run.stem!r} ({runs[run.stem].name}, {run.name}): rename one",
                        path=str(run),
                    )
                runs[run.stem] = run
                case = Case(alg.name, ds.name, run.stem, truth[ds.name], run)
                if not all(plain_name(n) for n in (alg.name, ds.name, run.stem)):
                    log.warning(
                        "%s: the case %r has a name with a backslash (or '.', '..'): it fails, "
                        "marked in the tables; rename it",
                        run,
                        case.key,
                    )
                cases.append(case)
        if len(cases) == n_cases:
            log.warning("%s: algorithm %r has no case: it is in no output", alg, alg.name)
    if skipped:
        shown = ", ".join(str(p) for p in skipped[:5]) + (
            f" and {len(skipped) - 5} more" if len(skipped) > 5 else ""
        )
        log.warning(
            "%d file(s) or folder(s) taken as neither a run nor a reference: %s",
            len(skipped),
            shown,
        )
    _unused_sources(cfg, algorithms, sorted(truth))
    if not cases:
        raise EpaError(
            "no estimate matches a reference (expected <algorithm>/<dataset>/<run>.<ext>)",
            path=str(algorithms_dir),
        )
    return truth, cases


def _timing_pattern(cfg: dict | None, algorithm: str) -> str | None:
    if not cfg:
        return None
    from epa import readers

    return readers.options(cfg, "estimate", algorithm=algorithm).get("timing")


def _unused_sources(cfg: dict | None, algorithms: list[str], datasets: list[str]) -> None:
    """A setting for an algorithm or a dataset the grid does not have is a warning (a typo would
    otherwise be ignored without a word)."""
    if not cfg:
        return
    sources = cfg.get("sources") or {}
    for key, names, known in (
        ("sources.algorithms", sources.get("algorithms") or {}, algorithms),
        ("sources.datasets", sources.get("datasets") or {}, datasets),
        ("efficiency.datasets", (cfg.get("efficiency") or {}).get("datasets") or {}, datasets),
    ):
        for name in sorted(set(names) - set(known)):
            log.warning(
                "%s.%s names no %s of the grid (%s): ignored",
                key,
                name,
                key.split(".")[1][:-1],
                ", ".join(known) or "none",
            )
