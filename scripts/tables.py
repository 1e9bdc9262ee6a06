"""The tables rule's body: read every case's artifacts and write error_comparison.txt, the LaTeX
tables, summary.csv, comparison.txt/.tex, results/consistency/; on its own also provenance.json with
config.resolved.yaml (what made them: docs/reproducibility.md; in the workflow the provenance rule
writes these two).

The ``tables`` rule calls :func:`write` in a worker of the workflow's pool (``run:``, where
numpy, pandas and epa are imported already). It also runs on its own, on a results folder
a grid has filled, with the grid's config:

    python scripts/tables.py [--configfile config/config.yaml]
"""

import argparse
import os
import sys
from pathlib import Path

from epa.core import runtime
from epa.core.errors import EpaError
from epa.outputs import provenance, tables
from epa.readers import text

# pyarrow's reader parses every artifact from 32 KB on (epa.artifacts.files): 0.05 s to import,
# where pandas took 0.3-0.5 s of the serial tail
if not text.use_arrow():
    import pandas  # noqa: F401 - its C parser instead

WORKFLOW_DIR = Path(__file__).resolve().parents[1]
# a large artifact pyarrow declines (a value that is not finite) is read by pandas' C parser (3-4x
# loadtxt on large tables, imported only then); the same doubles whichever parses
runtime.use_pandas_parser()


def write(cases, results_dir, settings, idle_truths, log_path, workers=1) -> list[tuple[str, str]]:
    failed = tables.make(cases, results_dir, settings, idle_truths, workers)
    lines = [f"{len(cases)} cases, {len(failed)} without a result"]
    lines += [f"{key}: {reason}" for key, reason in failed]
    with open(log_path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    return failed


def write_provenance(results_dir, cfg, inputs, workflow_dir) -> None:
    """provenance.json and config.resolved.yaml (the inputs hashed now, after the tables)."""
    doc = provenance.document("grid", cfg, inputs, workflow_dir=workflow_dir)
    provenance.write(results_dir, doc)


def main(argv=None) -> int:
    """Without Snakemake: resolve the config and discover the cases as the Snakefile does."""
    from epa.workflow import chain, discovery, settings, terminal

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    args = parser.parse_args(argv)
    terminal.show_warnings()  # epa's warnings on stderr, as in the workflow
    try:
        cfg = settings.from_configfile(args.configfile)
        truth, cases = discovery.discover_config(cfg, source=args.configfile)
        used = {c.dataset for c in cases}
        idle = (
            {}
            if cfg["mode"] != "ov_eval"
            else {d: str(p) for d, p in sorted(truth.items()) if d not in used}
        )
        results = cfg["results_dir"]
        failed = write(
            sorted(c.key for c in cases),
            results,
            chain.tables_settings(cfg),  # what the tables rule passes
            idle,
            f"{results}/logs/tables.log",
            workers=os.cpu_count() or 1,
        )
        inputs = provenance.grid_inputs(cfg, cases, idle)
        write_provenance(results, cfg, inputs, WORKFLOW_DIR)
    except EpaError as exc:
        print(f"epa: error: {exc.one_line()}", file=sys.stderr)
        return 2
    print(f"{len(cases)} cases, {len(failed)} without a result: tables in {results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
