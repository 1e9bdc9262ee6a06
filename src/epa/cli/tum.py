"""``epa tum-ate`` and ``epa tum-rpe``: the TUM RGB-D benchmark's scripts, their arguments and their
printed text (docs/protocols.md)."""

from __future__ import annotations

import math

from epa.core.errors import EpaError


def add_parsers(sub) -> None:
    _add_tum_ate(sub)
    _add_tum_rpe(sub)


def _add_tum_ate(sub) -> None:
    """``epa tum-ate``: the TUM RGB-D benchmark's ``evaluate_ate.py``, its arguments and its printed
    text (docs/protocols.md)."""
    a = sub.add_parser("tum-ate", help="the TUM RGB-D benchmark's evaluate_ate.py")
    a.set_defaults(func=_tum_ate)
    a.add_argument(
        "first_file", help="ground truth trajectory (format: timestamp tx ty tz qx qy qz qw)"
    )
    a.add_argument(
        "second_file", help="estimated trajectory (format: timestamp tx ty tz qx qy qz qw)"
    )
    a.add_argument(
        "--offset",
        type=float,
        default=0.0,
        help="time offset added to the timestamps of the second file (default: 0.0)",
    )
    a.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="scaling factor for the second trajectory (default: 1.0)",
    )
    a.add_argument(
        "--max_difference",
        type=float,
        default=0.02,
        help="maximally allowed time difference for matching entries (default: 0.02)",
    )
    a.add_argument(
        "--save", help="save aligned second trajectory to disk (format: stamp2 x2 y2 z2)"
    )
    a.add_argument(
        "--save_associations",
        help="save associated first and aligned second trajectory to disk (format: stamp1 x1 y1 z1 stamp2 x2 y2 z2)",
    )
    a.add_argument(
        "--plot",
        help="plot the first and the aligned second trajectory to an image (format: png; imports matplotlib)",
    )
    a.add_argument(
        "--verbose",
        action="store_true",
        help="print all evaluation data (otherwise, only the RMSE absolute translational error in meters"
        " after alignment)",
    )


def _add_tum_rpe(sub) -> None:
    """``epa tum-rpe``: the TUM RGB-D benchmark's ``evaluate_rpe.py``, its arguments and its printed
    text, and ``--sampler`` (docs/protocols.md)."""
    r = sub.add_parser("tum-rpe", help="the TUM RGB-D benchmark's evaluate_rpe.py")
    r.set_defaults(func=_tum_rpe)
    r.add_argument(
        "groundtruth_file",
        help='ground-truth trajectory file (format: "timestamp tx ty tz qx qy qz qw")',
    )
    r.add_argument(
        "estimated_file",
        help='estimated trajectory file (format: "timestamp tx ty tz qx qy qz qw")',
    )
    r.add_argument(
        "--max_pairs",
        type=int,
        default=10000,
        help="maximum number of pose comparisons (default: 10000, set to zero to disable downsampling)",
    )
    r.add_argument(
        "--fixed_delta",
        action="store_true",
        help="only consider pose pairs that have a distance of delta delta_unit",
    )
    r.add_argument("--delta", type=float, default=1.0, help="delta for evaluation (default: 1.0)")
    r.add_argument(
        "--delta_unit",
        default="s",
        choices=["s", "m", "rad", "deg", "f"],
        help="unit of delta: seconds, meters, radians, degrees or frames (default: s)",
    )
    r.add_argument(
        "--offset",
        type=float,
        default=0.0,
        help="time offset between ground-truth and estimated trajectory (default: 0.0)",
    )
    r.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="scaling factor for the estimated trajectory (default: 1.0)",
    )
    r.add_argument(
        "--save",
        help="text file to which the evaluation will be saved"
        " (format: stamp_est0 stamp_est1 stamp_gt0 stamp_gt1 trans_error rot_error)",
    )
    r.add_argument(
        "--plot",
        help="plot the result to a file (requires --fixed_delta, output format: png; imports matplotlib)",
    )
    r.add_argument(
        "--verbose",
        action="store_true",
        help="print all evaluation data (otherwise, only the mean translational error in meters)",
    )
    r.add_argument(
        "--sampler",
        choices=["python2", "python3"],
        default="python2",
        help="whose random module draws the --max_pairs pairs: the published script's Python 2"
        " (default) or a Python 3 port's",
    )


