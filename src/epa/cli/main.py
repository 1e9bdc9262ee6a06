"""The ``epa`` command: ``epa eval`` (one case, every stage in one process), ``epa ape|rpe|res``
(evo's command lines, in epa.evo), ``epa rpg`` (rpg_trajectory_evaluation's), ``epa traj``,
``epa fig``, ``epa config``, ``epa selftest``, ``epa stage`` (one stage of one grid case),
``epa verify`` (regenerate a results folder or package and compare it by the numeric contract),
``epa pack`` (a replication package) and ``epa simulate``."""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from epa import __version__
from epa.artifacts.stage import folder
from epa.core import runtime
from epa.core.errors import EpaError

REPORT_STAGE = "report"
REPORT = folder(REPORT_STAGE)  # the report stage's folder in a case folder

# The commands whose parsers this module builds; the others' (evo, rpg, verify, pack) are built by
# their modules, whose imports (numpy, yaml, the contract) a run of these commands does not need.
OWN_COMMANDS = ("eval", "traj", "fig", "config", "selftest", "stage", "simulate")


def _parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line; for one of OWN_COMMANDS only its own parsers (``epa --help`` and the
    other commands build every one)."""
    p = argparse.ArgumentParser(prog="epa", description="Trajectory evaluation for SLAM/VIO.")
    p.add_argument("--version", action="version", version=f"epica {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    # in the order `epa --help` lists them
    _add_eval(sub)
    _add_traj(sub)
    _add_fig(sub)
    _add_config(sub)
    if command not in OWN_COMMANDS:
        _add_evo_rpg_verify(sub)
        _add_tum_ate(sub)
        _add_tum_rpe(sub)
    _add_selftest(sub)
    _add_stage(sub)
    _add_simulate(sub)
    return p


def _add_eval(sub) -> None:
    e = sub.add_parser("eval", help="evaluate one estimate against one reference")
    e.set_defaults(func=_eval)
    e.add_argument("ref", help="reference trajectory file")
    e.add_argument("est", help="estimated trajectory file")
    e.add_argument(
        "--out",
        required=True,
        help="output folder, laid out as a workflow case folder"
        f" ({folder('metrics')}/metrics.json, {folder('drift')}/drift.json, ...),"
        " with metrics.json: every stage's record in one document, as the per-case report's",
    )
    e.add_argument(
        "--artifacts",
        action="store_true",
        help="also write the per-pose and per-pair files (pairs.csv, ape.csv, ...) as the workflow does",
    )
    e.add_argument("-v", "--verbose", action="store_true", help="print each stage and its time")
    e.add_argument(
        "--config", help="YAML with stage settings (the workflow's keys: sync, align, ...)"
    )
    e.add_argument(
        "--algorithm",
        help="the estimate's algorithm: the config's overrides.algorithms and"
        f" sources.algorithms of that name apply (default {EVAL_ALGORITHM!r})",
    )
    e.add_argument(
        "--dataset", help="the reference's dataset: the config's overrides.datasets apply"
    )
    e.add_argument(
        "--metric-scale",
        choices=["true", "false"],
        help="false: the estimate's scale is arbitrary (monocular): Step 2 solves the scale and"
        " Step 3 fits Sim3 (sources.algorithms.<algorithm>.metric_scale)",
    )
    e.add_argument(
        "--mode",
        choices=["epa", "ov_eval", "rpg"],
        help="ov_eval: no Step 1/2, one-to-one 0.02 s; rpg: rpg_trajectory_evaluation's association,"
        " alignment (--align, --first-n: its align_type, align_num_frames) and statistics",
    )
    e.add_argument("--align", choices=["se3", "sim3", "posyaw", "none"], help="Step 3 method")
    e.add_argument("--first-n", type=int, help="align on the first N matched poses")
    e.add_argument("--policy", choices=["ov_eval", "evo", "rpg"], help="association policy")
    e.add_argument("--max-diff", type=float, help="association tolerance (s)")
    e.add_argument("--offset", type=float, help="fixed time offset (s), t_ref = t_est + offset")
    e.add_argument("--no-offset-estimate", action="store_true", help="skip Step 1")
    e.add_argument("--no-calibrate", action="store_true", help="skip Step 2")
    e.add_argument("--scale", action="store_true", help="Step 2 also solves a scale (monocular)")
    e.add_argument("--segments", type=float, nargs="+", help="distance-RPE segment lengths (m)")
    e.add_argument(
        "--protocol",
        action="append",
        choices=_protocols(),
        help="also score by a benchmark's own protocol (metrics.<NAME>.enabled; repeatable;"
        " docs/protocols.md)",
    )
    _add_eval_sources(e)
    e.add_argument(
        "--report",
        action="store_true",
        help=f"also write {REPORT}/ (reports, figures; implies --artifacts, imports matplotlib)",
    )
    e.add_argument(
        "--rerun",
        action="store_true",
        help=f'also write a Rerun recording {REPORT}/<name>.rrd (implies --report; pip install "epica[rerun]")',
    )
    e.add_argument(
        "--timing",
        help="per-frame timing file of the estimate (default: <est>_timing.txt|csv beside it)",
    )
    e.add_argument(
        "--rate", type=float, help="sensor rate (Hz) for EA-Drift (default: from the timing file)"
    )


def _protocols() -> tuple[str, ...]:
    from epa.metrics import registry

    return registry.protocols()


def _add_eval_sources(e) -> None:
    """How `epa eval` reads its two inputs: formats, stamps, bag topics and TF frames."""
    e.add_argument(
        "--ref-format", help="reference format (auto, tum, kitti, euroc, openvins, csv, position)"
    )
    e.add_argument("--est-format", help="estimate format (the same choices)")
    e.add_argument("--unsorted", choices=["error", "sort"], help="repeated/backward stamps")
    e.add_argument("--time-unit", choices=["auto", "s", "ns", "sec_nsec"])
    e.add_argument("--ref-topic", help="reference bag topic")
    e.add_argument("--est-topic", help="estimate bag topic (may be another topic of the same bag)")
    e.add_argument("--ref-frames", nargs=2, metavar=("PARENT", "CHILD"), help="reference TF frames")
    e.add_argument("--est-frames", nargs=2, metavar=("PARENT", "CHILD"), help="estimate TF frames")
    e.add_argument(
        "--stamp",
        choices=["header", "record"],
        help="bag stamps: message header (default) or record time",
    )


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


def _add_config(sub) -> None:
    c = sub.add_parser(
        "config", help="every setting: the defaults, or the effective settings of a config file"
    )
    c.set_defaults(func=_config)
    c.add_argument("config", nargs="?", help="a config YAML (without it: the defaults)")


def _add_evo_rpg_verify(sub) -> None:
    """The commands whose parsers their own modules build; their handlers are attached by name."""
    from epa.evo import commands as cli_evo

    cli_evo.add_parsers(sub)
    cli_evo.add_res_parser(sub)

    from epa.rpg import command as rpg_command

    rpg_command.add_parser(sub)

    from epa.workflow import package, verify

    verify.add_parser(sub)
    package.add_parser(sub)
    handlers = {
        "ape": cli_evo.run,
        "rpe": cli_evo.run,
        "res": cli_evo.res,
        "rpg": rpg_command.run,
        "verify": verify.run,
        "pack": package.run,
    }
    for name, func in handlers.items():
        sub.choices[name].set_defaults(func=func)


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


def _add_selftest(sub) -> None:
    st = sub.add_parser(
        "selftest",
        help="how well Steps 1-2 recover known offsets and extrinsics on a reference's own motion",
    )
    st.set_defaults(func=_selftest)
    st.add_argument(
        "reference", help="the reference trajectory (a text file, or a bag with --config's sources)"
    )
    st.add_argument(
        "--config", help="a config YAML: its load, sources, sync and calibrate settings are used"
    )
    st.add_argument(
        "--rate", type=float, default=20.0, help="pose rate of the simulated estimates (Hz)"
    )
    st.add_argument("--trials", type=int, default=5, help="trials per noise level")
    st.add_argument("--scale", action="store_true", help="simulate and solve a scale (monocular)")
    st.add_argument("--seed", type=int, default=0)


def _add_stage(sub) -> None:
    sg = sub.add_parser(
        "stage", help="run one stage of one grid case from the previous stage's artifacts"
    )
    sg.set_defaults(func=_stage)
    sg.add_argument("name", help="the stage: load, crop, sync, calibrate, align, metrics, ...")
    sg.add_argument("case_dir", help="the case folder, results/cases/<algorithm>/<dataset>/<run>")
    sg.add_argument(
        "--configfile", default="config/config.yaml", help="the grid's config (its settings apply)"
    )


def _add_simulate(sub) -> None:
    s = sub.add_parser("simulate", help="write the deterministic example grid")
    s.set_defaults(func=_simulate)
    s.add_argument("out", help="folder to write truth/, algorithms/ and manifest.json into")
    s.add_argument("--seed", type=int, default=7)


def _eval_config(args):
    """The case's settings (the config's, the options over them, then what the config's overrides
    and metric_scale give this algorithm and dataset) and what they changed (CaseSettings)."""
    from epa.workflow import overrides as cells
    from epa.workflow import settings

    cfg: dict = {"truth_dir": ".", "algorithms_dir": "."}
    algorithm = args.algorithm or EVAL_ALGORITHM
    if args.config:
        cfg.update(settings.load_yaml(args.config))
    overrides: dict[tuple[str, ...], object] = {
        ("mode",): args.mode,
        ("align", "method"): args.align,
        ("align", "first_n"): args.first_n,
        ("sync", "policy"): args.policy,
        ("sync", "max_diff"): args.max_diff,
        ("sync", "offset"): args.offset,
        ("metrics", "segments"): args.segments,
        **{("metrics", name, "enabled"): True for name in args.protocol or ()},
        ("load", "truth_format"): args.ref_format,
        ("load", "estimate_format"): args.est_format,
        ("load", "unsorted"): args.unsorted,
        ("load", "time_unit"): args.time_unit,
        ("sync", "estimate_offset"): False if args.no_offset_estimate else None,
        ("calibrate", "enabled"): False if args.no_calibrate else None,
        ("calibrate", "scale"): True if args.scale else None,
        ("load", "stamp"): args.stamp,
        ("efficiency", "sensor_rate_hz"): args.rate,
        # epa eval stays free of matplotlib unless asked
        ("report", "per_case"): bool(args.report or args.rerun),
        ("report", "rerun"): True if args.rerun else None,
        ("report", "figures"): "all" if args.report else None,  # one case, asked for: every figure
        ("sources", "reference", "topic"): args.ref_topic,
        ("sources", "reference", "frames"): args.ref_frames,
        ("sources", "algorithms", algorithm, "topic"): args.est_topic,
        ("sources", "algorithms", algorithm, "frames"): args.est_frames,
        ("sources", "algorithms", algorithm, "timing"): args.timing
        and str(Path(args.timing).resolve()),
        ("sources", "algorithms", algorithm, "metric_scale"): (
            None if args.metric_scale is None else args.metric_scale == "true"
        ),
    }
    given = (
        (cfg.get("report") or {}).get("per_case") if isinstance(cfg.get("report"), dict) else None
    )
    if given is not None and given != overrides[("report", "per_case")]:
        logging.getLogger("epa").warning(
            "report.per_case: %s in the config is not used by epa eval (--report writes the report)",
            json.dumps(given),
        )
    for keys, value in overrides.items():
        if value is None:
            continue
        node = cfg
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
    source = args.config or "command line"
    resolved = settings.resolve(cfg, source=source)
    case_cfg, own = cells.one_case(resolved, algorithm, args.dataset or "", source=source)
    for where in own.applied:
        logging.getLogger("epa").info("settings of this case: %s", where)
    return case_cfg, own


LARGE_INPUT_MB = 20  # about 200,000 TUM poses, some seconds of work: worth showing progress


def _input_bytes(path) -> int:
    """Bytes of a file, or of a folder's files (a ROS 2 bag); 0 when it is missing (load reports that)."""
    p = Path(path)
    try:
        return (
            sum(f.stat().st_size for f in p.iterdir() if f.is_file())
            if p.is_dir()
            else p.stat().st_size
        )
    except OSError:
        return 0


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and v:
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def _config_listing(path) -> str:
    """One ``key: value`` line per setting, in the schema's order; with a config file, the settings it
    changes are marked with their default."""
    import json

    from epa.workflow import settings

    defaults = _flat(settings.defaults())
    if path is None:
        return "".join(f"{k}: {json.dumps(v)}\n" for k, v in defaults.items())
    effective = _flat(settings.from_configfile(path))
    lines = []
    for k, v in effective.items():
        note = (
            ""
            if k in defaults and defaults[k] == v
            else (f"  # set (default {json.dumps(defaults[k])})" if k in defaults else "  # set")
        )
        lines.append(f"{k}: {json.dumps(v)}{note}\n")
    return "".join(lines)


