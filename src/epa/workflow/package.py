"""A replication package (``epa pack RESULTS -o paper-results.tar.gz [--with-inputs]``): one archive
with a results folder's printed outputs and records, ``provenance.json``, ``config.resolved.yaml``,
the lock file, the epica version and a ``REPRODUCE.md`` with the two commands; with ``--with-inputs``
the inputs too, once per content (by sha256). ``epa verify paper-results.tar.gz [--data DIR]``
unpacks it, checks it, regenerates and compares (docs/reproducibility.md, "A reviewer's path").
"""

from __future__ import annotations

import io
import json
import re
import sys
import tarfile
from pathlib import Path
from typing import NamedTuple

from epa import __version__
from epa.core.errors import EpaError
from epa.outputs import provenance
from epa.workflow import compared, relocate

FORMAT = 1
MANIFEST = "package.json"
RESULTS = "results"  # the results folder inside the archive
INPUTS = "inputs"  # inputs/<sha256>, one per content
LOCK = "requirements.lock"
README = "REPRODUCE.md"


def packed_files(results: Path) -> list[str]:
    """What a package keeps of a results folder: the printed outputs and every case's records (the
    compared files of epa.workflow.verify but the arrays: 0.6 MB of the example's 128), the paper
    bundle, provenance and config."""
    names = [
        n
        for n in compared.compared_files(results)
        if compared.kind_of(n) == "printed" or n.endswith((".json", ".yaml"))
    ]
    names += sorted(
        str(p.relative_to(results))
        for p in (results / "paper").rglob("*")
        if p.is_file() and p.suffix in (".tex", ".pdf")
    )
    return [provenance.PROVENANCE, provenance.CONFIG, *names]


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(x) for x in re.findall(r"\d+", text)[:3])


def _reproduce_md(doc: dict, with_inputs: bool, name: str) -> str:
    epica = doc.get("epica", {})
    commit = epica.get("git_commit")
    where = f"epica {epica.get('version')}" + (f" (commit {commit})" if commit else "")
    data = "" if with_inputs else " --data /where/the/inputs/are"
    return (
        f"# Reproduce these results\n\nMade by {where}. In a checkout of that epica, two commands:\n\n"
        "```bash\n"
        f"pip install --require-hashes -r {LOCK} && pip install --no-deps -e .\n"
        f"epa verify {name}{data}\n"
        "```\n\n"
        "The first installs the exact versions the results were made with (every file's sha256 "
        "checked). The second unpacks this archive, finds every input by its sha256"
        + (" (they are in the archive)" if with_inputs else " under the folders given")
        + ", regenerates the results and compares them by epica's numeric contract: printed "
        "tables as text, records number by number. Exit status 0: reproduced. It writes "
        "`verify.json`, the verdict of every file, to attach to a review.\n"
    )


def pack(results, out, *, with_inputs: bool = False, data=None, log=None) -> Path:
    """Write the package of ``results`` to ``out``; returns ``out``. Its inputs (``with_inputs``) are
    read where they were recorded, or found by sha256 under ``data``."""
    log = log or sys.stdout
    results, out = Path(results), Path(out)
    try:
        doc = provenance.read(results)
    except OSError as exc:
        raise EpaError(
            f"no {provenance.PROVENANCE} ({exc.strerror}): not a results folder of epica",
            path=str(results),
        ) from None
    names = [n for n in packed_files(results) if (results / n).is_file()]
    inputs = _inputs(doc, data) if with_inputs else {}
    size = sum((results / n).stat().st_size for n in names)
    in_size = sum(r["size"] for r in inputs.values())
    print(
        f"epa pack: {len(names)} files of {results} ({size / 1e6:.1f} MB)"
        + (
            f" and {len(inputs)} inputs ({in_size / 1e6:.1f} MB, once per content)"
            if with_inputs
            else ""
        )
        + f" into {out}",
        file=log,
        flush=True,
    )
    lock = _lock_file()
    manifest = {
        "format": FORMAT,
        "epica": __version__,
        "results": RESULTS,
        "files": {n: provenance.sha256(results / n) for n in names},
        "inputs": {sha: {"size": r["size"], "paths": r["paths"]} for sha, r in inputs.items()},
        "lock": lock is not None,
    }
    tmp = out.with_name("." + out.name + ".part")
    try:
        with tarfile.open(tmp, "w:gz") as tar:
            _add_bytes(tar, MANIFEST, json.dumps(manifest, indent=2).encode())
            _add_bytes(tar, README, _reproduce_md(doc, with_inputs, out.name).encode())
            if lock is not None:
                tar.add(lock, LOCK)
            for n in names:
                tar.add(results / n, f"{RESULTS}/{n}")
            for sha, r in inputs.items():
                tar.add(r["file"], f"{INPUTS}/{sha}")
        tmp.replace(out)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise EpaError(f"cannot write: {exc.strerror}", path=str(out)) from None
    if lock is None:
        print(f"epa pack: no {LOCK} beside this epica (not a checkout): not packed", file=log)
    return out


