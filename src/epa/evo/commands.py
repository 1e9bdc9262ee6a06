"""`epa ape`, `epa rpe` (evo's command lines) and `epa res` (a table of saved results, as evo_res).

    epa ape tum|euroc|kitti REF EST [options]      epa ape bag|bag2|mcap BAG REF_TOPIC EST_TOPIC [options]
    epa rpe ... (the same forms, plus -d/-u/--all_pairs ...)
    epa res RESULT... [--save_table FILE.csv]

Option names and defaults are evo 1.38.1's; docs/evo.md maps every evo option to epica's.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

from epa.core.errors import EpaError

FORMS = {
    "tum": ("ref_file", "est_file"),
    "euroc": ("state_gt_csv", "est_file"),
    "kitti": ("ref_file", "est_file"),
    "bag": ("bag", "ref_topic", "est_topic"),
    "bag2": ("bag", "ref_topic", "est_topic"),
    "mcap": ("bag", "ref_topic", "est_topic"),
}
RESULT_FORMAT = "epica-result/1"
TF_LOOKUP_HZ = 10.0  # evo's setting tf_cache_lookup_frequency


def add_parsers(sub) -> None:
    for kind in ("ape", "rpe"):
        title = "absolute pose error" if kind == "ape" else "relative pose error"
        p = sub.add_parser(
            kind, help=f"{title} with evo's command line (evo_{kind}'s forms, options and printout)"
        )
        forms = p.add_subparsers(
            dest="form", required=True, metavar="{tum,euroc,kitti,bag,bag2,mcap}"
        )
        for form, positionals in FORMS.items():
            f = forms.add_parser(form, help=f"{' '.join(x.upper() for x in positionals)}")
            for name in positionals:
                f.add_argument(name)
            _add_options(f, kind, timed=form != "kitti")
            if form in ("bag", "bag2", "mcap"):
                f.add_argument(
                    "--tf_cache_lookup_frequency",
                    type=float,
                    default=TF_LOOKUP_HZ,
                    help="a TF id (/tf:parent.child) is looked up at this rate (Hz), from the first "
                    "TF message on, as evo's setting of that name (default: 10)",
                )


def _add_options(f, kind: str, timed: bool) -> None:
    from epa.metrics import relations

    choices = list(relations.RELATIONS) if kind == "rpe" else list(relations.RELATIONS[:-1])
    f.add_argument(
        "-r",
        "--pose_relation",
        default="trans_part",
        choices=choices,
        help="pose relation the error is based on (default: trans_part)",
    )
    group = f.add_mutually_exclusive_group()
    group.add_argument("-a", "--align", action="store_true", help="Umeyama SE(3) alignment")
    group.add_argument("--align_origin", action="store_true", help="align the first poses")
    group.add_argument(
        "--align_posyaw",
        action="store_true",
        help="align position and yaw only (4-DoF; not in evo 1.38.1: its pending option)",
    )
    f.add_argument(
        "-s", "--correct_scale", action="store_true", help="with -a: Sim(3); alone: the scale only"
    )
    f.add_argument(
        "--n_to_align", type=int, default=-1, help="align on the first N poses (default: all)"
    )
    f.add_argument(
        "--project_to_plane",
        choices=["xy", "xz", "yz"],
        help="project both to a plane after aligning",
    )
    if kind == "rpe":
        f.add_argument(
            "-d", "--delta", type=float, default=1, help="delta between the poses of a pair"
        )
        f.add_argument(
            "-u",
            "--delta_unit",
            default="f",
            choices=["f", "d", "r", "m"],
            help="unit of delta: f frames, d degrees, r radians, m metres",
        )
        f.add_argument(
            "-t",
            "--delta_tol",
            type=float,
            default=0.1,
            help="relative delta tolerance (all pairs)",
        )
        f.add_argument(
            "--all_pairs", action="store_true", help="all pairs instead of consecutive pairs"
        )
        f.add_argument(
            "--pairs_from_reference", action="store_true", help="choose the pairs on the reference"
        )
    if timed:
        f.add_argument("--t_max_diff", type=float, default=0.01, help="association tolerance (s)")
        f.add_argument(
            "--t_offset", type=float, default=0.0, help="added to the estimate's stamps (s)"
        )
        f.add_argument("--t_start", type=float, help="use reference poses from this stamp (s)")
        f.add_argument("--t_end", type=float, help="use reference poses up to this stamp (s)")
        f.add_argument(
            "--sync_method", default="nearest_time", choices=["nearest_time", "interpolation"]
        )
        f.add_argument(
            "--step1",
            action="store_true",
            help="epica: estimate the time offset (Step 1) and add it to --t_offset",
        )
    _add_output_options(f)


def _add_output_options(f) -> None:
    """What evo's commands write: the result file, the figures, the printed block."""
    from epa.evo.plots import PLOT_MODES, X_DIMENSIONS

    f.add_argument(
        "--unsorted",
        default="error",
        choices=["error", "sort", "keep"],
        help="repeated or backward stamps: stop (default), sort and drop repeats, or keep repeats (evo)",
    )
    f.add_argument(
        "--save_results",
        help="write the result: FILE.zip (evo's result zip, which evo_res reads) or FILE.json",
    )
    f.add_argument(
        "-p",
        "--plot",
        action="store_true",
        help="show evo's figures (error over time, trajectory coloured by it) in a window; "
        "without a display, only with --save_plot",
    )
    f.add_argument(
        "--save_plot",
        help="write evo's figures: FILE.pdf (both pages) or FILE.png (FILE_raw.png, FILE_map.png)",
    )
    f.add_argument(
        "--plot_mode", choices=list(PLOT_MODES), help="the trajectory's axes (default: xyz, 3D)"
    )
    f.add_argument(
        "--plot_x_dimension",
        choices=list(X_DIMENSIONS),
        help="x axis of the error plot (default: seconds; index without stamps)",
    )
    f.add_argument("--silent", action="store_true", help="do not print the statistics block")