EVAL_ALGORITHM = "estimate"  # the name `epa eval` gives its one estimate in `sources.algorithms`


def _eval(args) -> None:
    import time

    from epa.artifacts.case import CaseFolder
    from epa.workflow import chain

    runtime.one_case_alone()  # a second core for its stages, freed memory kept for reuse
    cfg, own = _eval_config(args)
    out = CaseFolder(args.out)
    chain.clear_arrays(out)
    document = Path(args.out) / "metrics.json"  # every stage's record in one document
    document.unlink(missing_ok=True)  # a previous run's: never beside this run's stage folders
    write_provenance = _eval_provenance(args, cfg)
    clock: dict[str, Any] = {"stage": None, "t": time.perf_counter()}
    size_mb = sum(_input_bytes(p) for p in (args.ref, args.est)) / 1e6
    progress = args.verbose or size_mb >= LARGE_INPUT_MB
    if progress and not args.verbose:
        print(
            f"epa: {size_mb:.0f} MB of input: each stage is printed as it starts, with its time when done",
            file=sys.stderr,
        )

    def on_stage(name):
        now = time.perf_counter()
        if progress and clock["stage"]:
            print(f"epa: {clock['stage']:<11} {now - clock['t']:7.3f} s", file=sys.stderr)
        if progress and name and not args.verbose:
            print(f"epa: {name} ...", file=sys.stderr, flush=True)
        clock.update(stage=name, t=now)
        if name == REPORT_STAGE:  # the report (--report) lists the inputs from provenance.json
            write_provenance()

    from epa import readers

    try:
        result = chain.run_case(
            args.ref,
            args.est,
            args.out,
            cfg,
            write_arrays=args.artifacts or args.report or args.rerun,
            on_stage=on_stage,
            ref_source=readers.options(cfg, "reference"),
            est_source=readers.options(cfg, "estimate", algorithm=args.algorithm or EVAL_ALGORITHM),
            settings_record=own.record() if own.applied else None,
        )
    finally:  # also for a case that fails: what it was run on
        write_provenance()
    on_stage(None)
    from epa.artifacts import files

    files.write_json(document, out.document())
    record = result["metrics"]
    ate = record["ate"]["trans_m"]["rmse"]
    print(
        f"{record['n_matched']} poses matched, eval_source {record['eval_source']}, "
        f"ATE rmse {ate:.4f} m -> {out.path('metrics', 'metrics.json')}"
    )
    if record.get("rpg"):  # mode rpg: rpg's own statistics files
        r = record["rpg"]
        print(
            f"rpg {r['align_type']}_{r['align_num_frames']}: ATE rmse {r['absolute']['trans']['rmse']:.4f} m,"
            f" {r['absolute']['rot']['rmse']:.4f} deg; relative errors at"
            f" {', '.join(f'{d:g}' for d in r['distances_m'])} m -> {out.path('metrics', 'rpg')}"
        )
    c, e = result["consistency"], result["efficiency"]
    if c.get("available"):
        print(
            f"NEES orientation {c['nees_rot_mean']:.3f}, position {c['nees_pos_mean']:.3f} (3 = consistent),"
            f" {c['outside_3sigma_pct']:.2f} % outside 3 sigma"
        )
    if e.get("available"):
        ea = (
            f"EA-Drift {e['ea_drift']:.4f} % (EPA's formula {e['ea_drift_seed']:.4f} %)"
            if e.get("ea_drift") is not None
            else "EA-Drift empty: " + e.get("ea_drift_reason", "")
        )
        print(
            f"frame time mean {e['frame_time_mean_ms']:.2f} ms (p95 {e['frame_time_p95_ms']:.2f}), {ea}"
        )


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


