"""The rules every source's poses follow, text file or bag: positions within reach of the origin,
stamps strictly increasing (or sorted, or repeats kept, where the settings say so)."""

from __future__ import annotations

import numpy as np

from epa.core.trajectory import Trajectory

# Farther than this from the origin is no trajectory (the Moon is 4e8 m away); squares of it still fit
# a float64 comfortably, so metrics never overflow.
MAX_POSITION_M = 1e9


def beyond_reach(p: np.ndarray) -> int | None:
    """The first pose farther than MAX_POSITION_M from the origin, or None."""
    a = np.abs(p)
    if not (a > MAX_POSITION_M).any():  # (a max along each row's three columns: 7 ms a 100k poses)
        return None
    huge = a.max(axis=1, initial=0) > MAX_POSITION_M  # a row with a NaN is not beyond reach
    return int(np.argmax(huge)) if huge.any() else None


def disorder(t: np.ndarray) -> tuple[int, str] | None:
    """The first stamp that repeats or goes backwards, and which; None when strictly increasing."""
    dt = np.diff(t)
    if not (dt <= 0).any():
        return None
    k = int(np.argmax(dt <= 0)) + 1
    return k, "repeats" if dt[k - 1] == 0 else "goes backwards"


def sort_unique(traj: Trajectory) -> tuple[Trajectory, str]:
    """Sorted by stamp, the first of each repeat kept, and the note saying so."""
    order = np.argsort(traj.t, kind="stable")
    keep = np.concatenate([[True], np.diff(traj.t[order]) > 0])
    n_back, n_dup = int((np.diff(traj.t) < 0).sum()), int((~keep).sum())
    return traj.select(order[keep]), (
        f"{n_back} backward and {n_dup} repeated timestamps: sorted, kept the first of each repeat"
    )


class Unordered(Exception):
    """Stamps that repeat or go backwards where the rule is to stop: the first one (k) and which."""

    def __init__(self, k: int, what: str):
        super().__init__(what)
        self.k, self.what = k, what


def in_order(traj: Trajectory, on_unsorted: str) -> tuple[Trajectory, str | None]:
    """The trajectory under the ``unsorted`` rule, and the note of what was done (None: in order).
    ``sort``: sorted, the first of each repeat kept. ``keep`` (as evo reads files): repeated stamps
    stay in file order (stamps that go backwards still stop). Otherwise raises :class:`Unordered`."""
    bad = disorder(traj.t)
    if bad is None:
        return traj, None
    if on_unsorted == "keep" and not (np.diff(traj.t) < 0).any():
        return (
            traj,
            f"{int((np.diff(traj.t) == 0).sum())} repeated timestamps kept (unsorted: keep)",
        )
    if on_unsorted != "sort":
        raise Unordered(*bad)
    return sort_unique(traj)