def _read(args, which: str, table=None):
    """``table``: the file's table being read (:func:`_read_ahead`), or None."""
    bag = args.form in ("bag", "bag2", "mcap")
    return read_source(
        args.form,
        args.bag if bag else _path(args, which),
        getattr(args, f"{which}_topic") if bag else None,
        reference=which == "ref",
        unsorted=args.unsorted,
        tf_rate=getattr(args, "tf_cache_lookup_frequency", TF_LOOKUP_HZ),
        table=table,
    )


def _read_ahead(args) -> dict:
    """{"ref"|"est": its table being read}: the two files of a text form parsed in threads
    (:func:`epa.readers.text.tables_ahead`; the parse releases the GIL) while the command imports
    its maths and reads its settings; only regular files (anything else is read, and reported, as
    before)."""
    import os
    import stat

    from epa.readers import text

    if args.form in ("bag", "bag2", "mcap"):
        return {}
    paths = {}
    for which in ("ref", "est"):
        try:
            regular = stat.S_ISREG(os.stat(_path(args, which)).st_mode)
        except (OSError, ValueError):
            continue
        if regular:
            paths[which] = Path(_path(args, which))
    return dict(zip(paths, text.tables_ahead(list(paths.values()))))


def read_source(
    form: str,
    path,
    topic: str | None = None,
    *,
    reference: bool = False,
    unsorted: str = "error",
    tf_rate: float = TF_LOOKUP_HZ,
    table=None,
):
    """One side of an evo command: a file of ``form`` or a bag topic, or a TF id ``/tf:parent.child``
    (optionally ``:/tf_static``) looked up at ``tf_rate`` Hz as evo does. ``table``: a text file's
    table already started (:class:`epa.readers.text.TableAhead`)."""
    from epa import readers
    from epa.workflow import settings

    opts = readers.options(settings.defaults(), "reference")
    opts["unsorted"] = unsorted
    if form in ("bag", "bag2", "mcap"):
        if topic is not None and ":" in topic:  # evo's TF id: /tf:parent.child(:/tf_static)
            tf_topic, _, frames = topic.partition(":")
            frames, _, static_topic = frames.partition(":")
            parent, _, child = frames.partition(".")
            if not parent or not child:
                raise EpaError(f"TF id {topic!r} should look like /tf:parent.child", path=str(path))
            if tf_rate <= 0:
                raise EpaError(f"--tf_cache_lookup_frequency must be positive, not {tf_rate}")
            opts.update(
                frames=(parent, child), tf_rate=tf_rate, static_topic=static_topic or "/tf_static"
            )
            topic = tf_topic
        opts["topic"] = topic
    else:
        opts["format"] = (
            "euroc" if (form == "euroc" and reference) else ("kitti" if form == "kitti" else "tum")
        )
        opts["kitti_printed"] = form == "kitti"  # evo computes on the printed rotation blocks
    try:
        return readers.read(path, opts, table=table)
    except EpaError as exc:
        if "repeats" in str(exc):
            raise EpaError(
                f"{exc.one_line()}; --unsorted keep keeps repeated stamps as evo does"
            ) from None
        raise


