"""Case discovery from path patterns: ``inputs.reference`` and ``inputs.estimate`` name the files
where they lie, with the wildcards ``{dataset}``, ``{algorithm}`` and ``{run}`` anywhere in the path
(any order, any depth, repeated: each occurrence takes the same value). ``inputs.estimate`` is one
pattern, a list, or a mapping ``{algorithm: pattern}`` for layouts that do not name the algorithm.
An estimate's ``{dataset}`` finds its reference by name or through ``inputs.datasets`` (``MH01:
MH_01_easy``); the case is named by the reference's dataset, so every form of the inputs gives the
same case names. Without ``{run}`` a run is named by its file name without the extension, as in the
OpenVINS layout.

What each pattern matched is printed (``say``); every file a pattern matched and discovery did not
take is named with the reason. A pattern matching nothing, an unknown wildcard, two patterns
matching one file and two files for one case are each a one-line error.
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from epa.artifacts.case import Case, plain_name
from epa.core.errors import EpaError
from epa.workflow.side_files import is_side_file, timing_side_files

WILDCARDS = ("algorithm", "dataset", "run")
REFERENCE_WILDCARDS = ("dataset",)
_FIELD = re.compile(r"\{([^{}]*)\}")


@dataclass(frozen=True)
class Pattern:
    """One pattern: its config key (for messages), its text, and a fixed algorithm (mapping form)."""

    key: str
    text: str
    algorithm: str | None = None

    def wildcards(self) -> list[str]:
        return _FIELD.findall(self.text)

    def check(self, allowed: tuple[str, ...], required: tuple[str, ...], source: str) -> None:
        for name in self.wildcards():
            if name not in allowed:
                known = ", ".join("{" + w + "}" for w in allowed)
                raise EpaError(
                    f"{self.key}: unknown wildcard {{{name}}} in {self.text!r} (known here: {known})",
                    path=source,
                )
        for name in required:
            if name not in self.wildcards():
                raise EpaError(f"{self.key}: {self.text!r} has no {{{name}}}", path=source)
        if "{" in _FIELD.sub("", self.text) or "}" in _FIELD.sub("", self.text):
            raise EpaError(f"{self.key}: unbalanced brace in {self.text!r}", path=source)

    def glob(self) -> str:
        """The shell pattern of the files it may match (each wildcard a ``*`` within one folder)."""
        parts = _FIELD.split(self.text)  # literal, name, literal, name, ...
        return "".join(glob.escape(p) if k % 2 == 0 else "*" for k, p in enumerate(parts))

    def regex(self) -> re.Pattern:
        parts = _FIELD.split(self.text)
        seen: set[str] = set()
        out = []
        for k, part in enumerate(parts):
            if k % 2 == 0:
                out.append(re.escape(part))
            elif part in seen:
                out.append(f"(?P={part})")  # a repeated wildcard takes the same value
            else:
                seen.add(part)
                out.append(f"(?P<{part}>[^/]+)")
        return re.compile("".join(out) + r"\Z")

    def matches(self) -> dict[str, dict[str, str]]:
        """{path: its wildcards' values} of every path the pattern matches (hidden ones aside)."""
        rx = self.regex()
        found = {}
        for path in sorted(glob.glob(self.glob())):
            m = rx.match(path)
            if m:
                found[path] = m.groupdict()
        return found


def patterns(value, key: str) -> list[Pattern]:
    """``inputs.<key>`` as patterns: a string, a list of strings, or {algorithm: pattern}."""
    home = os.path.expanduser  # `~/data/...` as a shell would read it
    if isinstance(value, str):
        return [Pattern(f"inputs.{key}", home(value))]
    if isinstance(value, list):
        return [Pattern(f"inputs.{key}.{k}", home(v)) for k, v in enumerate(value)]
    if not value:
        raise EpaError(f"inputs.{key}: an empty mapping names no pattern")
    for alg in value:
        if not plain_name(alg):
            raise EpaError(f"inputs.{key}.{alg}: an algorithm's name is one path component")
    return [Pattern(f"inputs.{key}.{alg}", home(v), alg) for alg, v in value.items()]


def _owned(pats: list[Pattern], source: str) -> dict[str, tuple[Pattern, dict]]:
    """Each matched path with the one pattern that matched it (two: an error naming both)."""
    owner: dict[str, tuple[Pattern, dict]] = {}
    for pat in pats:
        found = pat.matches()
        if not found:
            raise EpaError(f"{pat.key}: {pat.text!r} matches no file", path=source)
        for path, values in found.items():
            if path in owner:
                raise EpaError(
                    f"matched by two patterns, {owner[path][0].key} and {pat.key}: make them"
                    " exclusive",
                    path=path,
                )
            owner[path] = (pat, values)
    return owner


def _kind(path: str, side_file: Callable[[Path], bool]) -> str | None:
    """Why a matched path is no trajectory (None: it is one)."""
    p = Path(path)
    if p.is_dir():
        return None if (p / "metadata.yaml").is_file() else "a folder, not a ROS 2 bag"
    if side_file(p):
        return "a side file (timing, KITTI times, YAML, Markdown or JSON)"
    return None


def references(cfg: dict, source: str, say, skip) -> dict[str, Path]:
    """The reference of each dataset, by ``inputs.reference``."""
    pats = patterns(cfg["inputs"]["reference"], "reference")
    for pat in pats:
        pat.check(REFERENCE_WILDCARDS, ("dataset",), source)
    truth: dict[str, Path] = {}
    owner = _owned(pats, source)
    for path, (pat, values) in owner.items():
        why = _kind(path, is_side_file)
        if why:
            skip(path, f"{pat.key}: {why}")
            continue
        ds = values["dataset"]
        if ds in truth:
            raise EpaError(
                f"two reference files for dataset {ds!r} ({truth[ds]}, {path})", path=path
            )
        truth[ds] = Path(path)
    for pat in pats:
        n = sum(1 for p, (q, _) in owner.items() if q is pat and Path(p) in truth.values())
        say(f"{pat.key} {pat.text!r}: {n} reference(s)")
    return truth


def discover(cfg: dict, *, source: str, say, skip) -> tuple[dict[str, Path], list[Case]]:
    """The reference per dataset and the cases, by the patterns of ``cfg["inputs"]``."""
    truth = references(cfg, source, say, skip)
    names = cfg["inputs"]["datasets"] or {}
    pats = patterns(cfg["inputs"]["estimate"], "estimate")
    for pat in pats:
        need = ("dataset",) if pat.algorithm else ("algorithm", "dataset")
        allowed = ("dataset", "run") if pat.algorithm else WILDCARDS
        pat.check(allowed, need, source)
    owner = _owned(pats, source)
    side = timing_side_files(
        cfg, owner, lambda p: owner[p][0].algorithm or owner[p][1]["algorithm"]
    )
    cases: dict[str, Case] = {}
    counts = {pat.key: 0 for pat in pats}
    for path, (pat, values) in owner.items():
        why = "a timing file of a run beside it" if path in side else _kind(path, is_side_file)
        if why:
            skip(path, f"{pat.key}: {why}")
            continue
        dataset = names.get(values["dataset"], values["dataset"])
        if dataset not in truth:
            mapped = (
                "" if dataset == values["dataset"] else f" (inputs.datasets: {values['dataset']})"
            )
            skip(path, f"{pat.key}: no reference for dataset {dataset!r}{mapped}")
            continue
        p = Path(path)
        run = values.get("run") or (p.name if p.is_dir() else p.stem)
        case = Case(pat.algorithm or values["algorithm"], dataset, run, truth[dataset], p)
        if case.key in cases:
            raise EpaError(
                f"two files for case {case.key!r} ({cases[case.key].estimate}, {path}): give the"
                " patterns a {run}, or rename one",
                path=path,
            )
        cases[case.key] = case
        counts[pat.key] += 1
    for pat in pats:
        say(f"{pat.key} {pat.text!r}: {counts[pat.key]} run(s)")
    unknown = sorted(set(names) - {v["dataset"] for _, v in owner.values()})
    for name in unknown:
        skip(f"inputs.datasets.{name}", "names no dataset any estimate pattern matched")
    return truth, sorted(cases.values(), key=lambda c: (c.algorithm, c.dataset, c.run))
