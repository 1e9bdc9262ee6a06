"""The process's state outside its arguments, in one registry: each module-level cache (parsed
references, kept figures, the table index, the worker pool, ...) registers here with the way to
empty it, and :func:`reset` empties them all, e.g. between two grids in one process or in a test."""

from __future__ import annotations

from collections.abc import Callable

_RESETS: dict[str, Callable[[], None]] = {}


def register(name: str, cache=None, *, reset: Callable[[], None] | None = None):
    """Register ``cache`` (emptied by its ``clear()``) or a ``reset`` function under ``name``.

    Parameters
    ----------
    name : str
        The cache's name, ``module.what`` (a module re-imported registers its new cache again).
    cache : dict-like, optional
        A cache that ``clear()`` empties.
    reset : callable, optional
        What empties state that is not one container (a pool to shut down, a patch to undo).

    Returns
    -------
    The ``cache`` given (None with ``reset``), so a module writes ``_X = runtime.register(..., {})``.
    """
    if (cache is None) == (reset is None):
        raise TypeError(f"runtime.register({name!r}): give a cache or a reset function, not both")
    _RESETS[name] = cache.clear if reset is None else reset
    return cache


def names() -> tuple[str, ...]:
    """The registered caches, in registration order."""
    return tuple(_RESETS)


def reset() -> None:
    """Empty every registered cache: the process then behaves as a new one would."""
    for clear in list(_RESETS.values()):
        clear()