def _naming(path, compute):
    """``compute``, its errors naming the estimate's file (the scripts' messages name none)."""

    def run(*args, **kwargs):
        try:
            return compute(*args, **kwargs)
        except EpaError as exc:
            raise EpaError(exc.message, path=path) from None

    return run


def _finite_options(args, names) -> None:
    """A NaN or infinite option would give NaN numbers or a candidate for every pair of poses."""
    for name in names:
        value = getattr(args, name)
        if not math.isfinite(value):
            raise EpaError(f"--{name} must be a finite number, not {value}")


def _tum_ate(args) -> None:
    import numpy as np

    from epa.artifacts import files
    from epa.metrics import tum
    from epa.readers import tum_script

    _finite_options(args, ("offset", "scale", "max_difference"))
    ref_t, ref_p = tum_script.positions(args.first_file)
    est_t, est_p = tum_script.positions(args.second_file)
    fit = _naming(args.second_file, tum.ate)(
        ref_t,
        ref_p,
        est_t,
        est_p,
        offset=args.offset,
        scale=args.scale,
        max_difference=args.max_difference,
    )
    print("\n".join(tum.ate_lines(fit["error"], args.verbose)))
    aligned = (
        est_p * args.scale @ fit["rot"].T + fit["trans"]
    )  # the whole estimate, as --save writes it
    i_ref, i_est = fit["i_ref"], fit["i_est"]
    if args.save_associations:
        rows = np.column_stack([ref_t[i_ref], ref_p[i_ref], est_t[i_est], aligned[i_est]])
        files.write_text(
            args.save_associations, "\n".join(" ".join(f"{v:f}" for v in row) for row in rows)
        )
    if args.save:
        rows = np.column_stack([est_t, aligned])
        files.write_text(args.save, "\n".join(" ".join(f"{v:f}" for v in row) for row in rows))
    if args.plot:
        from epa.outputs import tum_figures

        tum_figures.ate(args.plot, ref_t, ref_p, est_t, aligned, ref_p[i_ref], aligned[i_est])


def _tum_rpe(args) -> None:
    from epa.artifacts import files
    from epa.metrics import tum
    from epa.readers import tum_script

    _finite_options(args, ("offset", "scale", "delta"))
    if args.max_pairs < 0:
        raise EpaError(
            f"--max_pairs must be 0 (every pair) or a number of pairs, not {args.max_pairs}"
        )
    if args.plot and not args.fixed_delta:
        raise EpaError(
            "--plot: The '--plot' option can only be used in combination with '--fixed_delta'"
        )
    gt_t, gt_p, gt_q = tum_script.poses(args.groundtruth_file)
    est_t, est_p, est_q = tum_script.poses(args.estimated_file)
    for path, t in ((args.groundtruth_file, gt_t), (args.estimated_file, est_t)):
        if len(t) < 2:
            raise EpaError(f"{len(t)} poses: the relative pose error needs 2", path=path)
    gt = _naming(args.groundtruth_file, tum.transform44)(gt_q, gt_p)
    est = _naming(args.estimated_file, tum.transform44)(est_q, est_p)
    rows = _naming(args.estimated_file, tum.rpe)(
        gt_t,
        gt,
        est_t,
        est,
        max_pairs=args.max_pairs,
        fixed_delta=args.fixed_delta,
        delta=args.delta,
        delta_unit=args.delta_unit,
        offset=args.offset,
        scale=args.scale,
        sampler=args.sampler,
    )
    if args.save:
        files.write_text(args.save, "\n".join(" ".join(f"{v:f}" for v in row) for row in rows))
    print("\n".join(tum.rpe_lines(rows, args.verbose)))
    if args.plot:
        from epa.outputs import tum_figures

        tum_figures.rpe(args.plot, rows[:, 0], rows[:, 4])
