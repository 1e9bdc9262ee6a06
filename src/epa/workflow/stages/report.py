"""Report: the case's documents, figures and zip, from its artifacts only (10_report/).
matplotlib is imported only here."""

from __future__ import annotations

from epa.artifacts.case import CaseData
from epa.artifacts.stage import Stage

NAME = "report"


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    """Only where the artifacts are written (the workflow; ``epa eval --report``)."""
    if not cfg["report"]["per_case"] or not write_arrays:
        summary = {
            "available": False,
            "reason": "report.per_case is off" if write_arrays else "no artifacts written",
        }
    else:
        from epa.outputs import report  # tables and figures: only where a report is written

        folder = data.folder
        name = "/".join(folder.root.parts[-3:])
        # from the artifacts alone, as the workflow's report job reads them
        summary = {"available": True, **report.write_case_report(type(data)(folder), name, cfg)}
    data.folder.write_record(NAME, "report.json", summary)


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("report", "truth_dir", "load", "sources"),  # the inputs in the report's provenance
    records=("report.json",),
)
