"""Case discovery in the OpenVINS layout: truth/<dataset>.<ext>, algorithms/<algorithm>/<dataset>/<run>.<ext>.

A run or a reference is a file or a ROS 2 bag folder (holding ``metadata.yaml``); its name without
the extension names it. Side files are never runs: ``<run>_times.txt`` / ``times.txt`` (KITTI
stamps), ``<run>_timing.*`` (per-frame timing), the files a configured timing pattern
(``sources.algorithms.<alg>.timing``) names for the runs beside them, and ``.yaml``, ``.yml``,
``.md``, ``.json`` files.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from epa.artifacts.case import Case, plain_name
from epa.core.errors import EpaError
from epa.workflow.side_files import (  # noqa: F401 - SIDE_FILES: part of this module's rule
    SIDE_FILES,
    _timing_pattern,
    _timing_side_files,
    is_side_file,
    timing_side_files,
)

log = logging.getLogger(__name__)


def sources_of(cfg: dict, case: Case) -> tuple[dict, dict]:
    """The reference's and the estimate's source settings of a case: a sheet row's own (discovery
    put them in the case), else the config's for its dataset and algorithm."""
    from epa import readers

    return (
        case.truth_source or readers.options(cfg, "reference", dataset=case.dataset),
        case.estimate_source or readers.options(cfg, "estimate", algorithm=case.algorithm),
    )


def discover_config(
    cfg: dict, *, source: str | None = None, say=None
) -> tuple[dict[str, Path], list[Case]]:
    """The reference per dataset and the cases of a resolved config, whichever way it names its
    inputs: ``inputs.sheet`` (:mod:`epa.workflow.sheet`), ``inputs.reference`` / ``inputs.estimate``
    patterns (:mod:`epa.workflow.patterns`), or the OpenVINS layout of ``truth_dir`` and
    ``algorithms_dir`` (:func:`discover`). ``say``: where the patterns' and the sheet's account of
    what they matched goes (default: stderr)."""
    inputs = cfg.get("inputs") or {}
    if inputs.get("constraints") and not inputs.get("estimate"):  # never ignored in silence
        raise EpaError(
            "inputs.constraints constrain the wildcards of inputs.reference and inputs.estimate:"
            " there are none",
            path=source or "config",
        )
    if not inputs.get("sheet") and not inputs.get("estimate"):
        return discover(cfg["truth_dir"], cfg["algorithms_dir"], source=source, cfg=cfg)
    say = say or (lambda line: print(f"epa: {line}", file=sys.stderr))
    skipped: list[tuple[str, str]] = []
    source = source or "config"
    if inputs.get("sheet"):
        from epa.workflow import sheet

        truth, cases = sheet.discover(cfg, source=source, say=say)
    else:
        from epa.workflow import patterns

        truth, cases = patterns.discover(
            cfg, source=source, say=say, skip=lambda p, why: skipped.append((p, why))
        )
    by_reason: dict[str, list[str]] = {}
    for path, why in skipped:
        by_reason.setdefault(why, []).append(path)
    for why, paths in by_reason.items():  # one line per reason: a large tree may skip many files
        more = f" and {len(paths) - SHOWN_SKIPS} more" if len(paths) > SHOWN_SKIPS else ""
        log.warning("skipped %d: %s: %s%s", len(paths), why, ", ".join(paths[:SHOWN_SKIPS]), more)
    _unused_sources(cfg, sorted({c.algorithm for c in cases}), sorted(truth))
    if not cases:
        raise EpaError("no estimate matches a reference (see the skipped files above)", path=source)
    return truth, cases


SHOWN_SKIPS = 3  # the files named for each reason a pattern's file was skipped


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
