"""Settings per cell: a grid's settings are every case's defaults; ``overrides`` gives some algorithms,
datasets or (algorithm, dataset) cells their own, and ``sources.algorithms.<alg>.metric_scale: false``
declares an algorithm monocular (Step 2 solves the scale, Step 3 fits Sim3).

Precedence, the most specific last (it wins): the grid's settings, in mode rpg an estimate folder's
``eval_cfg.yaml`` (rpg's per-folder ``align_type``), ``overrides.datasets``,
``overrides.algorithms``, ``overrides.cases`` (``<algorithm>/<dataset>``), then what
``metric_scale: false`` implies. Within one level a name beats a glob pattern; two patterns of one
level that set one key of a case to different values are an error naming both. A pattern that
matches nothing in the grid is an error naming it (a typo would otherwise be silently ignored).

A case's settings are the grid's with whole sections replaced (:func:`for_case`); what differs from
the grid's travels with the case (:class:`CaseSettings`): to the stage jobs that read it, and into
the case's ``01_load/load.json`` (``settings``), so every case records what it ran with.
"""

from __future__ import annotations

import copy
import fnmatch
from dataclasses import dataclass, field
from pathlib import Path

from epa.core.errors import EpaError

# The sections a cell may set (the stages' and metrics' settings); mode, tables, report, load and
# the folders are the grid's (load's per-source settings are `sources`).
SECTIONS = ("crop", "sync", "calibrate", "align", "metrics", "drift", "efficiency")
LEVELS = ("datasets", "algorithms", "cases")  # least to most specific


@dataclass(frozen=True)
class CaseSettings:
    """What a case runs with beside the grid's settings: ``changed``, each section that differs
    (whole, resolved); ``applied``, where each change came from, in the order applied."""

    changed: dict = field(default_factory=dict)
    applied: tuple[str, ...] = ()

    def record(self) -> dict:
        return {"applied": list(self.applied), "changed": self.changed}

    def for_stage(self, sections) -> dict:
        return {k: self.changed[k] for k in sections if k in self.changed}


def _is_pattern(name: str) -> bool:
    return any(ch in name for ch in "*?[")


def _matches(pattern: str, name: str) -> bool:
    return fnmatch.fnmatchcase(name, pattern)


def _hits(level: str, key: str, algorithms, datasets) -> bool:
    """Whether an override key of ``level`` names one of the algorithms, datasets or their cells."""
    if level == "cases":
        alg_pat, _, ds_pat = key.partition("/")
        return any(_matches(alg_pat, a) for a in algorithms) and any(
            _matches(ds_pat, d) for d in datasets
        )
    names = datasets if level == "datasets" else algorithms
    return any(_matches(key, n) for n in names)


def _leaves(tree: dict, prefix: tuple = ()) -> dict[tuple, object]:
    out: dict[tuple, object] = {}
    for k, v in tree.items():
        if isinstance(v, dict) and v:
            out.update(_leaves(v, prefix + (k,)))
        else:
            out[prefix + (k,)] = v
    return out


def _merge(into: dict, given: dict) -> None:
    """``given`` over ``into``: mappings key by key, anything else (lists too) replaced whole."""
    for k, v in given.items():
        if isinstance(v, dict) and isinstance(into.get(k), dict):
            _merge(into[k], v)
        else:
            into[k] = copy.deepcopy(v)


def _entries(cfg: dict, algorithm: str, dataset: str) -> list[tuple[str, dict]]:
    """The override entries that apply to one cell, in the order they apply (``(where, settings)``);
    a conflict between two patterns of one level is an error."""
    overrides = cfg.get("overrides") or {}
    out: list[tuple[str, dict]] = []
    for level in LEVELS:
        table = overrides.get(level) or {}
        names: list[tuple[str, dict]] = []
        patterns: list[tuple[str, dict]] = []
        for key, value in table.items():
            if _hits(level, key, [algorithm], [dataset]):
                exact = not _is_pattern(key)
                (names if exact else patterns).append((f"overrides.{level}.{key}", value or {}))
        _check_conflicts(patterns, algorithm, dataset)
        out += patterns + names
    return out


def _check_conflicts(patterns: list[tuple[str, dict]], algorithm: str, dataset: str) -> None:
    seen: dict[tuple, tuple[str, object]] = {}
    for where, settings in patterns:
        for leaf, value in _leaves(settings).items():
            if leaf in seen and seen[leaf][1] != value:
                raise EpaError(
                    f"{seen[leaf][0]} and {where} both match {algorithm}/{dataset} and set"
                    f" {'.'.join(leaf)} to {seen[leaf][1]!r} and {value!r}: name the cell"
                    " (a name beats a pattern) or make the patterns disjoint"
                )
            seen.setdefault(leaf, (where, value))


def _metric_scale(cfg: dict, algorithm: str) -> bool | None:
    src = ((cfg.get("sources") or {}).get("algorithms") or {}).get(algorithm) or {}
    return src.get("metric_scale")


