"""Figures for papers, from plot bundles.

A *bundle* is one figure's data and labels as JSON (``{"kind", "title", "data", "meta"}``; arrays as
lists). The workflow writes the bundle beside each figure and renders it; ``epa fig BUNDLE`` renders
it again with another style or size, without recomputing anything. ``render`` is the only function
that imports matplotlib (≈0.9 s), so no metric stage pays for it.

Style: the Okabe-Ito colour-blind-safe palette, one colour per algorithm across every figure of a
grid (by the algorithm's place in the sorted list of the grid's algorithms), viridis for error
colour maps (its middle is not the grey of the reference), DejaVu Sans (no LaTeX needed),
sizes in inches for a 3.5 in paper column.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from epa.artifacts import files
from epa.core import runtime
from epa.core.errors import EpaError

if TYPE_CHECKING:
    from matplotlib.artist import Artist

OKABE_ITO = ["#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442", "#000000"]
STYLES = {  # name: (width in, height in, base font pt)
    "paper": (3.5, 2.6, 8.0),
    "wide": (7.0, 2.8, 8.0),
    "slide": (6.4, 4.0, 12.0),
}
MAX_POINTS = (
    1000  # a plotted line at column width needs no more; keeps bundles small and drawing fast
)


def thin(n: int, most: int | None = None) -> np.ndarray:
    """Indices of at most ``most`` (MAX_POINTS) evenly spread samples of ``n`` (first and last kept)."""
    most = MAX_POINTS if most is None else most
    if n <= most:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, most).round().astype(int))


def _plain(obj):
    """Bundle data as JSON types, except float arrays, which stay arrays (written by ``_json``)."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.astype(float) if obj.dtype.kind in "fiub" else _plain(obj.tolist())
    if isinstance(obj, (float, np.floating)):
        return None if not np.isfinite(obj) else float(f"{float(obj):.7g}")
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


_NOT_FINITE = re.compile(r"-?\b(?:nan|inf)\b")


def _json(obj, memo: dict | None = None) -> str:
    """JSON with arrays at 7 significant digits (a figure needs no more) and NaN as null, formatted
    in one call per array: element-by-element conversion cost more than drawing a figure. ``memo``:
    the text of each array already formatted, by its values (a case's bundles repeat some)."""
    if isinstance(obj, np.ndarray):
        if memo is None or obj.size < MEMO_FROM:
            return _array_json(obj)
        key = (obj.shape, obj.dtype.str, obj.tobytes())
        text = memo.get(key)
        if text is None:
            text = memo[key] = _array_json(obj)
        return text
    if isinstance(obj, dict):  # keys as json.dumps(str(k)) writes them, without its per-call cost
        return (
            "{" + ",".join([_ESCAPE(str(k)) + ":" + _json(v, memo) for k, v in obj.items()]) + "}"
        )
    if isinstance(obj, list):
        return "[" + ",".join([_json(v, memo) for v in obj]) + "]"
    if type(obj) is float and obj - obj == 0:  # finite: json.dumps' text
        return float.__repr__(obj)
    return json.dumps(obj)


# arrays from this size on are looked up in a memo: the steps bundle repeats the trajectory
# bundle's reference and estimate (a third of a case's bundle text)
MEMO_FROM = 256


