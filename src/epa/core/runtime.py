"""The process's state outside its arguments, in one registry: each module-level cache (parsed
references, kept figures, the table index, the worker pool, ...) registers here with the way to
empty it, and :func:`reset` empties them all, e.g. between two grids in one process or in a test."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")
U = TypeVar("U")

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


def _switch(name: str) -> tuple[Callable[..., None], Callable[[], bool]]:
    """A process-wide setting, off until its setter is called and again after :func:`reset`: the
    setter (``on=True``) and the getter."""
    state = {"on": False}

    def set_on(on: bool = True) -> None:
        state["on"] = on

    register(name, reset=lambda: set_on(False))
    return set_on, lambda: state["on"]


# Whether this process reads every file with pandas' C parser (it has paid pandas' import on
# purpose: the workflow's workers and the tables script say so) or only files large enough to
# repay the import. Either parser gives the same doubles; this is the cost, chosen by the caller.
use_pandas_parser, pandas_parser = _switch("core.runtime.parser")

# Whether this process runs one case alone (`epa eval`), so that a stage may give a second thread
# work that releases the GIL (the estimate's parse beside the reference's, Step 1's two forward
# transforms). Off elsewhere: the workflow runs a worker per core, which a second thread would
# oversubscribe. Either way the same bits: each thread computes what one thread did.
use_spare_thread, spare_thread = _switch("core.runtime.spare_thread")


# glibc's malloc gives freed memory back to the system at once above its thresholds (the trim
# threshold grows only to 64 MB): a stage's temporaries of 1M poses (8-24 MB each, dozens a stage)
# then come as fresh pages, each zeroed by the kernel on its first touch. Keeping up to 1 GB of
# freed memory in the heap for reuse took the 1M pair's system time from 2-4 s to 1.0-1.5 s, and
# its peak from 1.32 to 1.24-1.25 GB (docs/performance.md). Values in a C int: mallopt's type.
_KEEP_FREED_BYTES = 1 << 30
# older glibc refuses an mmap threshold above 32 MiB (HEAP_MAX_SIZE / 2): the 8-24 MB temporaries
# then still come from the heap
_MMAP_THRESHOLD_CAP = 32 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_ARENA_MAX = -1, -3, -8  # glibc's malloc.h


def _mallopt():
    """glibc's mallopt, or None (another platform, musl)."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt  # absent from musl's libc
    except (OSError, AttributeError):
        return None
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return mallopt


def keep_freed_memory() -> bool:
    """Let this process's malloc keep freed memory for reuse (glibc only; elsewhere a no-op, and
    the same bits either way: where memory comes from changes no arithmetic). Whether it applied.
    The mmap threshold first: setting either fixes both (no more dynamic threshold), and a trim
    threshold kept beside a refused mmap threshold would leave the temporaries mmapped."""
    mallopt = _mallopt()
    if mallopt is None:
        return False
    if not any(
        mallopt(_M_MMAP_THRESHOLD, size) == 1 for size in (_KEEP_FREED_BYTES, _MMAP_THRESHOLD_CAP)
    ):
        return False
    return mallopt(_M_TRIM_THRESHOLD, _KEEP_FREED_BYTES) == 1


def one_arena() -> bool:
    """Let every thread of this process allocate from glibc's one main heap (a no-op elsewhere, and
    the same bits either way). A second thread gets a heap of its own, and what it frees stays
    there, kept for that heap alone: the estimate's parse beside the reference's then left 100-150
    MB at a million poses that no later stage could reuse (1.0-1.2 GB peak against 0.9-0.96, and
    the later stages' temporaries came as fresh pages). Its threads allocate a few large arrays
    each, so they hardly wait for the one heap's lock. Whether it applied; before the second thread
    first allocates, which it then keeps to."""
    mallopt = _mallopt()
    return mallopt is not None and mallopt(_M_ARENA_MAX, 1) == 1


def one_case_alone() -> None:
    """This process runs one case alone (`epa eval`): its stages may use a second thread, and its
    temporaries reuse freed memory, whichever thread freed it."""
    use_spare_thread()
    keep_freed_memory()
    one_arena()


class Background(Generic[T]):
    """``f()`` started in a thread of its own; :meth:`result` waits for it and gives its value, or
    raises its error in the caller's thread, where a call of ``f`` would have raised it."""

    def __init__(self, f: Callable[[], T], name: str) -> None:
        import threading  # (imported by every process that gets here: provenance's thread)

        self._done: list = []  # [value] or [None, the exception]
        self._thread = threading.Thread(target=self._run, args=(f,), name=name, daemon=True)
        self._thread.start()

    def _run(self, f: Callable[[], T]) -> None:
        try:
            self._done.append(f())
        except BaseException as exc:  # raised in the caller's thread, by result()
            self._done.extend((None, exc))

    def join(self) -> None:
        """Wait for ``f`` (its error, if any, is raised only by :meth:`result`)."""
        self._thread.join()

    def result(self) -> T:
        self._thread.join()
        if len(self._done) == 2:
            raise self._done[1]
        return self._done[0]


def both(f: Callable[[], T], g: Callable[[], U]) -> tuple[T, U]:
    """(f(), g()); g in a second thread where :func:`spare_thread` allows (both should release the
    GIL for most of their time: else a second thread only adds its switches)."""
    if not spare_thread():
        return f(), g()
    second = Background(g, "epa-second")
    try:
        first = f()
    finally:
        second.join()
    return first, second.result()


def names() -> tuple[str, ...]:
    """The registered caches, in registration order."""
    return tuple(_RESETS)


def reset() -> None:
    """Empty every registered cache: the process then behaves as a new one would."""
    for clear in list(_RESETS.values()):
        clear()
