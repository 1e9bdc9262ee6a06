"""Metrics: every number a case is scored by.

- :mod:`epa.metrics.accuracy`: APE/ATE, distance and time RPE, drift rate, evo-style RPE pairs.
- :mod:`epa.metrics.relations`: evo's pose relations (trans_part, rot_part, full, angles, point
  distance) and statistics block.
- :mod:`epa.metrics.drift`: fail segments, success rate, drift-valid metrics, the global gate.
- :mod:`epa.metrics.consistency`: NEES and ±3σ from the estimate's covariance; RMSE(t)/NEES(t) across runs.
- :mod:`epa.metrics.efficiency`: frame-time statistics and EA-Drift.
- :mod:`epa.metrics.kitti`: the KITTI odometry devkit metric (100-800 m segments).
"""
