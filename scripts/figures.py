"""The figures rule's body: the grid's figures (PNG and vector PDF, with their plot bundles) from
summary.csv, success_curves.csv and results/consistency/, and each dataset's from the per-case
reports' files.

The ``figures`` rule calls :func:`write` in a worker of the workflow's pool (``run:``, where
numpy, pandas and epa are imported already). It also runs on its own, on a results folder
whose tables are written:

    python scripts/figures.py [--configfile config/config.yaml]
"""

import argparse
import os
import sys

from epa.outputs import report


def summary_segments(results_dir) -> list[float]:
    """The segment lengths of summary.csv's drift-rate columns: those the tables wrote, the
    datasets' own where they differ (overrides, ``metrics.segments: auto``)."""
    with open(os.path.join(results_dir, "summary.csv"), encoding="utf-8") as fh:
        header = fh.readline().strip().split(",")
    prefix, suffix = "drift_rate_", "m_pct"
    return [
        float(c[len(prefix) : -len(suffix)])
        for c in header
        if c.startswith(prefix) and c.endswith(suffix)
    ]


def write(results_dir, log_path, workers: int = 1, per_dataset: bool = True) -> list:
    segments = summary_segments(results_dir)
    written = report.write_grid_figures(
        results_dir, segments, workers=workers, per_dataset=per_dataset
    )
    with open(log_path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(map(str, written)) + "\n")
    return written


def main(argv=None) -> int:
    """Without Snakemake: the results folder from the grid's config."""
    from epa.core.errors import EpaError
    from epa.workflow import settings, terminal

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    args = parser.parse_args(argv)
    terminal.show_warnings()  # epa's warnings on stderr, as in the workflow
    try:
        cfg = settings.from_configfile(args.configfile)
    except EpaError as exc:
        print(f"epa: error: {exc.one_line()}", file=sys.stderr)
        return 2
    results = cfg["results_dir"]
    written = write(
        results,
        f"{results}/logs/figures.log",
        workers=os.cpu_count(),
        per_dataset=cfg["report"]["per_case"],
    )
    print(f"{len(written)} files in {results}/figures")
    return 0


if __name__ == "__main__":
    sys.exit(main())
