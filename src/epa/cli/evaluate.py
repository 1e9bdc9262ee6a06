"""``epa eval``: one estimate against one reference, every stage in one process, the output folder
laid out as a workflow case folder."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from epa.artifacts.stage import folder
from epa.cli.common import REPORT, REPORT_STAGE
from epa.core import runtime

EVAL_ALGORITHM = "estimate"  # the name `epa eval` gives its one estimate in `sources.algorithms`


def add_parser(sub) -> None:
    e = sub.add_parser("eval", help="evaluate one estimate against one reference")
    e.set_defaults(func=_eval)
    _add_arguments(e, _protocols())


def _add_arguments(e, protocols: tuple[str, ...] | None) -> None:
    """eval's arguments; ``protocols``: the choices of --protocol (None: any, for read_ahead)."""
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
        choices=protocols,
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


class _Silent(argparse.ArgumentParser):
    """A parser that prints nothing and never exits: a mistake raises ValueError."""

    def error(self, message):
        raise ValueError(message)

    def exit(self, status=0, message=None):
        raise ValueError(message)


def read_ahead(argv: list[str]) -> Callable[[], None]:
    """Start reading the two files of ``epa eval ARGV`` (:func:`epa.workflow.stages.load.read_ahead_case`)
    before eval's parser is built, which imports every metric module (its --protocol choices):
    0.1-0.2 s in which the parse of large files, which mostly releases the GIL, is done. The
    arguments are read as eval's parser reads them, its --protocol choices aside; any mistake is
    left to that parser, which says what it is. Returns what ends the reading of files no stage
    took (a parser's error, ``--help``)."""
    from epa.workflow.stages import load

    quiet = _Silent(prog="epa eval", add_help=False)
    _add_arguments(quiet, protocols=None)
    try:
        args, _ = quiet.parse_known_args(argv)
    except ValueError:
        return load.forget_ahead
    runtime.one_case_alone()  # (as _eval: the spare core reads them)
    load.read_ahead_case(args.ref, args.est)
    return load.forget_ahead


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
        logging.getLogger(__name__).warning(
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
        logging.getLogger(__name__).info("settings of this case: %s", where)
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


def _eval(args) -> None:
    from epa.workflow.stages import load

    runtime.one_case_alone()  # a second core for its stages, freed memory kept for reuse
    # the two files are parsed in a thread while the settings are resolved and the stages imported
    load.read_ahead_case(args.ref, args.est)
    try:
        _eval_case(args)
    finally:  # a case stopped before its load stage: the reading ends here
        load.forget_ahead()


def _eval_case(args) -> None:
    import time

    from epa.artifacts.case import CaseFolder
    from epa.workflow import chain

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

    files.write_json(document, out.document(chain.DOCUMENT))
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
