"""Metrics: every number a case is scored by, one module per family.

- :mod:`epa.metrics.accuracy`: APE/ATE, distance and time RPE, drift rate, evo-style RPE pairs.
- :mod:`epa.metrics.drift`: fail segments, success rate, drift-valid metrics, the global gate.
- :mod:`epa.metrics.relations`: evo's pose relations and statistics block.
- :mod:`epa.metrics.statistics`: the comparison of algorithms (Wilcoxon, Mann-Whitney).
- The registered metrics (:mod:`epa.metrics.registry`, declared as :mod:`epa.metrics.spec` says):
  ``ate_2d``, ``consistency`` (NEES, ±3σ), ``efficiency`` (frame times, EA-Drift), ``kitti`` (the
  devkit metric), ``per_axis``, ``rpg`` (rpg_trajectory_evaluation's statistics, mode rpg only),
  ``sim3_check`` (the scale and SE3 ATE beside a Sim3 ATE).
"""

__all__ = [
    "accuracy",
    "ate_2d",
    "consistency",
    "drift",
    "efficiency",
    "kitti",
    "per_axis",
    "registry",
    "relations",
    "rpg",
    "sim3_check",
    "spec",
    "statistics",
]
