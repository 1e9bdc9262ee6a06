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


# Whether this process reads every file with pandas' C parser (it has paid pandas' import on
# purpose: the workflow's workers and the tables script say so) or only files large enough to
# repay the import. Either parser gives the same doubles; this is the cost, chosen by the caller.
_PARSER = {"pandas": False}


def use_pandas_parser(on: bool = True) -> None:
    """Read every file with pandas' C parser from now on (the caller has imported pandas)."""
    _PARSER["pandas"] = on


def pandas_parser() -> bool:
    """Whether :func:`use_pandas_parser` was called in this process (since the last reset)."""
    return _PARSER["pandas"]


register("core.runtime.parser", reset=lambda: use_pandas_parser(False))


def names() -> tuple[str, ...]:
    """The registered caches, in registration order."""
    return tuple(_RESETS)


def reset() -> None:
    """Empty every registered cache: the process then behaves as a new one would."""
    for clear in list(_RESETS.values()):
        clear()
