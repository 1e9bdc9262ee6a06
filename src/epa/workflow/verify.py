"""``epa verify RESULTS_DIR``: are these results what their recorded inputs and settings give?

1. every input file recorded in ``provenance.json`` is hashed again; a changed or missing one is
   named (and, unless ``force``, nothing is re-run: other inputs give other numbers);
2. the grid is run again from ``config.resolved.yaml`` into a temporary folder: Snakemake as a
   subprocess with the workflow's Snakefile, target ``tables`` (every stage, no per-case report or
   figure), in the working directory the inputs' relative paths were recorded from;
   (a case folder written by ``epa eval --out`` is evaluated again in this process instead);
3. every regenerated file is compared by the numeric contract (epa.outputs.contract): each printed
   output (``error_comparison.txt``, ``tables/*.tex``, ``summary.csv``, ``comparison.{txt,tex}``,
   ``success_curves.csv``, ``consistency/summary.csv``, mode rpg's ``rpg_*.txt``) as text, each
   record (every case's stage artifacts, ``consistency/<alg>/<dataset>.csv``) number by number. Exit
   status 0 only when every printed output is identical (or differs only by digits flipped at a
   rounding boundary) and every record is within the contract; ``exact`` compares bytes instead.
A package's members that its ``package.json`` does not list are named, never extracted, and make
the verdict NOT VERIFIED (exit status 1): a package vouches only for what it lists.
See docs/reproducibility.md.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from epa.core.errors import EpaError
from epa.outputs import contract, provenance
from epa.workflow import package, relocate
from epa.workflow.compared import REPORT_FOLDER, compared_files, kind_of
from epa.workflow.relocate import check_inputs


def compare(a, b, *, exact: bool = False, rewrites=()) -> list[contract.Comparison]:
    """Every file of :func:`compared_files` of the results ``a`` against the regenerated ``b``
    (in whose text each ``(new, recorded)`` of ``rewrites`` is put back as recorded: the inputs'
    paths, when they were found elsewhere)."""
    a, b = Path(a), Path(b)
    names = compared_files(a)
    extra = [n for n in compared_files(b) if kind_of(n) == "printed" and n not in names]
    out = []
    for name in names + extra:
        kind = kind_of(name)
        if exact:
            out.append(_compare_bytes(a, b, name, kind, rewrites))
        else:
            out.append(contract.compare_files(a, b, name, kind, rewrites))
    return out


def _compare_bytes(a: Path, b: Path, name: str, kind: str, rewrites=()) -> contract.Comparison:
    pa, pb = a / name, b / name
    if not pb.is_file():
        return contract.Comparison(name, kind, contract.Verdict.MISSING)
    if not pa.is_file():
        return contract.Comparison(name, kind, contract.Verdict.EXTRA)
    got = contract.rewritten(pb.read_bytes(), rewrites)
    if pa.read_bytes() == got:
        return contract.Comparison(name, kind, contract.Verdict.IDENTICAL)
    la, lb = pa.read_bytes().splitlines(), got.splitlines()
    i = next((k for k, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
    text_a, text_b = (
        lines[i].decode("utf-8", "replace") if i < len(lines) else "" for lines in (la, lb)
    )
    return contract.Comparison(
        name, kind, contract.Verdict.DIFFERS, contract.Place(f"line {i + 1}", text_a, text_b)
    )


def summary_rows(results: list[contract.Comparison]) -> list[tuple[str, str, str]]:
    """The closing table: each printed output, then the records grouped by their file in every
    case (``cases/*/*/*/06_metrics/metrics.json``); the verdict of a group is its worst."""
    rows = [(r.name, str(r.verdict), _worst_text(r)) for r in results if r.kind == "printed"]
    groups: dict[str, list[contract.Comparison]] = {}
    for r in results:
        if r.kind == "record":
            groups.setdefault(_group(r.name), []).append(r)
    for group, members in groups.items():
        worst = max(members, key=_badness)
        verdict = str(worst.verdict)
        if len(members) > 1:
            group = f"{group} ({len(members)})"
        rows.append((group, verdict, _worst_text(worst, with_name=len(members) > 1)))
    return rows


def _group(name: str) -> str:
    parts = name.split("/")
    if parts[0] == "cases" and len(parts) > 4:  # rpg's files are named by their distances
        return "/".join(["cases", "*", "*", "*", *parts[4:-1], re.sub(r"\d+", "N", parts[-1])])
    if parts[0] == "consistency" and len(parts) == 3:
        return "consistency/*/*.csv"
    return name


def _badness(r: contract.Comparison) -> tuple[bool, bool, float]:
    """Failing first, then not identical, then the larger difference over its tolerance."""
    place = r.worst
    ratio = place.diff / place.tol if place and place.tol > 0 else 0.0  # nan > 0 is False
    return not r.ok, r.verdict != contract.Verdict.IDENTICAL, ratio


def _worst_text(r: contract.Comparison, with_name: bool = False) -> str:
    if r.worst is None:
        return ""
    text = r.worst.describe()
    return f"{r.name}: {text}" if with_name else text


def default_snakefile() -> Path | None:
    """The workflow of this checkout (src/epa/workflow -> the repository's Snakefile)."""
    root = provenance.source_checkout()
    return root / "Snakefile" if root else None


def _workdir(doc: dict, snakefile: Path | None) -> Path:
    recorded = Path(doc.get("volatile", {}).get("workdir") or ".")
    if recorded.is_dir():
        return recorded
    return snakefile.parent if snakefile else Path.cwd()


def regenerate_grid(
    results: Path,
    into: Path,
    snakefile: Path,
    workdir: Path,
    cores: int,
    log,
    folders: dict | None = None,
) -> None:
    """The grid again from ``config.resolved.yaml`` (its folders replaced by ``folders``) into
    ``into/results``: Snakemake's ``tables`` target in a subprocess."""
    import yaml

    from epa.workflow import settings

    cfg = settings.load_yaml(results / provenance.CONFIG)
    cfg.update(folders or {}, results_dir=str(into / "results"))
    configfile = into / "config.yaml"
    configfile.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(snakefile)]
    cmd += ["--configfile", str(configfile), "--cores", str(cores), "--nolock", "tables"]
    print("epa verify: " + " ".join(cmd[2:]) + f"  (in {workdir})", file=log, flush=True)
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[2])  # this epica, not another installed one
    env["PYTHONPATH"] = (
        src + os.pathsep + env.get("PYTHONPATH", "") if env.get("PYTHONPATH") else src
    )
    run = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True)
    if run.returncode != 0:
        tail = "\n".join((run.stdout + run.stderr).strip().splitlines()[-15:])
        raise EpaError(f"the re-run failed (snakemake exit status {run.returncode}):\n{tail}")


