"""The figures rule's body: the grid's figures (PNG and vector PDF, with their plot bundles) from
summary.csv, success_curves.csv and results/consistency/, and each dataset's from the per-case
reports' files.

Snakemake runs it for the ``figures`` rule (``script:``). It also runs on its own, on a results folder
whose tables are written:

    python scripts/figures.py [--configfile config/config.yaml]
"""

import argparse
import os
import sys

from epa.outputs import report


def write(results_dir, segments, log_path, workers: int = 1, per_dataset: bool = True) -> list:
    written = report.write_grid_figures(
        results_dir, segments, workers=workers, per_dataset=per_dataset
    )
    with open(log_path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(map(str, written)) + "\n")
    return written


def main(argv=None) -> int:
    """Without Snakemake: the results folder and segment lengths from the grid's config."""
    from epa.core.errors import EpaError
    from epa.workflow import settings

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    args = parser.parse_args(argv)
    try:
        cfg = settings.from_configfile(args.configfile)
    except EpaError as exc:
        print(f"epa: error: {exc.one_line()}", file=sys.stderr)
        return 2
    results = cfg["results_dir"]
    written = write(
        results,
        cfg["metrics"]["segments"],
        f"{results}/logs/figures.log",
        workers=os.cpu_count(),
        per_dataset=cfg["report"]["per_case"],
    )
    print(f"{len(written)} files in {results}/figures")
    return 0


if __name__ == "__main__":
    if "snakemake" in globals():  # run by the figures rule
        sm = globals()["snakemake"]
        write(
            sm.params.results,
            sm.params.segments,
            sm.log[0],
            workers=sm.threads,
            per_dataset=sm.params.per_dataset,
        )
    else:
        sys.exit(main())
