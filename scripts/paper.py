"""The paper rule's body: results/paper/ (every LaTeX table, every grid figure as PDF, paper.tex).

The ``paper`` rule calls :func:`write` in a worker of the workflow's pool (``run:``, where
numpy, pandas and epa are imported already). It also runs on its own, on a results folder
whose tables and figures are written:

    python scripts/paper.py [--configfile config/config.yaml]
"""

import argparse
import sys
from pathlib import Path

from epa.outputs import paper

CAPTIONS = Path(__file__).resolve().parents[1] / "docs" / "captions"


def write(results_dir, caption_dir, log_path) -> list:
    written = paper.write_paper(results_dir, paper.figure_captions(caption_dir))
    with open(log_path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(map(str, written)) + "\n")
    return written


def main(argv=None) -> int:
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
    written = write(results, CAPTIONS, f"{results}/logs/paper.log")
    print(f"{len(written)} files in {results}/paper")
    return 0


if __name__ == "__main__":
    sys.exit(main())
