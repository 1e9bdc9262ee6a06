"""What ``evo_ape`` and ``evo_rpe`` draw with ``--plot`` / ``--save_plot``, for ``epa ape|rpe``.

Two figures, as evo 1.38.1's ``plot_result``: ``raw``, the error over time (or distance, or index)
with its rmse, median and mean as lines and its std as a band one std wide about the mean (evo's
band); ``map``, the reference (dashed grey) and the estimate coloured by its error (each segment by
the error of the pose, or RPE pair, that it ends at; the colour scale from min to max, as evo's
default), in one plane or in 3D (``--plot_mode``, evo's choices, 3D by default as evo's). The data
are those of the result zip (:mod:`epa.evo.archive`): the same arrays, the same poses. Colours are
epica's (Okabe-Ito, viridis), not evo's seaborn palette and jet.

``--save_plot FILE.pdf`` writes one PDF with both pages (evo's default, ``plot_split`` off); another
suffix writes ``FILE_raw.EXT`` and ``FILE_map.EXT``, as evo names them. ``--plot`` opens windows only
where there is a display and an interactive matplotlib backend; without, it draws nothing
interactive (see :func:`can_show`).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from epa.core.errors import EpaError

PLOT_MODES = ("xy", "xz", "yx", "yz", "zx", "zy", "xyz")  # evo's --plot_mode
X_DIMENSIONS = ("index", "seconds", "distances")  # evo's --plot_x_dimension
FORMATS = ("png", "pdf", "svg", "jpg", "jpeg", "tif", "tiff", "eps", "ps", "webp")
NOT_INTERACTIVE = {"agg", "cairo", "pdf", "pgf", "ps", "svg", "template"}
# evo's SETTINGS.plot_statistics without min and max, in its order, each in its own colour
STATISTICS = ("rmse", "median", "mean", "std")
COLOURS = {"rmse": "#0072B2", "median": "#E69F00", "mean": "#009E73", "std": "#CC79A7"}
REFERENCE = "#444444"  # evo's plot_reference_color
SIZE = {"raw": (8.0, 5.0), "map": (8.0, 7.0)}  # inches


def can_show() -> bool:
    """Whether ``--plot`` can open a window: a display (always on macOS and Windows; DISPLAY or
    WAYLAND_DISPLAY elsewhere) and an interactive matplotlib backend to open it with."""
    if sys.platform not in ("darwin", "win32") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        return False
    import matplotlib

    return matplotlib.get_backend().lower() not in NOT_INTERACTIVE


def outputs(path) -> list[Path]:
    """The files ``--save_plot PATH`` writes (evo's PlotCollection.export): the PDF itself, or one
    file per figure, ``STEM_raw.EXT`` and ``STEM_map.EXT``. A suffix matplotlib cannot write is
    one line naming the file."""
    path = Path(path)
    ext = path.suffix.lower().lstrip(".")
    if ext not in FORMATS:
        raise EpaError(
            f"--save_plot needs a file suffix among {', '.join('.' + f for f in FORMATS)}",
            path=str(path),
        )
    if ext == "pdf":
        return [path]
    return [path.with_name(f"{path.stem}_{name}{path.suffix}") for name in SIZE]


def draw(result, *, plot_mode: str = "xyz", x_dimension: str = "seconds", show: bool = False):
    """The figures {"raw", "map"} of a result (:class:`epa.evo.protocol.EvoResult`). Without
    ``show``, on matplotlib's Agg backend: no window, no display needed."""
    import matplotlib

    if not show:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return {"raw": _raw(plt, result, x_dimension), "map": _map(plt, result, plot_mode)}


def _raw(plt, result, x_dimension: str):
    """The error over seconds (or distance, or index) from the start, with its statistics."""
    from epa.evo import archive

    a = archive.arrays(result)
    err = a["error_array"]
    x, xlabel = np.arange(len(err)), "index"  # evo's fallback, also without stamps
    if x_dimension == "seconds" and "seconds_from_start" in a:
        x, xlabel = a["seconds_from_start"], "t (s)"
    elif x_dimension == "distances" and "distances_from_start" in a:
        x, xlabel = a["distances_from_start"], "d (m)"
    label = f"{result.kind.upper()} ({result.unit})"
    fig, ax = plt.subplots(figsize=SIZE["raw"], layout="constrained")
    ax.plot(x, err, color="grey", lw=1.0, label=label)
    s = result.stats
    for name in STATISTICS:
        if name == "std":  # evo's band: mean - std/2 to mean + std/2
            ax.axhspan(
                s["mean"] - s["std"] / 2,
                s["mean"] + s["std"] / 2,
                color=COLOURS[name],
                alpha=0.5,
                lw=0,
                label=name,
            )
        else:
            ax.axhline(s[name], color=COLOURS[name], lw=2.0, label=name)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(label)
    ax.set_title(result.title)
    ax.legend(frameon=True)
    return fig


def _map(plt, result, plot_mode: str):
    """The reference and the estimate coloured by its error, to scale."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize

    if plot_mode not in PLOT_MODES:
        raise EpaError(f"unknown --plot_mode {plot_mode!r}; choose one of {', '.join(PLOT_MODES)}")
    from epa.evo import archive

    ref, est = archive.poses(result)
    err = np.asarray(result.errors, float)
    axes = [("xyz".index(c)) for c in plot_mode]
    fig = plt.figure(figsize=SIZE["map"], layout="constrained")
    norm = Normalize(vmin=result.stats["min"], vmax=result.stats["max"], clip=True)
    # segment k (pose k to k+1) in the colour of error k: as evo's colored_line_collection
    points = est.p[:, axes]
    segments = np.stack([points[:-1], points[1:]], axis=1)
    colour = err[: len(segments)]
    if plot_mode == "xyz":
        from mpl_toolkits.mplot3d.art3d import Line3DCollection  # type: ignore[import-untyped]

        ax = fig.add_subplot(projection="3d")
        ax.plot(*ref.p.T, ls="--", color=REFERENCE, alpha=0.5, label="reference")
        line = Line3DCollection(segments, cmap="viridis", norm=norm, lw=1.5)
        line.set_array(colour)
        ax.add_collection3d(line)
        ax.set_zlabel("z (m)")
    else:
        ax = fig.add_subplot()
        r = ref.p[:, axes]
        ax.plot(r[:, 0], r[:, 1], ls="--", color=REFERENCE, alpha=0.5, label="reference")
        line = LineCollection(list(segments), cmap="viridis", norm=norm, lw=1.5)
        line.set_array(colour)
        ax.add_collection(line)
    both = np.vstack([ref.p, est.p])
    low, high = both.min(axis=0), both.max(axis=0)
    pad = 0.02 * max(float(np.max(high - low)), 1e-9)
    for k, set_lim in zip(axes, (ax.set_xlim, ax.set_ylim, getattr(ax, "set_zlim", None))):
        if set_lim is not None:
            set_lim(low[k] - pad, high[k] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel(f"{plot_mode[0]} (m)")
    ax.set_ylabel(f"{plot_mode[1]} (m)")
    lo, hi = result.stats["min"], result.stats["max"]
    ticks = [lo, hi - (hi - lo) / 2, hi]
    bar = fig.colorbar(line, ax=ax, ticks=ticks, shrink=0.8)
    bar.ax.set_yticklabels([f"{v:0.3f}" for v in ticks])
    bar.set_label(f"{result.kind.upper()} ({result.unit})")
    ax.set_title(result.title)
    ax.legend(frameon=True)
    return fig


def save(figures: dict, path) -> list[Path]:
    """Write the figures as ``--save_plot PATH`` says (:func:`outputs`), each file under a temporary
    name first, renamed when every file is drawn: no partial output."""
    out = outputs(path)
    temporaries = [p.with_name(f".{p.name}.tmp") for p in out]
    try:
        if len(out) == 1:  # one PDF, a page per figure
            from matplotlib.backends.backend_pdf import PdfPages

            with PdfPages(temporaries[0], metadata={"CreationDate": None}) as pdf:
                for fig in figures.values():
                    pdf.savefig(fig)
        else:
            for fig, tmp, final in zip(figures.values(), temporaries, out):
                fig.savefig(tmp, format=final.suffix.lstrip(".").lower(), dpi=150)
    except OSError as exc:
        for tmp in temporaries:
            tmp.unlink(missing_ok=True)
        raise EpaError(f"cannot write: {exc.strerror or exc}", path=str(path)) from None
    for tmp, final in zip(temporaries, out):
        tmp.replace(final)
    return out
