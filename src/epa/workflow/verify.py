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
See docs/reproducibility.md.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from epa.artifacts.case import FOLDERS
from epa.core.errors import EpaError
from epa.outputs import contract, provenance

REPORT_FOLDER = FOLDERS["report"]
GRID_FILES = (
    "error_comparison.txt",
    "summary.csv",
    "comparison.txt",
    "comparison.tex",
    "success_curves.csv",
    "consistency/summary.csv",
    "rpg_translation_rmse.txt",  # mode rpg
    "rpg_rel_err.txt",
)


def compared_files(results) -> list[str]:
    """The files ``epa verify`` compares, relative to ``results`` (those that exist there): the
    printed outputs, then the records."""
    results = Path(results)
    names = [n for n in GRID_FILES if (results / n).is_file()]
    names += sorted(str(p.relative_to(results)) for p in (results / "tables").glob("*.tex"))
    records = [  # every stage's artifacts (10_report/ holds copies for the reader)
        *results.glob("cases/*/*/*/[0-9][0-9]_*/**/*"),
        *results.glob("consistency/*/*.csv"),
        *results.glob("[0-9][0-9]_*/**/*"),  # a case folder of `epa eval --out`
    ]
    names += sorted(
        str(p.relative_to(results))
        for p in records
        if p.is_file() and REPORT_FOLDER not in p.parts and not p.name.startswith(".")
    )
    return names


def kind_of(name: str) -> str:
    """``printed`` (a table a reader reads) or ``record`` (full-precision numbers)."""
    return "printed" if name in GRID_FILES or name.startswith("tables/") else "record"


def compare(a, b, *, exact: bool = False) -> list[contract.Comparison]:
    """Every file of :func:`compared_files` of the results ``a`` against the regenerated ``b``."""
    a, b = Path(a), Path(b)
    names = compared_files(a)
    extra = [n for n in compared_files(b) if kind_of(n) == "printed" and n not in names]
    out = []
    for name in names + extra:
        kind = kind_of(name)
        if exact:
            out.append(_compare_bytes(a, b, name, kind))
        else:
            out.append(contract.compare_files(a, b, name, kind))
    return out


def _compare_bytes(a: Path, b: Path, name: str, kind: str) -> contract.Comparison:
    pa, pb = a / name, b / name
    if not pb.is_file():
        return contract.Comparison(name, kind, contract.Verdict.MISSING)
    if not pa.is_file():
        return contract.Comparison(name, kind, contract.Verdict.EXTRA)
    if pa.read_bytes() == pb.read_bytes():
        return contract.Comparison(name, kind, contract.Verdict.IDENTICAL)
    la, lb = pa.read_bytes().splitlines(), pb.read_bytes().splitlines()
    i = next((k for k, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
    text = [lines[i].decode("utf-8", "replace") if i < len(lines) else "" for lines in (la, lb)]
    return contract.Comparison(
        name, kind, contract.Verdict.DIFFERS, contract.Place(f"line {i + 1}", *text)
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


def _badness(r: contract.Comparison) -> tuple[int, float]:
    order = 0 if r.ok else 1
    ratio = r.worst.diff / r.worst.tol if r.worst and r.worst.tol and r.worst.tol > 0 else 0.0
    return order * 2 + (r.verdict != contract.Verdict.IDENTICAL), ratio if ratio == ratio else 0.0


def _worst_text(r: contract.Comparison, with_name: bool = False) -> str:
    if r.worst is None:
        return ""
    text = r.worst.describe()
    return f"{r.name}: {text}" if with_name else text


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
    doc: dict, results: Path, into: Path, snakefile: Path, workdir: Path, cores: int, log
) -> None:
    import yaml

    from epa.workflow import settings

    cfg = settings.load_yaml(results / provenance.CONFIG)
    cfg["results_dir"] = str(into / "results")
    configfile = into / "config.yaml"
    configfile.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    cmd = [
        sys.executable,
        "-m",
        "snakemake",
        "--snakefile",
        str(snakefile),
        "--configfile",
        str(configfile),
        "--cores",
        str(cores),
        "--nolock",
        "tables",
    ]
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


def regenerate_case(doc: dict, results: Path, into: Path, workdir: Path) -> None:
    """A case folder of ``epa eval --out``: every stage again, in this process."""
    from epa import readers
    from epa.workflow import chain, settings

    cfg = settings.load_yaml(results / provenance.CONFIG)
    cfg["report"] = {**cfg["report"], "per_case": False}  # the report is not compared
    case = doc["case"]
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


def verify(
    results_dir,
    *,
    cores: int = 2,
    snakefile=None,
    keep=None,
    force: bool = False,
    exact: bool = False,
    log=None,
) -> int:
    """Check, regenerate, compare; prints what it finds. 0: reproduced (within the numeric contract,
    or byte for byte with ``exact``); 1: not (a raised EpaError: cannot verify)."""
    log = log or sys.stdout
    results = Path(results_dir)
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
    snakefile = Path(snakefile) if snakefile else default_snakefile()
    workdir = _workdir(doc, snakefile)
    problems = check_inputs(doc, workdir)
    n = len(doc.get("inputs", []))
    if problems:
        print(f"epa verify: {len(problems)} of {n} inputs differ from the record:", file=log)
        for line in problems:
            print("  " + line, file=log)
        if not force:
            print("epa verify: not re-run (--force re-runs anyway): NOT VERIFIED", file=log)
            return 1
    else:
        print(f"epa verify: {n} inputs have their recorded sha256", file=log)
    if doc.get("kind") == "grid" and snakefile is None:
        raise EpaError("no Snakefile beside this epica (not a checkout): give --snakefile")
    tmp = tempfile.TemporaryDirectory(prefix="epa-verify-")
    into = Path(keep) if keep else Path(tmp.name)
    into.mkdir(parents=True, exist_ok=True)
    try:
        if doc.get("kind") == "case":
            regenerate_case(doc, results, into, workdir)
        else:
            regenerate_grid(doc, results, into, snakefile, workdir, cores, log)
        compared = compare(results, into / "results", exact=exact)
    finally:
        tmp.cleanup()
    ok = report(compared, exact=exact, log=log) and not problems
    how = "byte for byte" if exact else "within the numeric contract"
    print(f"epa verify: {'REPRODUCED ' + how if ok else 'NOT VERIFIED'}", file=log)
    return 0 if ok else 1


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


def add_parser(sub) -> None:
    v = sub.add_parser(
        "verify",
        help="check a results folder's inputs against provenance.json, regenerate it and compare "
        "by the numeric contract (docs/reproducibility.md)",
    )
    v.add_argument("results", help="a results folder (or an `epa eval --out` folder)")
    v.add_argument("--cores", type=int, default=2, help="cores of the re-run (default 2)")
    v.add_argument("--snakefile", help="the workflow (default: this checkout's Snakefile)")
    v.add_argument(
        "--keep", help="regenerate into this folder and keep it (default: a temporary one)"
    )
    v.add_argument(
        "--force", action="store_true", help="re-run and compare even when inputs changed"
    )
    v.add_argument(
        "--exact",
        action="store_true",
        help="compare byte for byte (a check on the machine that made the results)",
    )


def run(args) -> int:
    return verify(
        args.results,
        cores=args.cores,
        snakefile=args.snakefile,
        keep=args.keep,
        force=args.force,
        exact=args.exact,
    )
