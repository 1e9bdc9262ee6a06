"""The figures of the TUM RGB-D benchmark's scripts (``evaluate_ate.py --plot``, ``evaluate_rpe.py
--plot``), drawn as they draw them. Imports matplotlib when called."""

from __future__ import annotations

import numpy as np


def _pieces(t: np.ndarray) -> list[np.ndarray]:
    """``plot_traj``'s pieces: a gap of twice the median interval or more ends a piece; the pose
    after the gap is not drawn (the script skips it), the next one starts the new piece."""
    if len(t) < 2:
        return [np.arange(len(t))]
    gap = np.diff(t) >= 2 * np.median(np.diff(t))
    pieces = np.split(np.arange(len(t)), np.flatnonzero(gap) + 1)
    return [pieces[0]] + [p[1:] for p in pieces[1:] if len(p) > 1]


def ate(path, ref_t, ref_p, est_t, est_p_aligned, matched_ref_p, matched_est_p) -> None:
    """The x-y plot of the reference (black), the aligned estimate (blue) and each matched pair's
    difference (red), at 90 dpi."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    fig = plt.figure()
    ax = fig.add_subplot(111)
    for t, p, color, label in (
        (ref_t, ref_p, "black", "ground truth"),
        (est_t, est_p_aligned, "blue", "estimated"),
    ):
        for k, piece in enumerate(_pieces(t)):
            ax.plot(p[piece, 0], p[piece, 1], "-", color=color, label=label if k == 0 else "")
    segments = np.stack([matched_ref_p[:, :2], matched_est_p[:, :2]], axis=1)
    ax.add_collection(LineCollection(list(segments), colors="red", label="difference"))
    ax.legend()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def rpe(path, stamps, trans_error) -> None:
    """The translational error (m) over time since the first compared stamp, at 300 dpi."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure()
    ax = fig.add_subplot(111)
    ax.plot(stamps - stamps[0], trans_error, "-", color="blue")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("translational error [m]")
    fig.savefig(path, dpi=300)
    plt.close(fig)
