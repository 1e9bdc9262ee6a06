"""Metrics: every number a case is scored by, one module per family.

- :mod:`epa.metrics.accuracy`: APE/ATE, distance and time RPE, drift rate, evo-style RPE pairs.
- :mod:`epa.metrics.drift`: fail segments, success rate, drift-valid metrics, the global gate.
- :mod:`epa.metrics.relations`: evo's pose relations and statistics block.
- :mod:`epa.metrics.statistics`: the comparison of algorithms (Wilcoxon, Mann-Whitney).
- The registered metrics, one module each (their list: :data:`epa.metrics.registry.MODULES`),
  declared as :mod:`epa.metrics.spec` says: ``consistency`` (NEES, ±3σ), ``efficiency`` (frame
  times, EA-Drift), ``kitti`` (the devkit metric), ``rpg`` (rpg_trajectory_evaluation's
  statistics), ``sim3_check`` (the scale and SE3 ATE beside a Sim3 ATE), the benchmarks' own
  protocols, ...
"""

import pkgutil

# every module of the package, as they are (none named twice)
__all__ = sorted(m.name for m in pkgutil.iter_modules(__path__))
