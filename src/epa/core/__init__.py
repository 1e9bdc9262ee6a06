"""Values and maths with no I/O: the trajectory type, rotations, stamp and pair arithmetic, errors,
and the registry of the process's caches (``runtime``).

Every other layer may import from here; nothing here imports from the rest of ``epa``.
"""

__all__ = ["errors", "geometry", "runtime", "stamps", "trajectory"]
