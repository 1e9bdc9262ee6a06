"""Case discovery from path patterns: ``inputs.reference`` and ``inputs.estimate`` name the files
where they lie, with the wildcards ``{dataset}``, ``{algorithm}`` and ``{run}`` anywhere in the path
(any order, any depth, repeated: each occurrence takes the same value). ``inputs.estimate`` is one
pattern, a list, or a mapping ``{algorithm: pattern}`` for layouts that do not name the algorithm.
An estimate's ``{dataset}`` finds its reference by name or through ``inputs.datasets`` (``MH01:
MH_01_easy``); the case is named by the reference's dataset, so every form of the inputs gives the
same case names. Without ``{run}`` a run is named by its file name without the extension, as in the
OpenVINS layout.

A wildcard stands for one or more characters within one folder. It can take a constraint, as
Snakemake's ``wildcard_constraints`` do: inline (``{run,[0-9]+}``) or for every pattern
(``inputs.constraints: {run: "[0-9]+"}``; the inline one wins), a regular expression its whole
value must match. An estimate's ``{dataset}`` takes only the names of datasets that have a
reference, so ``laptop_{algorithm}_{dataset}`` reads ``laptop_vislam_ba_MH_01`` as ``vislam_ba``
and ``MH_01`` whatever the underscores. A path with two readings is a one-line error naming both.

What each pattern matched is printed (``say``); every file a pattern matched and discovery did not
take is named with the reason. A pattern matching nothing, an unknown wildcard, two patterns
matching one file and two files for one case are each a one-line error.
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property
from itertools import islice
from pathlib import Path

from epa.artifacts.case import Case, plain_name
from epa.core.errors import EpaError
from epa.workflow.side_files import is_side_file, timing_side_files

WILDCARDS = ("algorithm", "dataset", "run")
REFERENCE_WILDCARDS = ("dataset",)
# a field's text: anything but braces, save a regular expression's counted repeat ({2}, {1,3})
_FIELD = re.compile(r"\{((?:[^{}]|\{\d*,?\d*\})*)\}")


def constraint(regex: str, key: str, source: str) -> re.Pattern:
    """A wildcard's constraint compiled; not a regular expression: a one-line error naming ``key``."""
    try:
        return re.compile(regex)
    except re.error as err:
        raise EpaError(f"{key}: {regex!r} is no regular expression ({err})", path=source) from None


