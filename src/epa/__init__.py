"""epica: trajectory evaluation for SLAM and VIO (import package ``epa``)."""

__version__ = "0.1.0"
