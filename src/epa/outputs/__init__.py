"""Outputs: what a researcher reads.

- :mod:`epa.outputs.tables`: error_comparison.txt, LaTeX tables, summary.csv, RMSE/NEES across runs.
- :mod:`epa.outputs.figures`: plot bundles and their rendering (the only place matplotlib is imported).
- :mod:`epa.outputs.report`: per-case metrics.json, metrics_summary.csv, reports (en, zh), figures,
  the case zip; the grid figures.
"""
