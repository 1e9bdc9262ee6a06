"""``epa verify`` (regenerate a results folder or package and compare it by the numeric contract) and
``epa pack`` (a replication package); their work is in epa.workflow.verify and epa.workflow.package,
imported only when the command runs."""

from __future__ import annotations

from epa.cli.common import deprecated_alias


def add_parsers(sub) -> None:
    _add_verify(sub)
    _add_pack(sub)


def _add_verify(sub) -> None:
    v = sub.add_parser(
        "verify",
        help="check a results folder's inputs against provenance.json, regenerate it and compare "
        "by the numeric contract (docs/reproducibility.md)",
    )
    v.set_defaults(func=_verify)
    v.add_argument(
        "results", help="a results folder, an `epa eval --out` folder or a package of `epa pack`"
    )
    v.add_argument("--cores", type=int, default=2, help="cores of the re-run (default 2)")
    v.add_argument("--snakefile", help="the workflow (default: this checkout's Snakefile)")
    v.add_argument(
        "--keep", help="regenerate into this folder and keep it (default: a temporary one)"
    )
    v.add_argument(
        "--force", action="store_true", help="re-run and compare even when inputs changed"
    )
    v.add_argument(
        "--data",
        action="append",
        metavar="DIR",
        help="a folder where the inputs are now (repeatable): each recorded input is found by its "
        "sha256 under them, whatever its path or name",
    )
    v.add_argument(
        "--json",
        metavar="FILE",
        help="write the verdicts here (default: RESULTS/verify.json, or NAME.verify.json in this "
        "folder for a package, or KEEP/verify.json with --keep)",
    )
    v.add_argument(
        "--exact",
        action="store_true",
        help="compare byte for byte (a check on the machine that made the results)",
    )


def _add_pack(sub) -> None:
    p = sub.add_parser(
        "pack",
        help="write a replication package: a results folder's outputs, provenance, lock file and "
        "REPRODUCE.md in one archive (docs/reproducibility.md)",
    )
    p.set_defaults(func=_pack)
    p.add_argument("results", help="a results folder (or an `epa eval --out` folder)")
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("-o", "--out", help="the archive to write (.tar.gz)")
    deprecated_alias(out, "--output", "--out", dest="out")
    p.add_argument(
        "--with-inputs",
        action="store_true",
        help="also pack every input, once per content (its size is said before writing)",
    )
    p.add_argument(
        "--data",
        action="append",
        metavar="DIR",
        help="with --with-inputs: a folder where the inputs are now (found by sha256)",
    )


def _verify(args) -> int:
    from epa.workflow import verify

    return verify.run(args)


def _pack(args) -> int:
    from epa.workflow import package

    return package.run(args)
