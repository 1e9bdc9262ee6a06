"""The files of a results folder that ``epa verify`` compares and ``epa pack`` keeps: the printed
outputs (a reader's tables) and the records (every stage artifact at full precision). See
docs/reproducibility.md, "The numeric contract"."""

from __future__ import annotations

from pathlib import Path

from epa.artifacts.stage import folder

REPORT_FOLDER = folder("report")
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
    records = [  # every stage's artifacts (the report's folder holds copies for the reader)
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
