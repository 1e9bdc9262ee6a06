"""Inputs found where they live now (``epa verify --data DIR``): every input ``provenance.json``
records is looked for by its sha256 under the given folders, whatever its new path or name, and the
recorded layout is laid again as links in a temporary folder, so the grid re-runs on exactly the
recorded inputs. See docs/reproducibility.md, "A reviewer's path".
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from epa.core.errors import EpaError
from epa.outputs import provenance


def check_inputs(doc: dict, workdir) -> list[str]:
    """Each recorded input that is missing or whose bytes changed, one line each."""
    problems = []
    for rec in doc.get("inputs", []):
        path = Path(workdir) / rec["path"]
        if rec.get("missing"):
            if path.exists():
                problems.append(f"was missing, now present: {rec['path']}")
            continue
        if not path.is_file():
            problems.append(f"missing: {rec['path']}")
            continue
        size = path.stat().st_size
        digest = provenance.sha256(path)
        if digest != rec["sha256"]:
            problems.append(
                f"changed: {rec['path']} (size {rec['size']} -> {size}, "
                f"sha256 {rec['sha256'][:12]}... -> {digest[:12]}...)"
            )
    return problems


@dataclass
class Located:
    """Where each recorded input was found (recorded path -> file), what was said about it, and what
    could not be found."""

    found: dict[str, Path] = field(default_factory=dict)
    said: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def _wanted(doc: dict) -> list[dict]:
    return [r for r in doc.get("inputs", []) if not r.get("missing")]


def _walk(folders) -> list[Path]:
    files = []
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise EpaError("--data: not a folder", path=str(folder))
        for root, dirs, names in os.walk(folder, followlinks=True):
            dirs.sort()
            files += [Path(root) / n for n in sorted(names)]
    return files


def locate(doc: dict, folders) -> Located:
    """Find every recorded input under ``folders`` by size, then sha256 (only files of a recorded
    size are hashed). One input found in several places takes the one whose path ends as recorded."""
    records = _wanted(doc)
    sizes = {r["size"] for r in records}
    names = {Path(r["path"]).name for r in records}
    by_hash: dict[str, list[Path]] = {}
    by_name: dict[str, list[Path]] = {}
    for path in _walk(folders):
        if path.name in names:
            by_name.setdefault(path.name, []).append(path)
        try:
            if path.stat().st_size not in sizes:
                continue
        except OSError:
            continue
        by_hash.setdefault(provenance.sha256(path), []).append(path)
    out = Located()
    for rec in records:
        tail = rec.get("relative") or Path(rec["path"]).name
        places = _as_recorded_first(by_hash.get(rec["sha256"], []), tail)
        if places:
            out.found[rec["path"]] = places[0]
            out.said.append(f"found {rec['path']} at {places[0]}")
            continue
        same_name = [  # the same path within its folder (another run's run2.txt is not it)
            p for p in by_name.get(Path(rec["path"]).name, []) if p.as_posix().endswith("/" + tail)
        ]
        if same_name:
            other = provenance.sha256(same_name[0])
            out.problems.append(
                f"found with the right name but the wrong hash: {same_name[0]} (recorded "
                f"{rec['path']}: sha256 {rec['sha256'][:12]}..., this one {other[:12]}...)"
            )
        else:
            out.problems.append(
                f"not found under --data: {rec['path']} ({rec['size']} bytes, sha256 "
                f"{rec['sha256'][:12]}...)"
            )
    return out


def _as_recorded_first(paths: list[Path], tail: str) -> list[Path]:
    """The paths that end as the input's recorded path within its folder first."""
    return sorted(paths, key=lambda p: (not p.as_posix().endswith("/" + tail), str(p)))


def _place(rec: dict, roots: dict[str, str]) -> tuple[str, str]:
    """The config folder an input belongs to and its path within it (recorded, or worked out from
    the config for a record made before epica recorded it)."""
    if rec.get("folder") and rec.get("relative"):
        return rec["folder"], rec["relative"]
    place = provenance.where(rec["path"], roots)
    if not place:
        raise EpaError(
            "cannot lay out this input again: it is under none of the config's folders "
            f"({', '.join(roots) or 'none'})",
            path=rec["path"],
        )
    return place["folder"], place["relative"]


def _case_place(rec: dict, case: dict) -> tuple[str, str]:
    """A case's input: the reference (a file, or a ROS 2 bag folder's file) or else beside the
    estimate (the estimate, its bag folder's files, its timing file)."""
    path, ref = os.path.normpath(rec["path"]), os.path.normpath(str(case["reference"]))
    side = "reference" if path == ref or path.startswith(ref + os.sep) else "estimate"
    base = os.path.dirname(os.path.normpath(str(case[side])))
    return side, Path(os.path.relpath(path, base or ".")).as_posix()


def lay_out(doc: dict, cfg: dict, found: dict[str, Path], into: Path) -> tuple[dict, list]:
    """Link every found input into ``into`` at its recorded place. Returns the config folders to run
    with (``truth_dir``, ``algorithms_dir``; a case's ``reference`` and ``estimate`` files) and the
    rewrites ``(new text, recorded text)`` that turn a regenerated record's paths into the recorded
    ones (``load.json`` names its estimate's path)."""
    kind = doc.get("kind")
    named = cfg.get("inputs") or {}
    if kind != "case" and named.get("sheet"):
        raise EpaError(
            "this grid named its inputs by a run sheet (inputs.sheet): --data cannot lay them out"
            " again yet; verify with the inputs where they were (no --data)"
        )
    roots = provenance.input_roots(kind, cfg, doc.get("case"))
    for rec in _wanted(doc):
        folder, relative = _case_place(rec, doc["case"]) if kind == "case" else _place(rec, roots)
        link = into / folder / relative
        link.parent.mkdir(parents=True, exist_ok=True)
        os.symlink(Path(found[rec["path"]]).resolve(), link)
    if kind == "case":
        case = doc["case"]
        new = {side: str(into / side / Path(case[side]).name) for side in ("reference", "estimate")}
        rewrites = [(new[side], str(case[side])) for side in ("reference", "estimate")]
        return new, rewrites
    folders = {key: str(into / key) for key in roots}
    rewrites = [(folders[key], roots[key]) for key in roots]
    if named.get("estimate"):  # the patterns, each from its root's new place
        return {"inputs": moved_patterns(named, roots, folders)}, sorted(
            rewrites, key=lambda r: -len(r[0])
        )
    return folders, sorted(rewrites, key=lambda r: -len(r[0]))


def moved_patterns(inputs: dict, roots: dict[str, str], new: dict[str, str]) -> dict:
    """``inputs`` with each pattern's root replaced by its new place."""

    def move(text: str) -> str:
        text = os.path.expanduser(text)
        base = provenance.pattern_root(text)
        for key, root in roots.items():
            place = provenance.where(base + "/x", {key: root})
            if place:
                inside = os.path.relpath(os.path.normpath(text), root)
                return os.path.join(new[key], inside)
        raise EpaError(f"cannot lay out the inputs of pattern {text!r} again")

    def moved(value):
        if isinstance(value, str):
            return move(value)
        if isinstance(value, list):
            return [move(v) for v in value]
        return {k: move(v) for k, v in value.items()}

    return {**inputs, **{k: moved(inputs[k]) for k in ("reference", "estimate")}}