@dataclass(frozen=True)
class Pattern:
    """One pattern: its config key (for messages), its text, a fixed algorithm (mapping form), and
    the constraints of ``inputs.constraints`` as (wildcard, regex) pairs."""

    key: str
    text: str
    algorithm: str | None = None
    constraints: tuple[tuple[str, str], ...] = ()

    @cached_property
    def _fields(self) -> list[tuple[str, str | None]]:
        """(wildcard, its inline constraint or None) of each field, in order."""
        out = []
        for field in _FIELD.findall(self.text):
            name, comma, regex = field.partition(",")
            out.append((name.strip(), regex.strip() if comma else None))
        return out

    def wildcards(self) -> list[str]:
        return [name for name, _ in self._fields]

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
        self.compiled(source)

    def compiled(self, source: str = "config") -> dict[str, re.Pattern]:
        """Each constrained wildcard's regular expression: its inline one, else the config's."""
        inline: dict[str, str] = {}
        for name, regex in self._fields:
            if regex is None:
                continue
            if not regex or inline.get(name, regex) != regex:
                what = "an empty constraint" if not regex else "two different constraints"
                raise EpaError(f"{self.key}: {what} for {{{name}}} in {self.text!r}", path=source)
            inline[name] = regex
        out = {}
        for name, regex in self.constraints:
            if name in self.wildcards() and name not in inline:
                out[name] = constraint(regex, f"inputs.constraints.{name}", source)
        for name, regex in inline.items():
            out[name] = constraint(regex, f"{self.key}: {{{name},{regex}}}", source)
        return out

    @cached_property
    def _parts(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The literal texts (one more than the fields) and the wildcard of each field."""
        parts = _FIELD.split(self.text)
        return tuple(parts[0::2]), tuple(name for name, _ in self._fields)

    def glob(self) -> str:
        """The shell pattern of the files it may match (each wildcard a ``*`` within one folder)."""
        literals, names = self._parts
        return "".join(
            glob.escape(lit) + ("*" if k < len(names) else "") for k, lit in enumerate(literals)
        )

    @cached_property
    def _shapes(self) -> tuple[re.Pattern, re.Pattern]:
        """The pattern as a greedy and as a lazy regular expression (constraints aside): where both
        read a path alike, it has that one reading (they find the first and the last one in the
        order of :meth:`readings`), read in C: about 4 us a path, where :meth:`readings` takes 20-50."""
        literals, names = self._parts
        out = []
        for any_ in ("[^/]+", "[^/]+?"):
            seen: set[str] = set()
            text = re.escape(literals[0])
            for name, literal in zip(names, literals[1:], strict=True):
                text += f"(?P={name})" if name in seen else f"(?P<{name}>{any_})"
                text += re.escape(literal)
                seen.add(name)
            out.append(re.compile(text + r"\Z"))
        return out[0], out[1]

    def readings(self, path: str, accept: Callable[[str, str], bool]) -> Iterator[dict[str, str]]:
        """Every way the pattern reads ``path`` (its wildcards' values), each value one or more
        characters within one folder that ``accept(wildcard, value)`` takes; the reading with the
        longest first value leads (then the longest second, ...), as a greedy regular expression's
        would. Cost: the occurrences of the literal after each wildcard within its folder."""
        literals, names = self._parts
        head, tail = literals[0], literals[-1]
        end = len(path) - len(tail)
        if names and path.startswith(head) and path.endswith(tail) and end > len(head):
            yield from self._walk(path, 0, len(head), end, {}, accept)

    def _walk(self, s: str, i: int, pos: int, end: int, values: dict, accept) -> Iterator[dict]:
        literals, names = self._parts
        name, after, last = names[i], literals[i + 1], i == len(names) - 1
        folder = s.find("/", pos, end)  # a value never crosses into the next folder
        folder = end if folder < 0 else folder
        if name in values:  # a repeated wildcard: the same value again
            e = pos + len(values[name])
            ok = s.startswith(values[name], pos) and (e == end if last else s.startswith(after, e))
            ends = [e] if ok and e <= folder else []
        elif last:
            ends = [end] if pos < end <= folder else []
        elif after:
            ends = []
            e = s.rfind(after, pos + 1, folder + len(after))
            while e > pos:
                ends.append(e)
                e = s.rfind(after, pos + 1, e - 1 + len(after))
        else:  # two wildcards side by side: every split
            ends = list(range(folder, pos, -1))
        fixed = name in values
        for e in ends:
            if not fixed:
                if not accept(name, s[pos:e]):
                    continue
                values[name] = s[pos:e]
            if last:
                yield dict(values)
            else:
                yield from self._walk(s, i + 1, e + len(after), end, values, accept)
            if not fixed:
                del values[name]

    def matches(
        self, source: str = "config", known: Callable[[str], bool] | None = None
    ) -> dict[str, dict[str, str]]:
        """{path: its wildcards' values} of every path the pattern matches (hidden ones aside).
        With ``known`` (an estimate's datasets that have a reference), ``{dataset}`` reads only
        such a name where one fits; where none does, the greedy reading stands (discovery then says
        its dataset has no reference). Two readings of known datasets: an error naming both."""
        rules = self.compiled(source)

        def fits(name: str, value: str) -> bool:
            rule = rules.get(name)
            return rule is None or rule.fullmatch(value) is not None

        def fits_known(name: str, value: str) -> bool:
            return fits(name, value) and (name != "dataset" or known is None or known(value))

        greedy, lazy = self._shapes
        found = {}
        for path in sorted(glob.glob(self.glob())):
            shape = greedy.match(path)
            if shape is None:
                continue
            one = shape.groupdict()
            other = lazy.match(path)  # never None where the greedy one matched
            if other is not None and one == other.groupdict():  # one reading: does it fit?
                if all(fits_known(k, v) for k, v in one.items()):
                    found[path] = one
                elif known is not None and all(fits(k, v) for k, v in one.items()):
                    found[path] = one  # a dataset without a reference: discovery says so
                continue
            first = list(islice(self.readings(path, fits_known), 2))
            if len(first) == 2:
                raise EpaError(
                    f"{self.key} reads it two ways, {_said(first[0])} and {_said(first[1])}:"
                    f" {_settle(first[0], first[1])}",
                    path=path,
                )
            if not first and known is not None:
                first = list(islice(self.readings(path, fits), 1))
            if first:
                found[path] = first[0]
        return found


def _said(values: dict[str, str]) -> str:
    return ", ".join(f"{name} {value!r}" for name, value in values.items())


def _settle(one: dict[str, str], other: dict[str, str]) -> str:
    """What settles two readings: a constraint on a wildcard they read differently."""
    differ = [name for name in one if one[name] != other[name]]
    names = " or ".join("{" + name + "}" for name in differ)
    return f"constrain {names} ({{{differ[0]},<regex>}} or inputs.constraints.{differ[0]})"


def patterns(value, key: str, constraints: dict | None = None) -> list[Pattern]:
    """``inputs.<key>`` as patterns: a string, a list of strings, or {algorithm: pattern}."""
    home = os.path.expanduser  # `~/data/...` as a shell would read it
    rules = tuple(sorted((constraints or {}).items()))
    if isinstance(value, str):
        return [Pattern(f"inputs.{key}", home(value), None, rules)]
    if isinstance(value, list):
        return [Pattern(f"inputs.{key}.{k}", home(v), None, rules) for k, v in enumerate(value)]
    if not value:
        raise EpaError(f"inputs.{key}: an empty mapping names no pattern")
    for alg in value:
        if not plain_name(alg):
            raise EpaError(f"inputs.{key}.{alg}: an algorithm's name is one path component")
    return [Pattern(f"inputs.{key}.{alg}", home(v), alg, rules) for alg, v in value.items()]


def _owned(
    pats: list[Pattern], source: str, known: Callable[[str], bool] | None = None
) -> dict[str, tuple[Pattern, dict]]:
    """Each matched path with the one pattern that matched it (two: an error naming both)."""
    owner: dict[str, tuple[Pattern, dict]] = {}
    for pat in pats:
        found = pat.matches(source, known)
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


def _constraints(cfg: dict, source: str) -> dict[str, str]:
    """``inputs.constraints``, each a regular expression (else a one-line error naming its key)."""
    given = cfg["inputs"].get("constraints") or {}
    for name, regex in given.items():
        constraint(regex, f"inputs.constraints.{name}", source)
    return given


def references(cfg: dict, source: str, say, skip) -> dict[str, Path]:
    """The reference of each dataset, by ``inputs.reference``."""
    pats = patterns(cfg["inputs"]["reference"], "reference", _constraints(cfg, source))
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
    constraints = _constraints(cfg, source)
    pats = patterns(cfg["inputs"]["estimate"], "estimate", constraints)
    for pat in pats:
        need = ("dataset",) if pat.algorithm else ("algorithm", "dataset")
        allowed = ("dataset", "run") if pat.algorithm else WILDCARDS
        pat.check(allowed, need, source)
    every = patterns(cfg["inputs"]["reference"], "reference") + pats
    for name in constraints:
        if not any(name in pat.wildcards() for pat in every):
            raise EpaError(f"inputs.constraints.{name}: no pattern has {{{name}}}", path=source)
    owner = _owned(pats, source, known=lambda ds: names.get(ds, ds) in truth)
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
