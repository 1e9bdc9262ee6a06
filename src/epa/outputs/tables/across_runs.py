"""results/consistency/: RMSE(t) and NEES(t) across the runs of an algorithm on a dataset."""

from __future__ import annotations

from pathlib import Path

from epa.artifacts import files
from epa.artifacts.case import CaseFolder
from epa.metrics import consistency
from epa.outputs.tables.cells import cases_of, ok_runs
from epa.outputs.tables.results import CaseResult
from epa.outputs.tables.summary import records_csv


def write_across_runs(grid: list[CaseResult], results_dir) -> None:
    """results/consistency/<algorithm>/<dataset>.csv: RMSE(t) and (with covariance) NEES(t) over the
    reference stamps all runs share; results/consistency/summary.csv: their averages over time."""
    results_dir = Path(results_dir)
    rows = []
    for alg in sorted({c.algorithm for c in grid}):
        for ds in sorted({c.dataset for c in cases_of(grid, alg)}):
            runs = {}
            for c in ok_runs(grid, alg, ds):
                case = CaseFolder.of(results_dir, c.case)
                ape = c.ape or case.table("metrics", "ape.csv")  # read by collect, in parallel
                nees = case.path("consistency", "nees.csv")
                table = (
                    files.read_csv(nees)
                    if c.records.get("consistency", {}).get("available") and nees.exists()
                    else {}
                )
                runs[c.run] = {
                    "t": ape["t"],
                    "trans_m": ape["trans_m"],
                    "rot_deg": ape["rot_deg"],
                    "nees_pos": table.get("nees_pos"),
                    "nees_rot": table.get("nees_rot"),
                }
            if not runs:
                continue
            summary, table = consistency.across_runs(runs)
            files.write_csv(results_dir / "consistency" / alg / f"{ds}.csv", table)
            rows.append({"algorithm": alg, "dataset": ds, **summary})
    cols = [
        "algorithm",
        "dataset",
        "runs",
        "n_common",
        "rmse_pos_m",
        "rmse_rot_deg",
        "nees_pos_mean",
        "nees_rot_mean",
    ]
    files.write_text(results_dir / "consistency" / "summary.csv", records_csv(cols, rows))
