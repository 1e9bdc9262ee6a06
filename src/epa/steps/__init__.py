"""The three Steps, pure functions on arrays: ``sync`` (Step 1 time offset and association),
``calibrate`` (Step 2 hand-eye extrinsic), ``align`` (Step 3 world-frame fit); ``plan`` (the
evaluation plan) and ``rpg`` (rpg_trajectory_evaluation's association and alignment, in its
arithmetic)."""

__all__ = ["align", "calibrate", "plan", "rpg", "sync"]