def regenerate_case(
    doc: dict, results: Path, into: Path, workdir: Path, paths: dict | None = None
) -> None:
    """A case folder of ``epa eval --out``: every stage again, in this process (its reference and
    estimate at ``paths`` where they were found elsewhere)."""
    from epa import readers
    from epa.workflow import chain, settings

    cfg = settings.load_yaml(results / provenance.CONFIG)
    cfg["report"] = {**cfg["report"], "per_case": False}  # the report is not compared
    case = {**doc["case"], **(paths or {})}
    arrays = any(  # `epa eval --artifacts` wrote them: regenerate them to compare them
        p.is_file() and p.suffix != ".json"
        for p in results.glob("[0-9][0-9]_*/*")
        if p.parent.name != REPORT_FOLDER
    )
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        chain.run_case(
            case["reference"],
            case["estimate"],
            str(into / "results"),
            cfg,
            write_arrays=arrays,
            ref_source=readers.options(cfg, "reference"),
            est_source=readers.options(cfg, "estimate", algorithm=case["algorithm"]),
        )
    finally:
        os.chdir(cwd)


def _read_results(results: Path) -> dict:
    try:
        doc = provenance.read(results)
    except OSError as exc:
        raise EpaError(
            f"no {provenance.PROVENANCE} ({exc.strerror}): not a results folder of epica >= "
            "0.1 (the tables rule or `epa eval --out` writes it)",
            path=str(results),
        ) from None
    if not (results / provenance.CONFIG).is_file():
        raise EpaError(f"no {provenance.CONFIG}", path=str(results))
    return doc