def run(args) -> None:
    _check_numbers(args)
    show = _check_plot(args)
    result = compute(args)
    if not args.silent:
        print(result.statistics_block(), end="")
    if args.plot or args.save_plot:
        _plot(args, result, show)
    if args.save_results:
        # evo's zip names each side as evo does (the file as given, or the topic)
        name = _evo_name if Path(args.save_results).suffix.lower() == ".zip" else _source
        save(result, args.save_results, ref=name(args, "ref"), est=name(args, "est"))
        print(f"wrote {args.save_results}")


def compute(args):
    """The :class:`epa.evo.protocol.EvoResult` of parsed ``epa ape|rpe`` arguments."""
    tables = _read_ahead(args)
    try:
        from epa.evo import protocol as evo_protocol

        names = {"pose_relation": "relation"}
        fields = set(evo_protocol.EvoOptions.__dataclass_fields__)
        values = {
            names.get(k, k): v
            for k, v in vars(args).items()
            if names.get(k, k) in fields and v is not None
        }
        o = evo_protocol.EvoOptions(**values)
        ref = _read(args, "ref", tables.get("ref"))
        est = _read(args, "est", tables.get("est"))
    finally:  # a side that failed: the other's reading ends here
        for table in tables.values():
            table.join()
    fn = evo_protocol.ape if args.command == "ape" else evo_protocol.rpe
    return fn(ref, est, o, timed=args.form != "kitti")


def _check_plot(args) -> bool:
    """Whether --plot opens windows; before any reading: a plot setting without a plot, a
    --save_plot suffix matplotlib cannot write, or --plot with no display and no --save_plot is one
    line."""
    from epa.evo import plots

    plotting = args.plot or args.save_plot
    for name in ("plot_mode", "plot_x_dimension"):
        if getattr(args, name, None) is not None and not plotting:
            raise EpaError(f"--{name} draws nothing without --plot or --save_plot")
    if args.save_plot:
        plots.outputs(args.save_plot)
    show = bool(args.plot) and plots.can_show()
    if args.plot and not show and not args.save_plot:
        raise EpaError(
            "--plot: no display to open a window on; write the figures with --save_plot "
            "FILE.pdf or FILE.png"
        )
    return show


def _plot(args, result, show: bool) -> None:
    from epa.evo import plots

    figures = plots.draw(
        result,
        plot_mode=args.plot_mode or "xyz",
        x_dimension=args.plot_x_dimension or "seconds",
        show=show,
    )
    if args.save_plot:
        written = ", ".join(str(p) for p in plots.save(figures, args.save_plot))
        print(
            f"wrote {written}"
            if show or not args.plot
            else f"no display for --plot: wrote {written}"
        )
    import matplotlib.pyplot as plt

    if show:
        plt.show()
    for fig in figures.values():
        plt.close(fig)


# options that must be positive (deltas, tolerances, rates) or at least 0; every number is finite
POSITIVE = ("delta", "delta_tol", "tf_cache_lookup_frequency")
NOT_NEGATIVE = ("t_max_diff",)