def _array_json(obj: np.ndarray) -> str:
    """An array's JSON text (:func:`_json`)."""
    if obj.ndim > 2:
        return "[" + ",".join(_array_json(row) for row in obj) + "]"
    if not obj.size:
        return "[" + ",".join("[]" for _ in range(len(obj))) + "]" if obj.ndim == 2 else "[]"
    item = "%.7g," * obj.shape[-1]
    if obj.ndim == 2:
        item = "[" + item[:-1] + "],"
    text = (item * (obj.size // obj.shape[-1]) % tuple(obj.ravel().tolist()))[:-1]
    if not np.isfinite(obj).all():
        text = _NOT_FINITE.sub("null", text)
    return "[" + text + "]"


_ESCAPE = json.encoder.encode_basestring_ascii


def bundle(kind: str, title: str, data: dict, **meta) -> dict:
    if kind not in RENDERERS:
        raise ValueError(f"unknown figure kind {kind!r}")
    return {
        "format": "epica-plot-bundle/1",
        "kind": kind,
        "title": title,
        "data": _plain(data),
        "meta": _plain(meta),
    }


def write_bundle(path, b: dict, memo: dict | None = None) -> None:
    """``memo``: shared by the bundles of one case (:func:`_json`)."""
    files.write_text(path, _json(b, memo) + "\n")


def read_bundle(path) -> dict:
    try:
        with open(path, encoding="utf-8") as fh:
            b = json.load(fh)
    except FileNotFoundError:
        raise EpaError("file not found", path=str(path)) from None
    except (OSError, ValueError) as exc:
        raise EpaError(f"not a plot bundle: {exc}", path=str(path)) from None
    if (
        not isinstance(b, dict)
        or b.get("format") != "epica-plot-bundle/1"
        or b.get("kind") not in RENDERERS
    ):
        raise EpaError(
            "not an epica plot bundle (format epica-plot-bundle/1 with a known kind)",
            path=str(path),
        )
    if not isinstance(b.get("data"), dict):
        raise EpaError("a plot bundle without its data (key 'data')", path=str(path))
    return b


# ----------------------------------------------------------------------------- rendering
def prepare(style: str = "paper") -> None:
    """Import matplotlib and set the style now (before forking workers that draw)."""
    _setup(style)


def _setup(style: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _keep_font_subsets()
    from matplotlib.rcsetup import cycler  # what matplotlib.cycler is; the stubs declare it here

    w, h, pt = STYLES[style]
    plt.rcParams.update(
        {
            "font.family": "DejaVu Sans",
            "font.size": pt,
            "axes.titlesize": pt,
            "axes.labelsize": pt,
            "xtick.labelsize": pt - 1,
            "ytick.labelsize": pt - 1,
            "legend.fontsize": pt - 1,
            "axes.linewidth": 0.6,
            "lines.linewidth": 1.0,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "legend.frameon": False,
            "figure.dpi": 100,
            "savefig.dpi": 150,
            "pdf.fonttype": 42,
            "svg.fonttype": "none",
            "axes.prop_cycle": cycler(color=OKABE_ITO),
            # 1e4 and beyond as a power of ten above the axis: tick labels stay short enough for fixed margins
            # no mathtext: parsing it would cost more than drawing
            "axes.formatter.limits": (-3, 4),
            # glyphs as drawn, not fitted to the pixel grid by FreeType's hinting: as sharp at
            # 150 dpi, and a third less per label (Agg drew 1.7 ms a label, now 1.0)
            "text.hinting": "no_hinting",
        }
    )
    return plt, w, h


# A PDF embeds the subset of its font that its text uses, made by fontTools from the whole font file
# each time: 0.05-0.07 s of a 0.15 s PDF. Figures of one grid use the same few characters, so the
# subset made for one set of glyphs is kept (its bytes, for at most _MAX_SUBSETS sets) and given
# again. matplotlib has no public hook for this: the patch wraps the two functions that make and
# save a subset (only on matplotlib 3.11, whose signatures it knows; another is left as it is),
# and a test compares the PDF's bytes with those matplotlib writes alone.
_SUBSETS: dict[tuple, tuple[bytes, dict]] = runtime.register("outputs.figures.subsets", {})
_MAX_SUBSETS = 32
PATCHED_MATPLOTLIB = "3.11."  # the series whose two functions the test compares against


def _keep_font_subsets() -> None:
    import matplotlib
    from matplotlib.backends import _backend_pdf_ps as pdf_ps

    if not matplotlib.__version__.startswith(PATCHED_MATPLOTLIB):
        return  # another matplotlib's private functions may mean other things: its own subsets
    make, save = pdf_ps.get_glyphs_subset, pdf_ps.font_as_file
    if getattr(make, "epa_kept", False) or not hasattr(pdf_ps, "SubsetResults"):
        return
    from io import BytesIO

    from fontTools.ttLib import TTFont  # type: ignore[import-untyped]

    def kept(fontfile, glyphs):
        key = (str(fontfile), getattr(fontfile, "face_index", 0), frozenset(glyphs))
        if key not in _SUBSETS:
            with make(fontfile, glyphs) as made:
                subset = (save(made.font).getvalue(), dict(made.glyph_index_map))
            if len(_SUBSETS) >= _MAX_SUBSETS:
                del _SUBSETS[next(iter(_SUBSETS))]
            _SUBSETS[key] = subset
        data, index = _SUBSETS[key]
        font = TTFont(BytesIO(data))
        font.epa_bytes = data  # saved again, fontTools would write other (equivalent) bytes
        return pdf_ps.SubsetResults(font, dict(index))._as_cm()

    def saved(font):
        data = getattr(font, "epa_bytes", None)
        return save(font) if data is None else BytesIO(data)

    kept.epa_kept = True  # type: ignore[attr-defined]
    kept.__wrapped__, saved.__wrapped__ = make, save  # type: ignore[attr-defined]
    pdf_ps.get_glyphs_subset, pdf_ps.font_as_file = kept, saved


# A worker draws the same few layouts case after case. Creating axes and their tick objects is about
# half of a figure's cost, so after saving, a case figure is kept (one per kind and size, in this
# process) and the next figure of that layout reuses it, emptied of data: the same bytes as a new
# one (a test compares them), at about half the cost.
_KEPT: dict[tuple, object] = runtime.register("outputs.figures.kept", {})
MAX_KEPT = 8  # layouts kept at once: a dataset's two, a case's four, the grid's few


def _layout(plt, kind: str, size: tuple, make):
    """A figure of this layout: the kept one, emptied, or ``make()``'s. Axes are in ``fig.axes``."""
    key = (kind, tuple(round(v, 6) for v in size), plt.rcParams["font.size"])
    fig = _KEPT.pop(key, None)
    if fig is None:
        fig = make()
        # axes added later (a colour bar) go on reuse
        fig._epa_layout, fig._epa_axes = (key, len(fig.axes))
    else:
        _empty(fig)
    return fig


def _empty(fig) -> None:
    """Back to the state of a new figure of the same layout: no data, labels or legends; default
    ticks, limits, aspect and colour cycle. Tick objects stay (that is the saving)."""
    for ax in fig.axes[fig._epa_axes :]:
        ax.remove()
    insets = [child for parent in fig.axes for child in parent.child_axes]
    for ax in [*fig.axes, *insets]:  # insets are part of a layout
        for artist in [*ax.lines, *ax.collections, *ax.patches, *ax.texts, *ax.images]:
            artist.remove()
        if ax.legend_ is not None:
            ax.legend_.remove()
        ax.containers.clear()
        for loc in ("left", "center", "right"):
            ax.set_title("", loc=loc)
        ax.set_xlabel("")
        ax.set_ylabel("")
        # default locators and formatters (a box plot leaves fixed ones, a log axis its own);
        # resetting an axis already at its defaults cost a fifth of making a figure's artists
        for axis, set_scale in ((ax.xaxis, ax.set_xscale), (ax.yaxis, ax.set_yscale)):
            if axis.get_scale() != "linear" or not (
                axis.isDefault_majloc
                and axis.isDefault_minloc
                and axis.isDefault_majfmt
                and axis.isDefault_minfmt
            ):
                set_scale("linear")
        ax.set_aspect("auto", adjustable="box")
        ax.set_prop_cycle(None)
        ax.relim()
        ax.set_autoscale_on(True)
        ax.autoscale_view()
    for legend in list(fig.legends):
        legend.remove()


def _single(plt, w, h, top: float = 0.12):
    """One axes with fixed margins in inches (``top``: room above it, for a legend)."""

    def make():
        fig, ax = plt.subplots(figsize=(w, h))
        fig.subplots_adjust(left=0.6 / w, right=1 - 0.1 / w, bottom=0.45 / h, top=1 - top / h)
        return fig

    fig = _layout(plt, "single", (w, h, top), make)
    return fig, fig.axes[0]


# Kinds whose tick labels print "-" for minus, not U+2212: that one glyph makes a PDF embed a
# second subset of the font (0.1-0.3 s of a trajectory overlay's 0.5; the kinds before these keep it)
ASCII_MINUS = ("overlay", "boxes")
MAX_WIDTH_IN = 100.0  # a figure wider than this is a typo (centimetres, points)


def render(
    b: dict, out_stem, *, style: str = "paper", width: float | None = None, formats=("png", "pdf")
) -> list[Path]:
    """Draw a bundle to ``out_stem``.png / .pdf; returns the files written."""
    if style not in STYLES:
        raise EpaError(f"unknown style {style!r}; choose one of {', '.join(STYLES)}")
    if width is not None and not (np.isfinite(width) and 0 < width <= MAX_WIDTH_IN):
        raise EpaError(f"--width must be between 0 and {MAX_WIDTH_IN:g} inches, not {width:g}")
    plt, w, h = _setup(style)
    scale = (width / w) if width else 1.0
    try:
        fig = RENDERERS[b["kind"]](plt, b, w * scale, h * scale)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        plt.close("all")
        _KEPT.clear()
        what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc).splitlines()[0]
        raise EpaError(f"the {b['kind']} bundle's data cannot be drawn: {what}") from None
    from matplotlib.ticker import MaxNLocator

    # five ticks read well at column width, and tick labels are most of a figure's cost
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            # AutoLocator too; not log or fixed ticks
            if isinstance(axis.get_major_locator(), MaxNLocator):
                axis.get_major_locator().set_params(nbins=5)
    _no_ligatures(fig)
    out = []
    for fmt in formats:
        path = Path(f"{out_stem}.{fmt}")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise EpaError(f"cannot write: {exc.strerror}", path=str(path)) from None
        tmp = path.with_name("." + path.name + ".tmp")
        # fixed margins, not bbox_inches="tight": that draws the figure twice (half the cost of a
        # figure); fast PDF stream compression: 7-15 ms less a figure, for 8 % more bytes
        rc = {"pdf.compression": 1}
        if b["kind"] in ASCII_MINUS:
            rc["axes.unicode_minus"] = False
        with plt.rc_context(rc):
            if fmt == "png":
                _write_png(fig, tmp)
            else:  # no creation date: the same bundle gives the same bytes (re-runs compare equal)
                fig.savefig(tmp, format=fmt, metadata={"CreationDate": None})
        tmp.replace(path)
        out.append(path)
    key = getattr(fig, "_epa_layout", None)
    if key is None or key in _KEPT:
        plt.close(fig)
    else:
        if len(_KEPT) >= MAX_KEPT:  # the layout kept longest goes: memory stays bounded
            plt.close(_KEPT.pop(next(iter(_KEPT))))
        _KEPT[key] = fig
    return out


def _write_png(fig, path) -> None:
    """The figure as an opaque 8-bit RGB PNG at ``savefig.dpi``: Agg's pixels without their alpha
    (the figure is opaque), every row unfiltered, zlib level 1. Pillow's RGBA PNG took 22 ms of a
    figure's 0.1 s; this 10-13 ms, and its files are a quarter smaller (plots are mostly flat)."""
    import io
    import struct
    import zlib

    import matplotlib

    dpi = matplotlib.rcParams["savefig.dpi"]
    raw = io.BytesIO()
    fig.savefig(raw, format="rgba", dpi=dpi)
    width = int(fig.get_figwidth() * dpi)
    rgba = np.frombuffer(raw.getbuffer(), np.uint8).reshape(-1, width, 4)
    rows = np.zeros((len(rgba), 1 + 3 * width), np.uint8)  # each row: filter 0 (none), its pixels
    rows[:, 1:].reshape(len(rgba), width, 3)[:] = rgba[..., :3]

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    per_metre = round(dpi / 0.0254)
    software = f"Software\0Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"
    png = b"".join(
        [
            b"\x89PNG\r\n\x1a\n",
            chunk(b"IHDR", struct.pack(">IIBBBBB", width, len(rgba), 8, 2, 0, 0, 0)),
            chunk(b"tEXt", software.encode("latin-1")),
            chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1)),
            chunk(b"IDAT", zlib.compress(rows.data, 1)),
            chunk(b"IEND", b""),
        ]
    )
    Path(path).write_bytes(png)


