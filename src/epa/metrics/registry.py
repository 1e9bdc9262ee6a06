"""The metrics a case is scored by beyond ATE, RPE and drift: one module each, listed here once. The
metrics stage, the per-case arrays, the paper tables and ``summary.csv`` iterate this list (see
:mod:`epa.metrics.spec` for what a module declares). Its order is the order of their columns and
tables."""

from __future__ import annotations

from epa.metrics import ate_2d, consistency, efficiency, kitti, per_axis, rpg, sim3_check

REGISTRY = (ate_2d, consistency, efficiency, kitti, per_axis, rpg, sim3_check)


def computed_in(stage: str) -> tuple:
    """The registered metrics a stage computes."""
    return tuple(m for m in REGISTRY if m.STAGE == stage)