def _eval_provenance(args, cfg) -> Callable[[], None]:
    """provenance.json and config.resolved.yaml of the case (docs/reproducibility.md): started now
    (the environment read and the inputs hashed in a thread while they are loaded), written when
    the returned function is first called."""
    from epa.outputs import provenance

    algorithm = args.algorithm or EVAL_ALGORITHM
    timing = provenance.run_timing(cfg, args.est, algorithm)
    case = {"reference": args.ref, "estimate": args.est, "algorithm": algorithm}
    if args.dataset:
        case["dataset"] = args.dataset
    finish = provenance.document_started(
        "case",
        cfg,
        provenance.case_inputs(args.ref, args.est, timing),
        workflow_dir=provenance.source_checkout(),  # None for an installed package
        extra={"case": case},
    )
    written: list = []

    def write() -> None:
        if not written:
            written.append(provenance.write(args.out, finish()))

    return write


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


def _selftest(args) -> None:
    from epa.workflow import recovery as selftest
    from epa.workflow import settings
    from epa.workflow.stages import load

    cfg: dict[str, Any] = {"truth_dir": ".", "algorithms_dir": "."}
    if args.config:
        cfg.update(settings.load_yaml(args.config))
    if args.scale:
        cfg.setdefault("calibrate", {})["scale"] = True
    cfg = settings.resolve(cfg, source=args.config or "command line")
    ref, _ = load.load_reference(args.reference, cfg)
    if args.trials < 1 or not (math.isfinite(args.rate) and args.rate > 0):
        raise EpaError("--trials must be at least 1 and --rate a positive number")
    try:
        results = selftest.run(ref, cfg, trials=args.trials, rate=args.rate, seed=args.seed)
    except EpaError as exc:
        raise (exc if exc.path else EpaError(exc.message, path=args.reference)) from None
    print(selftest.report(results, Path(args.reference).name, args.rate), end="")


def _config(args) -> None:
    print(_config_listing(args.config), end="")


def _stage(args) -> None:
    from epa.workflow import one_stage

    elapsed, written = one_stage.run(args.name, args.case_dir, args.configfile)
    print(f"{args.name}: {elapsed:.3f} s, wrote " + ", ".join(map(str, written)))


def _simulate(args) -> None:
    from epa import simulate

    manifest = simulate.simulate(args.out, seed=args.seed)
    print(
        f"wrote {len(manifest['cases'])} estimates and {len(simulate.SEQUENCES)} references to {args.out}"
    )


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = _parser(argv[0] if argv else None).parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="epa: %(levelname)s: %(message)s")
    try:
        status = args.func(args)  # an exit status (epa verify), or None when the command is done
    except EpaError as exc:
        print(f"epa: error: {exc.one_line()}", file=sys.stderr)
        return 2
    return 0 if status is None else status


if __name__ == "__main__":
    sys.exit(main())
