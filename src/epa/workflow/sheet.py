"""Case discovery from a run sheet (``inputs.sheet``): a TSV file, one row per run, with the columns
``algorithm dataset run estimate reference`` and optional per-row source settings, each row checked
by ``sheet.schema.yaml`` (the schema Snakemake's ``validate`` takes) and every path it names checked.
A mistake is one line naming the sheet's line. Relative paths start at the working directory, as
the config's folders do. Blank lines and lines starting with ``#`` are not rows.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from epa.artifacts.case import Case
from epa.core.errors import EpaError

SCHEMA_PATH = Path(__file__).with_name("sheet.schema.yaml")
REQUIRED = ("algorithm", "dataset", "run", "estimate", "reference")
# per-row source settings: the estimate's under their own name, the reference's with a prefix
SOURCE_COLUMNS = ("format", "topic", "frames", "time_unit")
REFERENCE_PREFIX = "reference_"


@lru_cache(maxsize=1)
def schema() -> dict:
    import yaml

    with open(SCHEMA_PATH, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def read(path) -> list[tuple[int, dict]]:
    """The rows of a sheet as (line number, {column: value}), the header checked against the schema."""
    path = Path(path)
    if not path.is_file():
        what = "is a folder, not a sheet" if path.is_dir() else "not found"
        raise EpaError(f"inputs.sheet: {what}", path=str(path))
    lines = [
        (k, line.rstrip("\r\n"))
        for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise EpaError("inputs.sheet: no header line and no row", path=str(path))
    header_line, header = lines[0]
    columns = [c.strip() for c in header.split("\t")]
    known = schema()["properties"]
    for column in columns:
        if column not in known:
            raise EpaError(
                f"unknown column {column!r} (the columns: {', '.join(known)})",
                path=str(path),
                line=header_line,
            )
    for column in REQUIRED:
        if column not in columns:
            raise EpaError(
                f"no column {column!r} (a sheet needs {' '.join(REQUIRED)}, tab-separated)",
                path=str(path),
                line=header_line,
            )
    rows = []
    for k, line in lines[1:]:
        fields = [f.strip() for f in line.split("\t")]
        if len(fields) != len(columns):
            raise EpaError(
                f"{len(fields)} tab-separated fields, the header has {len(columns)}",
                path=str(path),
                line=k,
            )
        rows.append((k, dict(zip(columns, fields))))
    return rows


def _check_row(row: dict, where: dict) -> None:
    import jsonschema

    errors = list(jsonschema.Draft202012Validator(schema()).iter_errors(row))
    if errors:
        err = errors[0]
        column = ".".join(str(p) for p in err.path) or "(row)"
        raise EpaError(f"column {column}: {err.message}", **where)


def _check_path(value: str, column: str, where: dict, *, bag: bool = True) -> Path:
    p = Path(value)
    if p.is_dir() and not (bag and (p / "metadata.yaml").is_file()):
        raise EpaError(f"{column} {value!r} is a folder, not a trajectory file", **where)
    if not p.exists():
        raise EpaError(f"{column} {value!r} not found", **where)
    return p


def _source(row: dict, prefix: str, base: dict) -> dict:
    """``base`` (the config's settings of this source) with the row's own settings over it."""
    opts = dict(base)
    for column in SOURCE_COLUMNS:
        value = row.get(prefix + column, "")
        if value:
            opts[column] = value.replace(",", " ").split() if column == "frames" else value
    return opts


def discover(cfg: dict, *, source: str, say) -> tuple[dict[str, Path], list[Case]]:
    """The reference per dataset and the cases the sheet lists."""
    from epa import readers

    sheet = cfg["inputs"]["sheet"]
    truth: dict[str, tuple[Path, int]] = {}
    cases: dict[str, tuple[Case, int]] = {}
    for k, row in read(sheet):
        where: dict[str, Any] = {"path": str(sheet), "line": k}
        _check_row(row, where)
        estimate = _check_path(row["estimate"], "estimate", where)
        reference = _check_path(row["reference"], "reference", where)
        ds = row["dataset"]
        if ds in truth and truth[ds][0] != reference:
            raise EpaError(
                f"dataset {ds!r} has reference {str(reference)!r} here and"
                f" {str(truth[ds][0])!r} on line {truth[ds][1]}",
                **where,
            )
        truth.setdefault(ds, (reference, k))
        est_opts = _source(row, "", readers.options(cfg, "estimate", algorithm=row["algorithm"]))
        if row.get("timing"):
            timing = _check_path(row["timing"], "timing", where, bag=False)
            est_opts["timing"] = str(timing.resolve())  # an absolute path: no {run} to fill in
        ref_opts = _source(row, REFERENCE_PREFIX, readers.options(cfg, "reference", dataset=ds))
        case = Case(row["algorithm"], ds, row["run"], reference, estimate, ref_opts, est_opts)
        if case.key in cases:
            raise EpaError(
                f"case {case.key!r} is also on line {cases[case.key][1]}: one row per run", **where
            )
        cases[case.key] = (case, k)
    found = sorted((c for c, _ in cases.values()), key=lambda c: (c.algorithm, c.dataset, c.run))
    algorithms = sorted({c.algorithm for c in found})
    say(
        f"inputs.sheet {sheet}: {len(found)} run(s) of {len(algorithms)} algorithm(s) on"
        f" {len(truth)} dataset(s)"
    )
    return {ds: p for ds, (p, _) in sorted(truth.items())}, found
