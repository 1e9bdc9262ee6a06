"""The once-per-grid scripts' work in forked processes: the tables' reading of the cases and the grid
figures' drawing are the run's serial tail, and each item is independent of the others."""

from __future__ import annotations


def map_forked(fn, items: list[tuple], workers: int) -> list:
    """``[fn(*item) for item in items]``, in the items' order, in up to ``workers`` forked processes
    (one: in this process). Fork, not spawn: the callers are single-threaded scripts, and the workers
    inherit what they imported (matplotlib, pandas) instead of importing it again."""
    workers = max(1, min(workers, len(items)))
    if workers == 1:
        return [fn(*item) for item in items]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
        return list(pool.map(fn, *zip(*items)))
