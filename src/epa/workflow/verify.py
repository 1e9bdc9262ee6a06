"""``epa verify RESULTS_DIR``: are these results what their recorded inputs and settings give?

1. every input file recorded in ``provenance.json`` is hashed again; a changed or missing one is
   named (and, unless ``force``, nothing is re-run: other inputs give other numbers);
2. the grid is run again from ``config.resolved.yaml`` into a temporary folder: Snakemake as a
   subprocess with the workflow's Snakefile, target ``tables`` (every stage, no per-case report or
   figure), in the working directory the inputs' relative paths were recorded from;
   (a case folder written by ``epa eval --out`` is evaluated again in this process instead);
3. every table (``error_comparison.txt``, ``tables/*.tex``, ``comparison.{txt,tex}``,
   ``success_curves.csv``, ``consistency/summary.csv``, mode rpg's ``rpg_*.txt``), ``summary.csv`` and every case's
   ``metrics.json`` is compared byte for byte. Exit status 0 only when all are identical.
See docs/reproducibility.md.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from epa.core.errors import EpaError
from epa.outputs import provenance

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
    """The files ``epa verify`` compares, relative to ``results`` (those that exist there)."""
    results = Path(results)
    names = [n for n in GRID_FILES if (results / n).is_file()]
    names += sorted(str(p.relative_to(results)) for p in (results / "tables").glob("*.tex"))
    names += sorted(  # the metrics stage's (10_report/ holds a copy for the reader)
        str(p.relative_to(results))
        for p in results.glob("cases/**/metrics.json")
        if p.is_file() and "10_report" not in p.parts
    )
    names += sorted(
        str(p.relative_to(results)) for p in results.glob("[0-9][0-9]_*/metrics.json")
    )  # a case folder of `epa eval --out`
    return names


def compare(a, b) -> list[str]:
    """Differences between two results folders over :func:`compared_files` of either, one line each."""
    a, b = Path(a), Path(b)
    out = []
    for name in sorted(set(compared_files(a)) | set(compared_files(b))):
        pa, pb = a / name, b / name
        if not pa.is_file():
            out.append(f"only in the regenerated results: {name}")
        elif not pb.is_file():
            out.append(f"not regenerated: {name}")
        elif pa.read_bytes() != pb.read_bytes():
            out.append(f"differs: {name}")
    return out


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
    path = Path(__file__).resolve().parents[3] / "Snakefile"
    return path if path.is_file() else None


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
    case = doc["case"]
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        chain.run_case(
            case["reference"],
            case["estimate"],
            str(into / "results"),
            cfg,
            write_arrays=False,
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
    log=None,
) -> int:
    """Check, regenerate, compare; prints what it finds. 0: identical; 1: not (a raised EpaError:
    cannot verify)."""
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
        names = compared_files(results)
        diffs = compare(results, into / "results")
    finally:
        tmp.cleanup()
    if diffs:
        print(f"epa verify: {len(diffs)} of {len(names)} files are not identical:", file=log)
        for line in diffs[:50]:
            print("  " + line, file=log)
        if len(diffs) > 50:
            print(f"  ... and {len(diffs) - 50} more", file=log)
    ok = not diffs and not problems
    verdict = "IDENTICAL" if ok else "NOT VERIFIED"
    print(
        f"epa verify: {len(names) - len(diffs)} of {len(names)} files byte-identical: {verdict}",
        file=log,
    )
    return 0 if ok else 1


def add_parser(sub) -> None:
    v = sub.add_parser(
        "verify",
        help="check a results folder's inputs against provenance.json and regenerate it byte for byte",
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


def run(args) -> int:
    return verify(
        args.results, cores=args.cores, snakefile=args.snakefile, keep=args.keep, force=args.force
    )