def _no_ligatures(fig) -> None:
    """Text without ligatures ("fi" in "drift" as two letters). A ligature's glyph stands for no
    single character, so a PDF embeds a second subset of the font for it: 0.15-0.2 s of a figure's
    0.5, and text copied from the PDF reads as typed. (matplotlib 3.11 shapes text with HarfBuzz,
    which joins them; earlier releases never did.)"""
    from matplotlib.text import Text

    for text in fig.findobj(Text):
        if hasattr(text, "set_fontfeatures"):
            text.set_fontfeatures(["-liga"])


def _top_over_side(plt, kind, w, left, aw, bottom, side, gap, th, top):
    """A figure of a top view (``th`` in high) over a side view (``side`` in high) sharing x, both
    ``aw`` in wide from ``left``: the case's trajectory and the dataset's overlay. Figures of other
    heights and view widths share one kept figure, resized (datasets rarely share a shape)."""
    fh = bottom + side + gap + th + top

    def make():
        fig = plt.figure(figsize=(w, fh))
        ax_top = fig.add_axes([left / w, (bottom + side + gap) / fh, aw / w, th / fh])
        fig.add_axes([left / w, bottom / fh, aw / w, side / fh], sharex=ax_top)
        ax_top.tick_params(labelbottom=False)
        return fig

    fig = _layout(plt, kind, (w, left, bottom, side, gap, top), make)
    fig.set_size_inches(w, fh)
    ax_top, ax_side = fig.axes[:2]
    ax_top.set_position([left / w, (bottom + side + gap) / fh, aw / w, th / fh])
    ax_side.set_position([left / w, bottom / fh, aw / w, side / fh])
    return fig