def _inputs_as_recorded(doc: dict, workdir: Path, force: bool, log) -> list[str] | None:
    """The recorded inputs hashed again where they were read; None: stop (not re-run)."""
    problems = check_inputs(doc, workdir)
    n = len(doc.get("inputs", []))
    if not problems:
        print(f"epa verify: {n} inputs have their recorded sha256", file=log)
        return []
    print(f"epa verify: {len(problems)} of {n} inputs differ from the record:", file=log)
    for line in problems:
        print("  " + line, file=log)
    if force:
        return problems
    print("epa verify: not re-run (--force re-runs anyway): NOT VERIFIED", file=log)
    return None


def _inputs_found(doc: dict, data: list, log) -> relocate.Located | None:
    """The recorded inputs looked for by sha256 under ``data``; None: some are not there."""
    located = relocate.locate(doc, data)
    n = len([r for r in doc.get("inputs", []) if not r.get("missing")])
    print(f"epa verify: {len(located.found)} of {n} inputs found by sha256 under --data", file=log)
    for line in located.said:
        print("  " + line, file=log)
    for line in located.problems:
        print("  " + line, file=log)
    if located.problems:
        print("epa verify: not re-run: NOT VERIFIED", file=log)
        return None
    return located


def verify(
    results_dir,
    *,
    cores: int = 2,
    snakefile=None,
    keep=None,
    force: bool = False,
    exact: bool = False,
    data=None,
    json_path=None,
    log=None,
) -> int:
    """Check, regenerate, compare; prints what it finds and writes ``verify.json``. 0: reproduced
    (within the numeric contract, or byte for byte with ``exact``); 1: not (a raised EpaError:
    cannot verify). ``results_dir`` is a results folder or a package of ``epa pack``; ``data``
    folders where the inputs are now (found by sha256)."""
    log = log or sys.stdout
    tmp = tempfile.TemporaryDirectory(prefix="epa-verify-")
    try:
        return _verify(
            Path(results_dir), Path(tmp.name), cores, snakefile, keep, force, exact,
            list(data or []), json_path, log,
        )  # fmt: skip
    finally:
        tmp.cleanup()


def _verify(source, tmp, cores, snakefile, keep, force, exact, data, json_path, log) -> int:
    results = source
    damaged: list[str] = []
    unlisted: list[str] = []
    if package.is_package(source):
        results, inputs, damaged, unlisted = package.unpack(source, tmp / "package")
        print(
            f"epa verify: unpacked {source} ({len(damaged)} files changed since packed)", file=log
        )
        if unlisted:
            print(
                f"epa verify: {len(unlisted)} archive members not listed in {package.MANIFEST}, "
                "not extracted and not vouched for:",
                file=log,
            )
            for name in unlisted:
                print("  " + name, file=log)
        data += [inputs] if inputs else []
        json_path = json_path or Path.cwd() / (source.name.split(".")[0] + ".verify.json")
    doc = _read_results(results)
    snakefile = Path(snakefile) if snakefile else default_snakefile()
    if doc.get("kind") == "grid" and snakefile is None:
        raise EpaError("no Snakefile beside this epica (not a checkout): give --snakefile")
    into = Path(keep) if keep else tmp / "again"
    into.mkdir(parents=True, exist_ok=True)
    folders, workdir = None, _workdir(doc, snakefile)
    rewrites: list[tuple[str, str]] = []  # (new text, recorded text)
    if data:
        located = _inputs_found(doc, data, log)
        if located is None:
            return 1
        from epa.workflow import settings

        cfg = settings.load_yaml(results / provenance.CONFIG)
        folders, rewrites = relocate.lay_out(doc, cfg, located.found, into / "inputs")
        problems: list[str] | None = []
    else:
        problems = _inputs_as_recorded(doc, workdir, force, log)
        if problems is None:
            return 1
    if doc.get("kind") == "case":
        regenerate_case(doc, results, into, workdir, folders)
    else:
        regenerate_grid(results, into, snakefile, workdir, cores, log, folders)
    compared = compare(results, into / "results", exact=exact, rewrites=rewrites)
    compared += [
        contract.Comparison(n, "packed", contract.Verdict.DIFFERS, contract.Place(n, "packed", "changed"))
        for n in damaged
    ]  # fmt: skip
    ok = report(compared, exact=exact, log=log) and not problems
    how = "byte for byte" if exact else "within the numeric contract"
    verdict = "REPRODUCED " + how if ok else "NOT VERIFIED"
    if not ok and any(not c.ok for c in compared) and (versions := version_difference(doc)):
        # another epica may compute some numbers otherwise (CHANGELOG.md): say so, not only "differs"
        print(f"epa verify: {versions}: see CHANGELOG.md for what changed between them", file=log)
        verdict += f": {versions}"
    if unlisted:  # what it lists may reproduce; the archive as a whole is not what was packed
        ok = False
        verdict = f"NOT VERIFIED: {len(unlisted)} archive members not listed in {package.MANIFEST}"
    out = Path(json_path) if json_path else (into if keep else results) / "verify.json"
    try:
        _write_json(out, source, doc, compared, verdict, problems or [], exact, unlisted)
    except EpaError:
        if json_path:
            raise
        out = Path.cwd() / "verify.json"  # a results folder one may not write to (a read-only copy)
        _write_json(out, source, doc, compared, verdict, problems or [], exact, unlisted)
    print(f"epa verify: {verdict} (the verdicts: {out})", file=log)
    return 0 if ok else 1


