"""The three Steps, pure functions on arrays: ``sync`` (Step 1 time offset and association),
``calibrate`` (Step 2 hand-eye extrinsic), ``align`` (Step 3 world-frame fit)."""

__all__ = ["align", "calibrate", "sync"]