def _arr(x):
    return (
        np.array([np.nan if v is None else v for v in x], float)
        if isinstance(x, list)
        else np.asarray(x, float)
    )


def _trajectory(plt, b, w, h):
    """Top view to scale (its height follows the data) over a side view stretched in z."""
    d = b["data"]
    ref, est, err = _arr(d["ref"]), _arr(d["est"]), _arr(d["err"])
    left, right, bottom, top, gap, side = 0.62, 0.85, 0.4, 0.42, 0.35, 0.9
    aw = w - left - right
    span = np.ptp(np.vstack([ref, est])[:, :2], axis=0) if len(ref) else np.ones(2)
    # the height in steps of 0.05 in: cases of a dataset then share a layout (the aspect sets the limits)
    th = round(float(np.clip(aw * span[1] / max(span[0], 1e-9), 0.8, 3.2)) / 0.05) * 0.05
    fh = bottom + side + gap + th + top

    fig = _top_over_side(plt, "trajectory", w, left, aw, bottom, side, gap, th, top)
    ax_top, ax_side = fig.axes
    from matplotlib.collections import LineCollection

    vmax = np.nanpercentile(err, 99) if err.size else 1.0
    # a line coloured by its error: reads for dense and for sparse (keyframe) estimates alike. Pieces
    # of a few poses (at most 250 pieces) look the same as one piece per pose and draw in half the time.
    cuts = np.unique(
        np.linspace(0, max(len(est) - 1, 0), min(250, max(len(est) - 1, 1)) + 1).round().astype(int)
    )
    piece_err = np.array([np.nanmean(err[a : b + 1]) for a, b in zip(cuts[:-1], cuts[1:])])
    for ax, j, label in ((ax_top, 1, "y [m]"), (ax_side, 2, "z [m]")):
        ax.plot(ref[:, 0], ref[:, j], color="0.75", lw=2.2, label="reference", zorder=1)
        xy = est[:, [0, j]]
        lc = LineCollection(
            [xy[a : b + 1] for a, b in zip(cuts[:-1], cuts[1:])],
            cmap="viridis",
            lw=1.0,
            zorder=2,
            label="aligned estimate",
        )
        lc.set_array(piece_err)
        lc.set_clim(0, vmax)
        ax.add_collection(lc)
        ax.autoscale_view()
        ax.set_ylabel(label)
    ax_top.set_aspect("equal", adjustable="datalim")
    ax_side.set_xlabel("x [m]")
    # above the plot (a trajectory fills its axes), clear of a "x10^4" offset label
    ax_top.legend(
        loc="lower right",
        bbox_to_anchor=(1.0, 1.0 + 0.12 / th),
        ncols=2,
        fontsize="small",
        borderaxespad=0.1,
    )
    cax = fig.add_axes([(w - right + 0.12) / w, (bottom + side + gap) / fh, 0.08 / w, th / fh])
    fig.colorbar(lc, cax=cax).set_label("APE [m]")
    return fig