def _check_numbers(args) -> None:
    import math

    n = getattr(args, "n_to_align", -1)
    if n < -1:  # -1 is evo's "all"; another negative would cut poses off the end silently
        raise EpaError(f"--n_to_align must be -1 (all) or a number of poses, not {n}")
    for name, v in sorted(vars(args).items()):
        if not isinstance(v, float):
            continue
        flag = "--" + name
        if not math.isfinite(v):
            raise EpaError(f"{flag} must be a finite number, not {v}")
        if name in POSITIVE and v <= 0:
            raise EpaError(f"{flag} must be positive, not {v:g}")
        if name in NOT_NEGATIVE and v < 0:
            raise EpaError(f"{flag} must not be negative, not {v:g}")


def _path(args, which: str) -> str:
    """The file of one side of a text form (evo names the EuRoC reference state_gt_csv)."""
    return getattr(
        args, "state_gt_csv" if (args.form == "euroc" and which == "ref") else f"{which}_file"
    )


def _evo_name(args, which: str) -> str:
    """The name evo gives one side: its file as given on the command line, or its bag topic."""
    if args.form in ("bag", "bag2", "mcap"):
        return getattr(args, f"{which}_topic")
    return str(_path(args, which))


def _source(args, which: str) -> str:
    if args.form in ("bag", "bag2", "mcap"):
        return f"{args.bag}:{getattr(args, f'{which}_topic')}"
    return str(_path(args, which))


# ----------------------------------------------------------------------------- saved results
def save(result, path, *, ref: str, est: str) -> None:
    """The result as evo's result zip (``FILE.zip``, :mod:`epa.evo.archive`; ``ref`` and ``est``
    named as evo names them), or as JSON (``epica-result/1``: kind, title, stats, options, info,
    reference and estimate names, the error array)."""
    from epa.artifacts import files
    from epa.evo import archive
    from epa.outputs import figures

    if Path(path).suffix.lower() == ".zip":
        archive.write(path, result, ref_name=ref, est_name=est)
        return
    doc = {
        "format": RESULT_FORMAT,
        "kind": result.kind,
        "title": result.title,
        "ref": ref,
        "est": est,
        "stats": result.stats,
        "options": result.options,
        "info": result.info,
    }
    files.write_text(path, figures._json({**doc, "errors": result.errors}) + "\n")


STAT_COLUMNS = ("rmse", "mean", "median", "std", "min", "max", "sse")


def load_results(path) -> list[dict]:
    """Rows {name, what, stats} of one saved file: evo's result zip (written by evo or by ``epa
    ape/rpe --save_results X.zip``; the row also holds it as ``evo``), an ``epa ape/rpe`` JSON, the
    zip epica wrote before (result.json and errors.csv), a case's metrics.json (06_metrics/ or
    10_report/), or a case's result bundle .zip."""
    from epa.evo import archive

    path = Path(path)
    try:
        if path.suffix.lower() == ".zip":
            with zipfile.ZipFile(path) as z:
                if archive.is_evo_zip(z):
                    r = archive.read(z, str(path))
                    return [
                        {
                            "name": str(path),
                            "what": r.title.split("\n")[0],
                            "stats": r.stats,
                            "evo": r,
                        }
                    ]
                names = z.namelist()
                inner = next((n for n in names if n.endswith("result.json")), None) or next(
                    (n for n in names if n.endswith("metrics.json")), None
                )
                if inner is None:
                    raise EpaError(
                        "the zip holds neither result.json nor metrics.json", path=str(path)
                    )
                doc = json.loads(z.read(inner))
        else:
            doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise EpaError("file not found", path=str(path)) from None
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise EpaError(f"not a result file: {exc}", path=str(path)) from None
    where = str(path)
    if isinstance(doc, dict) and doc.get("format") == RESULT_FORMAT:
        title = doc.get("title")
        if not isinstance(title, str):
            raise EpaError(f"{RESULT_FORMAT} result without a title (key 'title')", path=where)
        return [{"name": where, "what": title.split("\n")[0], "stats": _stats(doc, "stats", where)}]
    metrics = doc.get("metrics", doc) if isinstance(doc, dict) else None
    if not isinstance(metrics, dict) or "ate" not in metrics:
        raise EpaError(
            "neither an epa result (epica-result/1) nor a case's metrics.json", path=where
        )
    if not isinstance(metrics["ate"], dict):
        why = " (the case failed)" if metrics.get("status") == "failed" else ""
        raise EpaError(f"key 'ate' holds no ATE: {metrics['ate']!r}{why}", path=where)
    rows = [
        {"name": where, "what": f"ATE {key}", "stats": _stats(metrics["ate"], key, where, "ate.")}
        for key in ("trans_m", "rot_deg")
        if key in metrics["ate"]
    ]
    rpe = metrics.get("rpe", [])
    if not isinstance(rpe, list) or not all(isinstance(spec, dict) for spec in rpe):
        raise EpaError("key 'rpe' is not a list of RPE records", path=where)
    for k, spec in enumerate(rpe):
        label = f"RPE {spec.get('delta')} {spec.get('unit')}{' all pairs' if spec.get('all_pairs') else ''}"
        rows += [
            {
                "name": where,
                "what": f"{label} {key}",
                "stats": _stats(spec, key, where, f"rpe.{k}."),
            }
            for key in ("trans_m", "rot_deg")
            if key in spec
        ]
    return rows