def for_case(
    cfg: dict,
    algorithm: str,
    dataset: str,
    *,
    source: str = "config",
    folder: tuple[str, dict] | None = None,
) -> CaseSettings:
    """The settings one case runs with, as what differs from the resolved grid ``cfg``.
    ``folder``: the estimate folder's own settings in mode rpg (``(where, settings)``, from its
    ``eval_cfg.yaml``), applied before the config's overrides."""
    from epa.workflow import settings

    entries = ([folder] if folder else []) + _entries(cfg, algorithm, dataset)
    monocular = _metric_scale(cfg, algorithm) is False
    if not entries and not monocular:
        return CaseSettings()
    merged = {k: copy.deepcopy(cfg[k]) for k in SECTIONS}
    applied = []
    given: dict = {}
    for where, values in entries:
        _merge(merged, values)
        _merge(given, values)
        applied.append(where)
    if monocular:
        implied = monocular_settings(cfg["mode"])
        for (section, key), value in implied.items():
            set_to = (given.get(section) or {}).get(key, value)
            if set_to != value:
                by = [w for w, v in entries if (v.get(section) or {}).get(key) == set_to][-1]
                raise EpaError(
                    f"sources.algorithms.{algorithm}.metric_scale: false needs {section}.{key}:"
                    f" {value!r} (an arbitrary scale is fitted), but {by} sets {set_to!r}"
                    f" for {algorithm}/{dataset}",
                    path=source,
                )
            merged[section][key] = value
        applied.append(
            f"sources.algorithms.{algorithm}.metric_scale: false ("
            + ", ".join(f"{s}.{k}: {str(v).lower()}" for (s, k), v in implied.items())
            + ")"
        )
    full = {**cfg, **merged}
    settings.apply_mode(full, given=given)
    problem = settings.check_first_n(full) or settings.check_crop(full)
    if problem:
        raise EpaError(f"{problem} (for {algorithm}/{dataset}: {', '.join(applied)})", path=source)
    changed = {k: full[k] for k in SECTIONS if full[k] != cfg[k]}
    return CaseSettings(changed, tuple(applied))


def monocular_settings(mode: str) -> dict[tuple[str, str], object]:
    """What ``metric_scale: false`` implies: Step 3 fits Sim3; in mode epa Step 2 solves the scale too
    (modes ov_eval and rpg run no Step 2)."""
    implied: dict[tuple[str, str], object] = {("align", "method"): "sim3"}
    if mode == "epa":
        implied[("calibrate", "scale")] = True
    return implied


def unmatched(cfg: dict, algorithms, datasets) -> str | None:
    """The first override key that matches nothing in the grid, as a message (None: all match)."""
    algorithms, datasets = sorted(set(algorithms)), sorted(set(datasets))
    overrides = cfg.get("overrides") or {}
    for level in LEVELS:
        for key in overrides.get(level) or {}:
            if not _hits(level, key, algorithms, datasets):
                kind = {"datasets": "dataset", "algorithms": "algorithm", "cases": "cell"}[level]
                known = datasets if level == "datasets" else algorithms
                return f"overrides.{level}.{key}: matches no {kind} of the grid" + (
                    "" if level == "cases" else f" ({', '.join(known) or 'none'})"
                )
    return None


def for_grid(cfg: dict, cases, *, source: str = "config") -> dict[str, CaseSettings]:
    """Case key -> its settings, for the cases whose settings differ from the grid's. A pattern
    that matches nothing is an error. One resolution per distinct (algorithm, dataset)."""
    problem = unmatched(cfg, (c.algorithm for c in cases), (c.dataset for c in cases))
    if problem:
        raise EpaError(problem, path=source)
    overrides = cfg.get("overrides") or {}
    if (
        not any(overrides.get(level) for level in LEVELS)
        and cfg["mode"] != "rpg"
        and not any(_metric_scale(cfg, a) is False for a in {c.algorithm for c in cases})
    ):
        return {}
    by_cell: dict[tuple, CaseSettings] = {}
    folders: dict[Path, tuple[str, dict] | None] = {}
    out = {}
    for c in cases:
        folder = None
        if cfg["mode"] == "rpg" and c.estimate is not None:
            parent = Path(c.estimate).parent
            if parent not in folders:
                folders[parent] = rpg_folder(parent)
            folder = folders[parent]
        cell = (c.algorithm, c.dataset, folder and folder[0])
        if cell not in by_cell:
            by_cell[cell] = for_case(cfg, c.algorithm, c.dataset, source=source, folder=folder)
        if by_cell[cell].applied:
            out[c.key] = by_cell[cell]
    return out


def rpg_folder(folder: Path) -> tuple[str, dict] | None:
    """Mode rpg: an estimate folder's ``eval_cfg.yaml`` as the settings of its cases (rpg's
    ``align_type`` and ``align_num_frames`` are ``align.method`` and ``align.first_n``); None where
    the folder has none (the grid's ``align`` then)."""
    from epa.readers.rpg_files import read_eval_cfg

    path = folder / "eval_cfg.yaml"
    if not path.is_file():
        return None
    kind, n = read_eval_cfg(folder)
    first_n = -1 if kind == "none" and n < 1 else n  # rpg ignores the count without alignment
    return str(path), {"align": {"method": kind, "first_n": first_n}}


def one_case(
    cfg: dict, algorithm: str, dataset: str, *, source: str = "config"
) -> tuple[dict, CaseSettings]:
    """A single case's settings (``epa eval``, :func:`epa.evaluate`): the grid's resolved ``cfg``
    with what its overrides and ``metric_scale`` give the cell (algorithm, dataset). Overrides of
    other cells are not errors here: one config serves a grid and its single cases."""
    own = for_case(cfg, algorithm, dataset, source=source)
    return case_config(cfg, own.changed), own


def case_config(cfg: dict, changed: dict | None) -> dict:
    """A stage's settings for one case: the grid's, with the case's changed sections."""
    return {**cfg, **changed} if changed else cfg