def version_difference(doc: dict) -> str | None:
    """The words ``results made by epica X, this is Y`` where ``provenance.json`` records another
    epica version than the running one (None where they agree or none is recorded)."""
    from epa import __version__

    recorded = (doc.get("epica") or {}).get("version")
    if not recorded or recorded == __version__:
        return None
    return f"results made by epica {recorded}, this is epica {__version__}"


def _write_json(
    out: Path, source, doc, compared, verdict: str, problems, exact: bool, unlisted=()
) -> None:
    """verify.json: the verdict, what was compared and how, and both machines' numerics."""
    from epa import __version__
    from epa.artifacts import files

    record = {
        "verified": str(source),
        "verdict": verdict,
        "rule": "bytes" if exact else "numeric contract (docs/reproducibility.md)",
        "epica": __version__,
        "inputs_not_as_recorded": problems,
        "unlisted_members": list(unlisted),
        "table": [dict(zip(("file", "verdict", "worst"), row)) for row in summary_rows(compared)],
        "files": [c.to_dict() for c in compared],
        "numerics": {"recorded": doc.get("numerics"), "here": provenance.environment()["numerics"]},
    }
    files.write_json(out, record)


def report(compared: list[contract.Comparison], *, exact: bool, log) -> bool:
    """Print what the comparison found: counts, every file that is not identical (the records that
    differ first, at most 50 lines), and the closing table. True when all of it passes."""
    for kind, label in (("printed", "printed outputs"), ("record", "records")):
        mine = [r for r in compared if r.kind == kind]
        counts: dict[str, int] = {}
        for r in mine:
            counts[str(r.verdict)] = counts.get(str(r.verdict), 0) + 1
        said = ", ".join(f"{k} {v}" for k, v in counts.items()) or "none"
        print(f"epa verify: {len(mine)} {label}: {said}", file=log)
    failed = [r for r in compared if not r.ok]
    flipped = [r for r in compared if r.verdict == contract.Verdict.ROUNDING]
    for r in (failed + flipped)[:50]:
        print("  " + r.line(), file=log)
        for place in r.flips[1:10]:
            print("    also " + place.describe(), file=log)
    if len(failed + flipped) > 50:
        print(f"  ... and {len(failed + flipped) - 50} more", file=log)
    rows = summary_rows(compared)
    width = max(len(r[0]) for r in rows) if rows else 4
    vwidth = max(len(r[1]) for r in rows) if rows else 7
    print(f"\n{'file':<{width}}  {'verdict':<{vwidth}}  worst difference", file=log)
    for name, verdict, worst in rows:
        print(f"{name:<{width}}  {verdict:<{vwidth}}  {worst}".rstrip(), file=log)
    print("", file=log)
    return not failed


def run(args) -> int:
    return verify(
        args.results,
        cores=args.cores,
        snakefile=args.snakefile,
        keep=args.keep,
        force=args.force,
        exact=args.exact,
        data=args.data,
        json_path=args.json,
    )
