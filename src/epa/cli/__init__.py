"""The ``epa`` command (``main``)."""

__all__ = ["main"]
