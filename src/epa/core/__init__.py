"""Values and maths with no I/O: the trajectory type, rotations, stamp and pair arithmetic, errors.

Every other layer may import from here; nothing here imports from the rest of ``epa``.
"""

__all__ = ["errors", "geometry", "stamps", "trajectory"]
