"""Outputs: what a researcher reads.

- :mod:`epa.outputs.tables`: error_comparison.txt, LaTeX tables, summary.csv, comparison, RMSE/NEES
  across runs (one module per output).
- :mod:`epa.outputs.report`: a case's 10_report/ (documents, bundles, figures, zip) and the grid
  figures; :mod:`epa.outputs.case_report` writes the report a person reads.
- :mod:`epa.outputs.figures`: plot bundles and their rendering (the only place matplotlib is
  imported); :mod:`epa.outputs.recording`: Rerun recordings.
- :mod:`epa.outputs.provenance`: what made a results folder; :mod:`epa.outputs.paper`: results/paper/.
- :mod:`epa.outputs.contract`: the numeric contract, when two results of the same inputs agree.
- :mod:`epa.outputs.parallel`: the once-per-grid scripts' work in forked processes.
"""

__all__ = [
    "case_report",
    "contract",
    "figures",
    "paper",
    "parallel",
    "provenance",
    "recording",
    "report",
    "tables",
]
