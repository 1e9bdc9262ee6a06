"""rpg_trajectory_evaluation (uzh-rpg) reproduced: ``epa rpg CASE_DIR`` reads rpg's folder and writes rpg's
statistics files with rpg's numbers. :mod:`epa.rpg.protocol` holds the arithmetic and documents rpg's
quirks; :mod:`epa.rpg.command` the files and the command line (see docs/protocols-rpg.md)."""

from epa.rpg.command import add_parser, evaluate, run, run_case
from epa.rpg.protocol import absolute_errors, align, associate, relative_errors, statistics

__all__ = [
    "absolute_errors",
    "add_parser",
    "align",
    "associate",
    "evaluate",
    "relative_errors",
    "run",
    "run_case",
    "statistics",
]