def _ape_time(plt, b, w, h):
    d = b["data"]
    t, ape = _arr(d["t"]), _arr(d["ape"])
    fig, ax = _single(plt, w, h)
    for k, (s, e) in enumerate(zip(d.get("fail_start", []), d.get("fail_end", []))):
        ax.axvspan(
            s, e, color=OKABE_ITO[5], alpha=0.18, lw=0, label="fail segment" if k == 0 else None
        )
    ax.plot(t, ape, color=OKABE_ITO[0], label="APE")
    thr = d.get("threshold")
    if thr is not None and (not ape.size or thr <= 1.5 * np.nanmax(ape)):
        ax.axhline(thr, color="0.4", ls="--", lw=0.7, label="knee threshold")
    elif thr is not None:  # drawn, it would squash the curve into the bottom of the plot
        ax.plot([], [], " ", label=f"knee threshold {thr:.3g} m (above the plot)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("APE [m]")
    ax.set_xlim(t[0] if t.size else 0, t[-1] if t.size else 1)
    ax.set_ylim(bottom=0)
    ax.legend(loc="upper left")
    return fig


def _rpe_box(plt, b, w, h):
    d = b["data"]
    lengths = d["lengths"]
    fig, ax = _single(plt, w, h)
    groups = [_arr(v) for v in d["trans"]]
    have = [k for k, g in enumerate(groups) if g.size]
    if have:
        ax.boxplot(
            [groups[k] for k in have],
            positions=np.arange(len(have)),
            widths=0.6,
            showfliers=False,
            patch_artist=True,
            boxprops={"facecolor": OKABE_ITO[4], "alpha": 0.6, "lw": 0.6},
            medianprops={"color": "black", "lw": 1.0},
            whiskerprops={"lw": 0.6},
            capprops={"lw": 0.6},
        )
        ax.set_xticks(np.arange(len(have)), [f"{lengths[k]:g}" for k in have])
    ax.set_xlabel("segment length [m]")
    ax.set_ylabel("RPE translation [m]")
    return fig


def _xcorr(plt, b, w, h):
    d = b["data"]
    lag, corr = _arr(d["lag"]), _arr(d["corr"])
    peak = d.get("peak")
    if peak is not None and lag.size:

        def make():
            fig, _ = _single(plt, w, h)
            # below the peak, where the zoomed curve is not
            inset = fig.axes[0].inset_axes([0.34, 0.1, 0.34, 0.34])
            inset.tick_params(labelsize=5.5, length=2, pad=1)
            return fig

        fig = _layout(plt, "xcorr", (w, h), make)
        ax, inset = fig.axes[0], fig.axes[0].child_axes[0]
        near = np.abs(lag - peak) <= max(0.1, 20 * (lag[1] - lag[0]) if lag.size > 1 else 0.1)
        ax.plot(lag[near] * 1000, corr[near], color=OKABE_ITO[0])
        ax.axvline(
            peak * 1000, color=OKABE_ITO[5], lw=0.8, ls="--", label=f"offset {peak * 1000:.2f} ms"
        )
        ax.legend(loc="upper left")
        inset.plot(lag, corr, color=OKABE_ITO[0], lw=0.6)
        inset.axvline(peak, color=OKABE_ITO[5], lw=0.6, ls="--")
        inset.set_title("full curve, lag [s]", fontsize=5.5, pad=2)
    else:  # why Step 1 was not used, above the plot (inside, it would cross the curve)
        fig, ax = _single(plt, w, h, top=0.3)
        ax.plot(lag, corr, color=OKABE_ITO[0])
        ax.set_title(d.get("reason", "Step 1 not used"), loc="left")
    ax.set_xlabel("lag [ms]" if peak is not None else "lag [s]")
    ax.set_ylabel("normalised correlation")
    return fig


def _steps(plt, b, w, h):
    """One top view: the reference, the estimate put on it by its first pose only, and after Steps 1-3."""
    d = b["data"]
    ref, before, after = _arr(d["ref"]), _arr(d["before"]), _arr(d["after"])
    fig, ax = _single(plt, w, h, top=0.42)
    ax.plot(ref[:, 0], ref[:, 1], color="0.6", lw=1.6, label="reference")
    ax.plot(before[:, 0], before[:, 1], color=OKABE_ITO[1], lw=0.8, ls="--", label="first pose")
    ax.plot(after[:, 0], after[:, 1], color=OKABE_ITO[0], lw=0.8, label="Steps 1-3")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal", adjustable="datalim")
    # above the plot, clear of a "x10^4" offset label
    ax.legend(
        loc="lower right",
        bbox_to_anchor=(1.0, 1.0 + 0.12 / (ax.get_position().height * h)),
        ncols=3,
        borderaxespad=0.1,
    )
    return fig


def _sigma3(plt, b, w, h):
    d = b["data"]
    t = _arr(d["t"])
    fw, fh = max(w, 7.0), h * 1.3

    def make():
        fig, _ = plt.subplots(2, 3, figsize=(fw, fh), sharex=True)
        fig.subplots_adjust(
            left=0.6 / fw,
            right=1 - 0.1 / fw,
            bottom=0.45 / fh,
            top=1 - 0.1 / fh,
            wspace=0.45,
            hspace=0.15,
        )
        return fig

    fig = _layout(plt, "sigma3", (fw, fh), make)
    axes = np.array(fig.axes).reshape(2, 3)
    labels = [
        ("err_x", "sigma_x", "x [m]"),
        ("err_y", "sigma_y", "y [m]"),
        ("err_z", "sigma_z", "z [m]"),
        ("err_rot_x", "sigma_rot_x", "roll [deg]"),
        ("err_rot_y", "sigma_rot_y", "pitch [deg]"),
        ("err_rot_z", "sigma_rot_z", "yaw [deg]"),
    ]
    for ax, (e, s, name) in zip(axes.ravel(), labels):
        k = 57.29577951308232 if "rot" in e else 1.0
        err, sig = _arr(d[e]) * k, 3 * _arr(d[s]) * k
        ax.fill_between(
            t, -sig, sig, color=OKABE_ITO[4], alpha=0.35, lw=0, label="±3σ", rasterized=True
        )
        ax.plot(t, err, color=OKABE_ITO[0], lw=0.5, label="error", rasterized=True)
        ax.set_ylabel(name)
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper left", ncols=2)
    return fig


def _grouped(plt, b, w, h):
    """Per algorithm and dataset: box plots over runs (or bars when one value per cell)."""
    d = b["data"]
    datasets, algs = d["datasets"], d["algorithms"]
    colors = d.get("colors") or OKABE_ITO
    rotate = len(datasets) > 3
    fig, ax = plt.subplots(figsize=(w, h))
    # room above for the legend (bars and boxes may reach any height) and below for slanted names
    fig.subplots_adjust(
        left=0.6 / w, right=1 - 0.1 / w, bottom=(0.75 if rotate else 0.35) / h, top=1 - 0.3 / h
    )
    width = 0.8 / max(len(algs), 1)
    for a, alg in enumerate(algs):
        pos = np.arange(len(datasets)) - 0.4 + width * (a + 0.5)
        vals = [_arr(v) for v in d["values"][a]]
        color = colors[a % len(colors)]
        if d.get("bars"):
            ax.bar(
                pos, [v[0] if v.size else np.nan for v in vals], width * 0.9, color=color, label=alg
            )
        else:
            keep = [k for k, v in enumerate(vals) if v.size]
            if keep:
                bp = ax.boxplot(
                    [vals[k] for k in keep],
                    positions=pos[keep],
                    widths=width * 0.8,
                    showfliers=True,
                    patch_artist=True,
                    manage_ticks=False,
                    flierprops={"markersize": 2},
                    medianprops={"color": "black", "lw": 0.8},
                )
                for box in bp["boxes"]:
                    box.set(facecolor=color, alpha=0.8, lw=0.5)
            ax.plot([], [], color=color, lw=4, label=alg)
    ax.set_xticks(
        np.arange(len(datasets)),
        datasets,
        rotation=20 if rotate else 0,
        ha="right" if rotate else "center",
    )
    ax.set_ylabel(d["ylabel"])
    if d.get("log"):
        _log_axis(ax)
    ax.legend(
        loc="lower left", bbox_to_anchor=(0.0, 1.0), ncols=min(len(algs), 4), borderaxespad=0.2
    )
    return fig


def _lines(plt, b, w, h):
    """One line per algorithm (drift rate against segment length, RMSE over time, success rate
    against the drift threshold)."""
    from matplotlib.ticker import FuncFormatter

    d = b["data"]
    colors = d.get("colors") or OKABE_ITO
    panels = d["panels"]
    fig, axes = plt.subplots(
        1, len(panels), figsize=(w, h), squeeze=False, sharey=d.get("sharey", False)
    )
    # fixed margins: a layout engine costs several draws (0.8 s for three panels)
    fig.subplots_adjust(
        left=0.6 / w,
        right=1 - 0.1 / w,
        bottom=0.75 / h,
        top=1 - 0.25 / h,
        wspace=0.15 if d.get("sharey") else 0.35,
    )
    for ax, panel in zip(axes[0], panels):
        for k, line in enumerate(panel["lines"]):
            # dashes per line where lines may coincide (several at 100 %)
            style = ("-", "--", ":", "-.")[line.get("color", k) % 4] if d.get("dashes") else "-"
            ax.plot(
                _arr(line["x"]),
                _arr(line["y"]),
                color=colors[line.get("color", k) % len(colors)],
                ls=style,
                marker="o" if d.get("markers") else None,
                ms=3,
                label=line["label"],
            )
        ax.set_title(panel.get("title", ""))
        ax.set_xlabel(d["xlabel"])
        if d.get("log"):
            _log_axis(ax)
        if d.get("ylim"):
            ax.set_ylim(*d["ylim"])
        if d.get("logx"):
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axes[0, 0].set_ylabel(d["ylabel"])
    # one legend for every panel, under them: inside, it would hide some line of some panel
    handles: dict[str, Artist] = {}
    for ax in axes[0]:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    fig.legend(
        handles.values(),
        handles.keys(),
        loc="lower center",
        ncols=min(len(handles), 5),
        bbox_to_anchor=(0.5, 0.0),
        borderaxespad=0.1,
    )
    return fig


OUT_OF_VIEW = 0.5  # a line more than half the reference's extent outside it leaves the view


def _finite_rows(rows) -> np.ndarray:
    xyz = _arr(rows).reshape(-1, 3)
    return xyz[np.isfinite(xyz).all(axis=1)]


def _overlay_view(d: dict):
    """The overlay's reference, its lines ``(legend label, xyz, out of view, index, line)`` and the
    view's corners (x, y, z): the reference and the lines that stay near it, padded by 4 %."""
    ref = _finite_rows(d["ref"])
    lines = []
    for k, line in enumerate(d["lines"]):
        xyz = _finite_rows(line["xyz"])
        out = False
        if len(ref) and len(xyz):
            lo, hi = ref[:, :2].min(axis=0), ref[:, :2].max(axis=0)
            tol = OUT_OF_VIEW * max(float(np.max(hi - lo)), 1.0)
            out = bool(((xyz[:, :2] < lo - tol) | (xyz[:, :2] > hi + tol)).any())
        name = f"{line['label']} ({line['run']})" if line.get("run") else line["label"]
        lines.append((name + (", leaves the view" if out else ""), xyz, out, k, line))
    shown = np.vstack([ref, *(xyz for _, xyz, out, _, _ in lines if not out), np.zeros((0, 3))])
    if not len(shown):
        shown = np.zeros((1, 3))
    lo, hi = shown.min(axis=0), shown.max(axis=0)
    pad = 0.04 * np.maximum(hi - lo, 1e-3)
    return ref, lines, lo - pad, hi + pad


def _key(ax, left: float, top: float, entries, *, title=None, ncols: int = 1) -> None:
    """A legend drawn as plain artists on ``ax``, in figure inches, its top left corner at ``(left,
    top)``: what matplotlib's legend draws (its default spacings in font sizes, no frame), filled
    column by column, without its layout of nested boxes, which measured each label several times
    and cost a 10-algorithm figure more than its lines (25-50 ms). ``entries``: ``(label, style)``,
    a line's style ``{"color", "lw"}`` or a marker's ``{"color", "marker"}``."""
    import matplotlib
    from matplotlib.collections import LineCollection
    from matplotlib.font_manager import FontProperties
    from matplotlib.lines import Line2D
    from matplotlib.textpath import text_to_path

    rc = matplotlib.rcParams
    fig = ax.figure
    inches = fig.dpi_scale_trans
    pt = float(rc["legend.fontsize"])
    em = pt / 72  # inches
    prop = FontProperties(size=pt)
    # a row: a label's height (1.01 font sizes for DejaVu Sans, as matplotlib measures it) and the
    # space between rows; the title's middle 0.46 of its size below the top, then half its height
    # and the space between rows above the first row (matplotlib's legend, measured at 8/7 pt)
    pitch = (1.01 + rc["legend.labelspacing"]) * em
    x0, y = left + rc["legend.borderpad"] * em, top - rc["legend.borderpad"] * em
    if title:
        size = float(rc["font.size"])
        middle = y - 0.46 * size / 72
        ax.text(x0, middle, title, transform=inches, fontsize=size, va="center", ha="left")
        y = middle - 0.505 * size / 72 - 0.5 * rc["legend.labelspacing"] * em
    per_col = -(-len(entries) // max(ncols, 1))
    handle, pad = rc["legend.handlelength"] * em, rc["legend.handletextpad"] * em
    segments, colors, widths = [], [], []
    for c in range(0, len(entries), max(per_col, 1)):
        column = entries[c : c + per_col]
        for r, (label, style) in enumerate(column):
            yc = y - (r + 0.5) * pitch
            if "marker" in style:
                mark = Line2D([x0 + handle / 2], [yc], transform=inches, ls="none", ms=4, **style)
                ax.add_artist(mark).set_clip_on(False)
            else:
                segments.append([(x0, yc), (x0 + handle, yc)])
                colors.append(style["color"])
                widths.append(style["lw"])
            ax.text(x0 + handle + pad, yc, label, transform=inches, fontsize=pt, va="center")
        if c + per_col >= len(entries):
            break  # the last column: nothing beside it to place
        longest = max(
            text_to_path.get_text_width_height_descent(t, prop, False)[0] for t, _ in column
        )
        x0 += handle + pad + longest / 72 + rc["legend.columnspacing"] * em
    if segments:
        lc = LineCollection(
            segments,
            colors=colors,
            linewidths=widths,
            capstyle=rc["lines.solid_capstyle"],  # as a legend's line handle
            transform=inches,
        )
        ax.add_collection(lc, autolim=False).set_clip_on(False)


def _ends(ax, ends, j: int) -> None:
    """The lines' starts (circles) and ends (squares) in x and coordinate ``j``: one collection
    each, what ax.scatter makes, without its handling of every other argument (a third of making
    the overlay's artists). ``ends``: ``(xyz, colour)`` per line."""
    from matplotlib.collections import PathCollection
    from matplotlib.markers import MarkerStyle
    from matplotlib.transforms import IdentityTransform

    for k, marker in ((0, "o"), (-1, "s")):
        style = MarkerStyle(marker)
        ax.add_collection(
            PathCollection(
                [style.get_path().transformed(style.get_transform())],
                sizes=[16],
                facecolors=[c for _, c in ends],
                edgecolors="white",
                linewidths=0.5,
                offsets=np.array([xyz[k, [0, j]] for xyz, _ in ends]),
                offset_transform=ax.transData,
                transform=IdentityTransform(),
                zorder=3,
            ),
            autolim=False,
        )


def _overlay(plt, b, w, h):
    """A dataset's trajectories: the reference and one line per algorithm, top view to scale (its
    height follows the data) over a side view stretched in z; start (circle) and end (square) marked.
    The view holds the reference and every line that stays near it: a line that goes farther than
    half the reference's extent (a diverged run, kilometres away) is drawn cut at the view's edge
    and says so in the legend, instead of shrinking the others to a dot. The legend, titled with
    the dataset, is beside the top view: a trajectory fills its axes. A panel's lines are one
    collection (the reference first, beneath)."""
    from matplotlib.collections import LineCollection

    d = b["data"]
    colors = d.get("colors") or OKABE_ITO
    ref, lines, lo, hi = _overlay_view(d)
    left, right, bottom, top, gap, side = 0.62, 1.75, 0.4, 0.15, 0.3, 0.9
    aw, most = w - left - right, 3.6
    ratio = (hi[1] - lo[1]) / (hi[0] - lo[0])
    # the top view at least as tall as the view at this width (the equal aspect then widens y,
    # never cuts it: x is shared); a tall trajectory narrows both views instead. Both in steps of
    # 0.05 in (the width rounded down, the height up), as the case figure's; a kept figure is
    # resized to each (_top_over_side).
    narrow = np.floor(most / ratio / 0.05) * 0.05
    aw = min(aw, narrow if narrow > 0 else most / ratio)
    th = float(np.ceil(np.clip(aw * ratio, 1.2, most) / 0.05 - 1e-9) * 0.05)
    fig = _top_over_side(plt, "overlay", w, left, aw, bottom, side, gap, th, top)
    ax_top, ax_side = fig.axes
    drawn = [(ref, "0.75", 2.2)] if len(ref) else []
    entries = [("reference", {"color": "0.75", "lw": 2.2})] if len(ref) else []
    for name, xyz, _, k, line in lines:
        color = colors[line.get("color", k) % len(colors)]
        drawn.append((xyz, color, 0.9))
        entries.append((name, {"color": color, "lw": 0.9}))
    ends = [(ref, "0.55")] if len(ref) else []
    ends += [(xyz, c) for xyz, c, _ in drawn[len(ends) :] if len(xyz)]
    for ax, j, label in ((ax_top, 1, "y [m]"), (ax_side, 2, "z [m]")):
        if drawn:
            ax.add_collection(
                LineCollection(
                    [xyz[:, [0, j]] for xyz, _, _ in drawn],
                    colors=[c for _, c, _ in drawn],
                    linewidths=[lw for _, _, lw in drawn],
                    zorder=2,
                ),
                autolim=False,
            )
        if ends:
            _ends(ax, ends, j)
        ax.set_ylabel(label)
    # to scale: the top view's y range is its x range times its height over its width (never less
    # than the view's: th >= aw * ratio above), set here rather than by an equal aspect, which would
    # override these limits with a warning
    half = 0.5 * (hi[0] - lo[0]) * th / aw
    ax_top.set_xlim(lo[0], hi[0])
    ax_top.set_ylim(0.5 * (lo[1] + hi[1]) - half, 0.5 * (lo[1] + hi[1]) + half)
    ax_side.set_ylim(lo[2], hi[2])
    ax_side.set_xlabel("x [m]")
    entries += [
        ("start", {"color": "0.3", "marker": "o"}),
        ("end", {"color": "0.3", "marker": "s"}),
    ]
    _key(
        ax_top, left + aw * 1.03, bottom + side + gap + th, entries, title=d.get("dataset") or None
    )
    return fig


def _boxes(plt, b, w, h):
    """Boxes per algorithm at each segment length: translation beside rotation, from box statistics
    (``med``, ``q1``, ``q3``, ``whislo``, ``whishi``) computed over the pooled segments. Drawn as
    a few paths a panel (the whiskers and caps, the medians, each algorithm's boxes): a PDF writes
    each path of a collection on its own, 720 a panel for 10 algorithms at 6 lengths otherwise."""
    from matplotlib.collections import PathCollection
    from matplotlib.path import Path as MplPath

    d = b["data"]
    colors = d.get("colors") or OKABE_ITO
    lengths, algs = d["lengths"], d["algorithms"]
    rows = -(-max(len(algs), 1) // 5) + 1  # legend rows above the panels, and its title
    top = 0.25 + 0.16 * rows

    def make():
        fig, _ = plt.subplots(1, 2, figsize=(w, h))
        fig.subplots_adjust(
            left=0.6 / w, right=1 - 0.1 / w, bottom=0.45 / h, top=1 - top / h, wspace=0.3
        )
        return fig

    def strokes(segments, lw, zorder):
        """Line segments as one path (each its move and line)."""
        vertices = np.asarray(segments, float).reshape(-1, 2)
        codes = np.tile([MplPath.MOVETO, MplPath.LINETO], len(segments))
        path = MplPath(vertices, codes.astype(MplPath.code_type))
        return PathCollection([path], facecolors="none", edgecolors="black", lw=lw, zorder=zorder)

    fig = _layout(plt, "boxes", (w, h, top), make)
    axes = fig.axes
    width = 0.8 / max(len(algs), 1)
    half, cap = 0.4 * width, 0.2 * width
    entries = []
    for ax, key, ylabel in zip(axes, ("trans", "rot"), d["ylabels"]):
        boxes, faces, whiskers, medians = [], [], [], []
        for a, alg in enumerate(algs):
            color = colors[alg.get("color", a) % len(colors)]
            mine = []
            for j, s in enumerate(alg[key]):
                if s is None:
                    continue
                x = j - 0.4 + width * (a + 0.5)
                lo, q1, med, q3, hi = s["whislo"], s["q1"], s["med"], s["q3"], s["whishi"]
                mine.append([(x - half, q1), (x + half, q1), (x + half, q3), (x - half, q3)])
                whiskers += [
                    [(x, lo), (x, q1)],
                    [(x, q3), (x, hi)],
                    [(x - cap, lo), (x + cap, lo)],
                    [(x - cap, hi), (x + cap, hi)],
                ]
                medians.append([(x - half, med), (x + half, med)])
            if mine:  # an algorithm's boxes as one path: one colour
                boxes.append(MplPath.make_compound_path_from_polys(np.array(mine, float)))
                faces.append(color)
            if key == "trans":
                entries.append((alg["label"], {"color": color, "lw": 4}))
        if boxes:
            ax.add_collection(strokes(whiskers, 0.6, 1))
            ax.add_collection(
                PathCollection(boxes, facecolors=faces, edgecolors="black", lw=0.5, alpha=0.8)
            )
            ax.add_collection(strokes(medians, 0.8, 3))
            ax.autoscale_view()
            _log_if_spread(ax, np.array([seg[0][1] for seg in medians]), np.array(whiskers))
        ax.set_xticks(np.arange(len(lengths)), [f"{v:g}" for v in lengths])
        ax.set_xlim(-0.5, max(len(lengths), 1) - 0.5)
        ax.set_xlabel("segment length [m]")
        ax.set_ylabel(ylabel)
    pad = 0.1 * float(plt.rcParams["legend.fontsize"]) / 72
    _key(
        axes[0],
        0.6,
        h - pad,
        entries,
        title=d.get("dataset") or None,
        ncols=min(len(entries), 5) or 1,
    )
    return fig


def _log_if_spread(ax, medians: np.ndarray, segments: np.ndarray) -> None:
    """A log axis where the medians span more than two decades (a diverged run would flatten the
    others), from the smallest positive value drawn: an error of zero sits on the bottom edge."""
    positive = medians[medians > 0]
    if not positive.size or positive.max() <= 100 * positive.min():
        return
    ys = segments[..., 1].ravel()
    ys = ys[ys > 0]
    ax.set_yscale("log")
    ax.set_ylim(ys.min() / 1.5, ys.max() * 1.5)
    _log_axis(ax)


def _log_axis(ax):
    """A log y axis labelled in plain numbers: 1-2-5 steps over up to two decades, decades beyond."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    if not ax.dataLim.y1 > 0:  # nothing positive (every case failed, every error zero): linear,
        ax.set_ylim(0, 1)  # from zero, with short tick labels that leave room for the axis label
        return
    ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    subs = (1.0, 2.0, 5.0) if hi / max(lo, 1e-300) <= 100 else (1.0,)
    ax.yaxis.set_major_locator(LogLocator(subs=subs))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


RENDERERS = {
    "trajectory": _trajectory,
    "ape_time": _ape_time,
    "rpe_box": _rpe_box,
    "xcorr": _xcorr,
    "steps": _steps,
    "sigma3": _sigma3,
    "grouped": _grouped,
    "lines": _lines,
    "overlay": _overlay,
    "boxes": _boxes,
}
