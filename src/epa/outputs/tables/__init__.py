"""What the tables rule writes: error_comparison.txt (``text``, ``ov_eval``), one LaTeX table per
.tex file (``latex``, cells in ``cells``, their marks in ``marks``) with its cells as numbers in a
.csv beside it and in cells.csv (``tidy``), summary.csv and success_curves.csv (``summary``),
comparison.txt/.tex (``comparison``), results/consistency/ (``across_runs``), mode rpg's
rpg_translation_rmse.txt, rpg_rel_err.txt and tables/rpg_*.tex (``rpg``), all read from the case
folders (``results``) and written by ``write.make``."""

from epa.outputs.tables.latex import latex_escape
from epa.outputs.tables.ov_eval import ov_eval_text
from epa.outputs.tables.results import CaseResult, has_result
from epa.outputs.tables.write import cell_tables, failure_report, make, mode_files, table_names

__all__ = [
    "CaseResult",
    "cell_tables",
    "failure_report",
    "has_result",
    "latex_escape",
    "make",
    "mode_files",
    "ov_eval_text",
    "table_names",
]
