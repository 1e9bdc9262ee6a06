"""``epa traj`` (what is in a trajectory file or bag; export to TUM or CSV) and ``epa fig`` (render a
plot bundle again)."""

from __future__ import annotations

from pathlib import Path

from epa.cli.common import REPORT
from epa.core.errors import EpaError


def add_parsers(sub) -> None:
    _add_traj(sub)
    _add_fig(sub)


def _add_traj(sub) -> None:
    tr = sub.add_parser(
        "traj", help="what is in a trajectory file or bag; export a topic to TUM or CSV"
    )
    tr.set_defaults(func=_traj)
    tr.add_argument("source", help="text trajectory file, .bag, .mcap or ROS 2 bag folder")
    tr.add_argument("--topic", help="bag topic to read (without: list the bag's topics)")
    tr.add_argument(
        "--frames", nargs=2, metavar=("PARENT", "CHILD"), help="TF frames (with --topic /tf)"
    )
    tr.add_argument("--stamp", choices=["header", "record"], default="header")
    tr.add_argument(
        "--format", default="auto", help="text format (auto, tum, kitti, euroc, openvins, csv)"
    )
    tr.add_argument(
        "--export",
        help="write the trajectory to FILE: TUM (.txt, .tum: 8 columns) or CSV (.csv: t x y z qx qy qz qw)",
    )
    tr.add_argument(
        "--covariance",
        action="store_true",
        help="with --export: also the orientation and position covariance upper triangles (TUM:"
        " the OpenVINS 20-column layout; CSV: named columns pr11..pt33); an error without covariance",
    )


def _add_fig(sub) -> None:
    f = sub.add_parser(
        "fig", help="render a plot bundle again (another style or size), recomputing nothing"
    )
    f.set_defaults(func=_fig)
    f.add_argument(
        "bundle", nargs="?", help=f"a bundle .json ({REPORT}/bundles/, results/figures/bundles/)"
    )
    f.add_argument("--out", help="output path without extension")
    f.add_argument(
        "--case",
        help="a case folder (results/cases/<algorithm>/<dataset>/<run>): draw every figure of its"
        f" report ({REPORT}/figures/) from its bundles",
    )
    f.add_argument("--style", default="paper", help="paper (3.5 in column), wide (7 in), slide")
    f.add_argument(
        "--width", type=float, help="width in inches (the height follows the style's proportions)"
    )
    f.add_argument("--pdf", action="store_true", help="also write a vector PDF")


def _fig(args) -> None:
    from epa.outputs import figures

    if (args.case is None) == (args.bundle is None) or (args.bundle and not args.out):
        raise EpaError("give a bundle and --out, or --case CASE_DIR")
    formats = ("png", "pdf") if args.pdf else ("png",)
    if args.bundle:
        jobs = [(Path(args.bundle), Path(args.out))]
    else:
        report = Path(args.case) / REPORT
        jobs = [(b, report / "figures" / b.stem) for b in sorted(report.glob("bundles/*.json"))]
        if not jobs:
            raise EpaError(
                f"no plot bundles in {REPORT}/bundles (has the report stage run?)", path=args.case
            )
    written = []
    for bundle, out in jobs:
        try:
            written += figures.render(
                figures.read_bundle(bundle),
                out,
                style=args.style,
                width=args.width,
                formats=formats,
            )
        except EpaError as exc:  # a bundle's own problem names the bundle
            if exc.path or exc.message.startswith(("unknown style", "--width")):
                raise
            raise EpaError(exc.message, path=str(bundle)) from None
    print("wrote " + ", ".join(map(str, written)))


def _traj(args) -> None:
    from epa import readers
    from epa.artifacts import files
    from epa.core.trajectory import Trajectory
    from epa.readers import bags
    from epa.workflow import settings

    if bags.is_bag(args.source) and not args.topic and not args.frames:
        infos = bags.topics(args.source)
        print(f"{args.source}: {len(infos)} topics")
        width = max([len(i.topic) for i in infos] + [5])
        for i in infos:
            span = (
                ""
                if i.start_s is None or i.end_s is None
                else f"{i.end_s - i.start_s:9.3f} s  {i.start_s:.6f} .. {i.end_s:.6f}"
            )
            mark = "*" if i.supported else " "
            print(f" {mark} {i.topic:<{width}}  {i.msgtype:<45} {i.count:8d} msgs  {span}".rstrip())
        print("   (* a pose type: read it with --topic, TF with --topic /tf --frames PARENT CHILD)")
        return
    # a source at the configured defaults, with what the command line names
    opts = {
        **readers.options(settings.defaults(), "reference"),
        "format": args.format,
        "topic": args.topic,
        "frames": args.frames,
        "stamp": args.stamp,
    }
    notes: list[str] = []
    traj = readers.read(args.source, opts, notes=notes)
    print(readers.describe(args.source, traj, notes))
    if args.export:
        out = args.export
        fmt = {".txt": "tum", ".tum": "tum", ".csv": "csv"}.get(Path(out).suffix.lower())
        if fmt is None:
            raise EpaError(
                "export to .txt or .tum (TUM) or .csv (CSV with named columns)", path=out
            )
        has_cov = traj.cov_rot is not None
        if args.covariance:
            if not has_cov:
                raise EpaError(
                    "--covariance: this trajectory has no covariance to write", path=args.source
                )
            fmt_written = "openvins" if fmt == "tum" else fmt
        else:
            traj, fmt_written = Trajectory(traj.t, traj.p, traj.q), fmt
            if traj.position_only and fmt == "tum":  # t x y z: no orientation to write
                fmt_written = "position"
        files.write_trajectory(out, traj, fmt_written)
        what = "OpenVINS layout: TUM + covariance" if fmt_written == "openvins" else fmt_written
        left = (
            "; its covariance is left out (--covariance writes it)"
            if has_cov and not args.covariance
            else ""
        )
        print(f"wrote {len(traj)} poses to {out} ({what}{left})")
    elif args.covariance:
        raise EpaError("--covariance is an option of --export (nothing is written without it)")