def _stats(doc: dict, key: str, where: str, prefix: str = "") -> dict:
    """A statistics record {rmse, mean, ...}: numbers (or null for none)."""
    stats = doc.get(key)
    if not isinstance(stats, dict):
        raise EpaError(f"key '{prefix}{key}' holds no statistics: {stats!r}", path=where)
    for name in STAT_COLUMNS:
        v = stats.get(name)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise EpaError(f"key '{prefix}{key}.{name}' is not a number: {v!r}", path=where)
    return stats


def res(args) -> None:
    rows = [row for path in args.results for row in load_results(path)]
    table = [
        [r["name"], r["what"], *(_cell(r["stats"].get(c)) for c in STAT_COLUMNS)] for r in rows
    ]
    if all("evo" in r for r in rows):  # evo's zips only: evo_res's printout
        _evo_res(args, [r["evo"] for r in rows])
    else:
        header = ["result", "metric", *STAT_COLUMNS]
        widths = [max(len(str(x)) for x in col) for col in zip(header, *table)]
        for line in [header, *table]:
            print("  ".join(str(x).ljust(w) for x, w in zip(line, widths)).rstrip())
    if args.save_table:  # epica's table, whatever was printed
        _save_table(args.save_table, table)


def _evo_res(args, zips) -> None:
    """What evo_res prints. A title that differs from the first file's is a warning (evo_res asks
    whether to go on, and then prints the first title)."""
    import sys

    from epa.evo import archive

    text = archive.evo_res_text(zips, use_filenames=args.use_filenames)
    for z in zips[1:]:
        if z.title != zips[0].title:
            print(
                f"warning: {z.path}: its title differs from {zips[0].path}'s, which is printed",
                file=sys.stderr,
            )
    print(text, end="")


def _save_table(path, table: list[list[str]]) -> None:
    from epa.artifacts import files

    header = ["result", "metric", *STAT_COLUMNS]
    files.write_text(
        path, "\n".join(",".join(_csv(x) for x in line) for line in [header, *table]) + "\n"
    )
    print(f"wrote {path}")


def _cell(v) -> str:
    return "" if v is None else f"{v:.6f}"


def _csv(x: str) -> str:
    return f'"{x}"' if ("," in x or '"' in x) else x


def add_res_parser(sub) -> None:
    r = sub.add_parser(
        "res",
        help="a table of saved results (evo's result zips, epa ape/rpe --save_results, "
        "metrics.json, case zips)",
    )
    r.add_argument(
        "results", nargs="+", help="result .zip/.json files (evo's or epica's) or case metrics.json"
    )
    r.add_argument("--save_table", help="also write the table as CSV")
    r.add_argument(
        "--use_filenames",
        action="store_true",
        help="label evo's zips by their file, not their estimate's name (as evo_res)",
    )