def _inputs(doc: dict, data=None) -> dict[str, dict]:
    """The recorded inputs once per content: sha256 -> size, recorded paths, a file to read (where
    recorded, or found by sha256 under ``data``); one missing or changed is an error naming it."""
    workdir = Path(doc.get("volatile", {}).get("workdir") or ".")
    if data:
        located = relocate.locate(doc, data)
        problems, found = located.problems, located.found
    else:
        problems = relocate.check_inputs(doc, workdir)
        found = {r["path"]: workdir / r["path"] for r in doc.get("inputs", [])}
    if problems:
        raise EpaError(f"--with-inputs: {problems[0]} (--data DIR: where the inputs are now)")
    out: dict[str, dict] = {}
    for rec in doc.get("inputs", []):
        if rec.get("missing"):
            continue
        entry = out.setdefault(
            rec["sha256"], {"size": rec["size"], "paths": [], "file": found[rec["path"]]}
        )
        entry["paths"].append(rec["path"])
    return out


def _lock_file() -> Path | None:
    root = provenance.source_checkout()
    return root / LOCK if root and (root / LOCK).is_file() else None


def _add_bytes(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mode = 0o644
    tar.addfile(info, io.BytesIO(data))


# ----------------------------------------------------------------------------- unpacking
def is_package(path) -> bool:
    path = Path(path)
    return path.is_file() and path.name.endswith((".tar.gz", ".tgz", ".tar"))


class Unpacked(NamedTuple):
    results: Path  # the results folder
    inputs: Path | None  # the inputs folder, if packed
    changed: list[str]  # listed files whose bytes no longer match package.json
    unlisted: list[str]  # members package.json does not list: named, never extracted


def listed_members(manifest: dict) -> set[str]:
    """The archive members a package vouches for: its manifest, REPRODUCE.md, the lock file, each
    results file and each input that ``package.json`` names."""
    names = {MANIFEST, README} | ({LOCK} if manifest.get("lock") else set())
    names |= {f"{manifest.get('results', RESULTS)}/{n}" for n in manifest["files"]}
    return names | {f"{INPUTS}/{sha}" for sha in manifest.get("inputs") or {}}


def unpack(archive, into) -> Unpacked:
    """Unpack the members of ``archive`` that its ``package.json`` lists into ``into``; any other
    member is named in ``unlisted`` and not extracted (a package vouches only for what it lists).
    A file that is not such an archive, a cut-off one, or one from a newer epica is one line naming
    the archive."""
    archive, into = Path(archive), Path(into)
    try:
        with tarfile.open(archive, "r:*") as tar:
            members = tar.getmembers()
            if MANIFEST not in {m.name for m in members}:
                raise EpaError(f"not an epica package: no {MANIFEST} in it", path=str(archive))
            manifest_file = tar.extractfile(MANIFEST)
            if manifest_file is None:  # a link or folder of that name
                raise EpaError(
                    f"not an epica package: its {MANIFEST} is not a file", path=str(archive)
                )
            manifest = json.load(manifest_file)
            _check_manifest(manifest, archive)
            for m in members:  # what tarfile's "data" filter refuses, on every Python 3.11
                parts = Path(m.name).parts
                if Path(m.name).is_absolute() or ".." in parts or not (m.isfile() or m.isdir()):
                    raise EpaError(f"refused: the archive holds {m.name!r}", path=str(archive))
            listed = listed_members(manifest)
            folders = {str(parent) for name in listed for parent in Path(name).parents}
            take = [m for m in members if m.isfile() and m.name in listed]
            unlisted = sorted(
                {m.name for m in members if m.name not in listed and m.name not in folders}
            )
            tar.extractall(into, members=take)
    except (tarfile.TarError, EOFError, OSError, ValueError) as exc:
        raise EpaError(f"cannot unpack: {_why(exc)}", path=str(archive)) from None
    results = into / manifest["results"]
    changed = [
        name
        for name, sha in sorted(manifest["files"].items())
        if not (results / name).is_file() or provenance.sha256(results / name) != sha
    ]
    inputs = into / INPUTS
    return Unpacked(results, inputs if inputs.is_dir() else None, changed, unlisted)


def _why(exc: Exception) -> str:
    text = str(exc)
    if "could not be opened successfully" in text or "not a gzip file" in text:
        return "not a tar.gz archive"
    if isinstance(exc, EOFError) or "unexpected end of data" in text:
        return "the archive is cut off (an incomplete download or copy?)"
    if isinstance(exc, json.JSONDecodeError):
        return f"{MANIFEST} is not JSON"
    return f"the archive is damaged ({text.splitlines()[0] if text else type(exc).__name__})"


def _check_manifest(manifest: dict, archive: Path) -> None:
    if not isinstance(manifest, dict) or not isinstance(manifest.get("files"), dict):
        raise EpaError(f"not an epica package: {MANIFEST} is not one", path=str(archive))
    made_by = str(manifest.get("epica", "?"))
    if manifest.get("format", FORMAT) > FORMAT or _version(made_by) > _version(__version__):
        raise EpaError(
            f"made by epica {made_by}, newer than this epica {__version__}: install epica "
            f"{made_by} (its {README} says how)",
            path=str(archive),
        )


# ----------------------------------------------------------------------------- the command
def run(args) -> int:
    pack(args.results, args.out, with_inputs=args.with_inputs, data=args.data)
    return 0
