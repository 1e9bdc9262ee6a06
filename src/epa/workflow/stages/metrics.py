"""Metrics: ATE, distance and time RPE, drift rate, evo-style RPE and the registered metrics of
:mod:`epa.metrics.registry` computed here, on the aligned matched poses (06_metrics/). ``metrics.json``
also holds what load and Steps 1-3 found, so one file tells the whole case."""

from __future__ import annotations

import logging
import os

from epa.artifacts.case import Case, CaseData, Columns, Kept, Record, remember
from epa.artifacts.stage import Stage, Value
from epa.core import geometry, runtime
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory, position_only
from epa.metrics import accuracy, registry
from epa.readers import read_printed_quaternions
from epa.readers.image_stamps import read_image_stamps
from epa.workflow.stages.load import c_parser_min_bytes

log = logging.getLogger(__name__)

NAME = "metrics"
BASE_ARRAYS = ("ape.csv", "rpe_segments.csv", "rpe_time.csv")

# reference source -> its quaternions as printed (the ETH3D protocol's), shared by a dataset's cases
_PRINTED: Kept = runtime.register("workflow.stages.metrics.printed", Kept())

# A matched reference shorter than this has no distance metrics (RPE per metre, drift rate,
# distance success rate would all be 0/0).
MIN_PATH_M = 0.01


def _insert(record: dict, key: str, value, after: str | None) -> dict:
    """``record`` with ``key`` placed right after ``after`` (None, or not in ``record``: last),
    keeping its key order. Never drops ``value``."""
    if after is None or after not in record:
        return {**record, key: value}
    out = {}
    for k, v in record.items():
        out[k] = v
        if k == after:
            out[key] = value
    return out


def compute(ref: Trajectory, est: Trajectory, cfg: dict, inputs: dict | None = None):
    """The metrics of the aligned matched poses. ``inputs``: {name: a function giving it} for the
    registered metrics that declare ``inputs`` (mode rpg's: ``unaligned``, ``transform``,
    ``reference``); each is asked for only when such a metric is on."""
    c = cfg["metrics"]
    dist = geometry.path_distances(ref.p)  # once: the check below and every distance metric
    length = float(dist[-1]) if len(dist) else 0.0
    if length < MIN_PATH_M:
        raise EpaError(
            f"the reference does not move ({length:.3g} m over the matched poses): distance RPE,"
            " drift rate and success rate are undefined"
        )
    if isinstance(c["segments"], str):  # auto, kitti: this case's lengths, for every metric here
        # auto: of the whole (cropped) reference's path, as rpg takes its groundtruth's
        whole = (inputs or {}).get("reference")
        whole_length = geometry.path_distances(whole().p)[-1] if whole is not None else length
        c = {**c, "segments": accuracy.segment_lengths(c["segments"], float(whole_length))}
        cfg = {**cfg, "metrics": c}
    which = position_only(ref, est)  # a side without orientation: every rotation error null
    # D = Q P^T and the positions as rows, once: every relative error and ATE 2D's yaw
    rows = None if which else geometry.pair_rows(None, ref.p, est.p, q=(ref.q, est.q))
    inputs = {**(inputs or {}), "pair_rows": lambda: rows}
    evaluated, tables = (accuracy.evaluate_positions if which else accuracy.evaluate)(
        ref,
        est,
        rows=rows,  # None for positions: evaluate_positions' D = I
        segments=c["segments"],
        segment_tol=c["segment_tol"],
        time_delta=c["time_delta"],
        time_tol=c["time_tol"],
        rpe=c["rpe"],
        dist=dist,
    )
    summary: dict = dict(evaluated)  # metrics.json grows from here (records.MetricsRecord)
    inputs["accuracy"] = lambda: summary
    summary["est_length_m"] = est.length()  # the aligned estimate's matched path (EA-Drift's L)
    # an empty segment length is shown as empty, never as a number; say why once, here
    summary["notes"] = [
        f"no {key} m segment fits in the {length:.3f} m matched path: its RPE and drift rate are empty"
        for key, rpe in summary["rpe_distance"].items()
        if rpe["trans_m"]["n"] == 0
    ]
    summary["notes"] += empty_relative_notes(summary, c)
    records: dict[str, dict | None] = {}
    if which:
        summary["position_only"] = True
        summary["notes"].append(accuracy.position_only_note(which))
    for metric in registry.computed_in(NAME):
        if metric.enabled(cfg) and which and metric.orientation:
            records[metric.key] = None  # never a rotation invented from positions
            summary["notes"].append(f"{metric.key}: null: it needs orientations ({which})")
        elif metric.enabled(cfg) and metric.compute is not None:  # (Metric requires it here)
            extra = {k: inputs[k]() for k in metric.inputs}
            records[metric.key], arrays, notes = metric.compute(ref, est, cfg, **extra)
            for name, columns in arrays.items():
                tables.setdefault(name, {}).update(columns)
            summary["notes"] += notes
    # each after the record it follows (where that one is off, after that one's anchor), anchors first
    for metric in registry.placement():
        if metric.key in records:
            at = registry.anchor(metric, summary)
            summary = _insert(summary, metric.key, records[metric.key], after=at)
    for note in summary["notes"]:
        log.warning("%s", note)
    return summary, tables


def empty_relative_notes(summary: dict, c: dict) -> list[str]:
    """Why the 1 s RPE and each evo-style RPE without a pair of poses are empty (their statistics
    are None): one note each, as for a segment length that does not fit."""
    notes = []
    if summary[accuracy.time_rpe_key(c["time_delta"])]["trans_m"]["n"] == 0:
        delta = c["time_delta"]
        notes.append(
            f"no two matched poses are {delta:g} s (±{100 * c['time_tol']:g} %) apart in"
            f" {summary['duration_s']:.3f} s: the {delta:g} s RPE is empty"
        )
    for spec in summary["rpe"]:
        if spec["trans_m"]["n"] == 0:
            notes.append(
                f"rpe {spec['delta']:g} {spec['unit']}: no pair of matched poses is"
                f" {spec['delta']:g} {spec['unit']} apart: its RPE is empty"
            )
    return notes


def case_record(
    load_info: dict, sync_info: dict, calib_info: dict, align_info: dict, summary: dict
) -> dict:
    """metrics.json: the metrics plus what loading and Steps 1-3 did, so one file tells the whole case."""
    ext = calib_info.get("extrinsic") or {}
    applied = bool(calib_info.get("plan", {}).get("apply_extrinsic"))
    offset = calib_info.get("reassociated", sync_info)["offset_s"]
    return {
        "n_matched": summary["n_matched"],
        "eval_source": calib_info.get("eval_source", "epa"),
        "time_offset_s": offset,
        "extrinsic_rot_deg": ext.get("rotation_deg") if applied else None,
        "extrinsic_trans_m": ext.get("translation_norm_m") if applied else None,
        "alignment": align_info,
        **{k: v for k, v in summary.items() if k != "n_matched"},
        # the estimate's path as invoked stays in load.json: metrics.json is the same from `epa eval` and the grid
        "load": {k: v for k, v in load_info.items() if k != "est_path"},
        "sync": sync_info,
        "calibrate": calib_info,
    }


def image_stamps(cfg: dict, case: Case | None):
    """The ETH3D protocol's image stamps: None (the reference's own) or those of the file
    ``metrics.eth3d.image_stamps`` names, ``{dataset}`` replaced by the case's dataset."""
    c = cfg["metrics"]["eth3d"]
    if c["image_stamps"] is None:
        return None
    dataset = case.dataset if case is not None else ""
    if "{dataset}" in c["image_stamps"] and not dataset:  # epa eval: a case of no dataset
        raise EpaError(
            "metrics.eth3d.image_stamps names {dataset} and this case has no dataset (epa eval):"
            " name the file itself"
        )
    path = c["image_stamps"].replace("{dataset}", dataset)
    return read_image_stamps(path, c["image_stamps_unit"])


def printed_quaternions(data: CaseData) -> tuple[Trajectory | None, Trajectory | None]:
    """The case's two files read again with the settings load read them with, their quaternions as
    printed (the ETH3D protocol's); None for a side that prints none (a bag, KITTI, positions)."""
    case = data.folder.case
    if case is None or case.truth is None or case.estimate is None:
        return None, None
    sources = data.load_record.get("sources", {})
    ref_opts = sources.get("reference") or {}
    try:
        st = os.stat(case.truth)
        source = (os.path.abspath(case.truth), st.st_mtime_ns, st.st_size, repr(ref_opts))
    except OSError:  # a vanished file: the reader says what is wrong
        source = None
    fast = c_parser_min_bytes()  # the parser load chose, so the same rows (and the same cost)
    if source is None or source not in _PRINTED:
        reference = read_printed_quaternions(case.truth, ref_opts, c_parser_min_bytes=fast)
        if source is not None:
            remember(_PRINTED, source, reference)
    else:
        reference = _PRINTED[source]
    estimate = read_printed_quaternions(
        case.estimate, sources.get("estimate") or {}, c_parser_min_bytes=fast
    )
    return reference, estimate


# What a registered metric may ask for beyond the aligned matched poses (Metric.inputs), each a
# function of the case's data and settings; compute adds PAIR_ROWS and ACCURACY, made on the way.
PROVIDED = {
    "unaligned": lambda data, cfg: data.calibrated[1],
    "transform": lambda data, cfg: data.transform,
    "reference": lambda data, cfg: data.cropped[0],
    "estimate_source": lambda data, cfg: data.load_record.get("sources", {}).get("estimate") or {},
    "estimate": lambda data, cfg: data.cropped[1],
    "image_stamps": lambda data, cfg: image_stamps(cfg, data.folder.case),
    "printed_quaternions": lambda data, cfg: printed_quaternions(data),
    "calibrate_record": lambda data, cfg: data.calibrate_record,
}
INPUTS = (*PROVIDED, "pair_rows", "accuracy")


def reads_for(cfg: dict) -> tuple[str, ...]:
    """What :func:`run` reads under ``cfg``: the cropped trajectories and the calibrated estimate
    only where a metric that is on asks for them (``reference``, ``estimate``, ``unaligned``) or
    the segment lengths follow the whole reference's path (``auto``, ``kitti``)."""
    asked = {
        name
        for metric in registry.computed_in(NAME)
        if metric.enabled(cfg) and metric.compute is not None
        for name in metric.inputs
    }
    only_if = {
        "cropped": bool({"reference", "estimate"} & asked)
        or isinstance(cfg["metrics"]["segments"], str),
        "calibrated": "unaligned" in asked,
    }
    return tuple(name for name in READS if only_if.get(name, True))


def check_inputs(metrics) -> None:
    """Every metric of this stage asks only for :data:`INPUTS` (else a ValueError naming it)."""
    for metric in metrics:
        if unknown := [i for i in metric.inputs if i not in INPUTS]:
            raise ValueError(f"metric {metric.key!r}: inputs {unknown} are not among {INPUTS}")


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    folder = data.folder
    inputs = {name: (lambda give=give: give(data, cfg)) for name, give in PROVIDED.items()}
    summary, tables = compute(data.matched[0], data.aligned, cfg, inputs)
    record = case_record(
        data.load_record, data.sync_record, data.calibrate_record, data.transform, summary
    )
    data.metrics_record = record
    data.ape, data.rpe_segments, data.rpe_time = (
        tables["ape"],
        tables["rpe_segments"],
        tables["rpe_time"],
    )
    for name in STAGE.arrays:
        table = tables.get(name.removesuffix(".csv"))
        if write_arrays and table is not None:
            folder.write_table(NAME, name, table)
        elif name not in BASE_ARRAYS:  # from a run with that metric on
            folder.remove(NAME, name)
    for metric in registry.computed_in(NAME):
        if metric.documents is not None:  # small files of its own, in 06_metrics/<key>/
            folder.remove_folder(NAME, metric.key)
            if record.get(metric.key) is not None:
                for name, text in metric.documents(record[metric.key]).items():
                    folder.write_text(NAME, f"{metric.key}/{name}", text)
    folder.write_record(NAME, "metrics.json", record)


check_inputs(registry.computed_in(NAME))

READS = (
    "matched",
    "aligned",
    "calibrated",
    "transform",
    "cropped",
    "load_record",
    "sync_record",
    "calibrate_record",
)

STAGE = Stage(
    name=NAME,
    run=run,
    # and the sections its registered metrics read (chain.sections_for)
    settings=("mode", "metrics"),
    records=("metrics.json",),
    arrays=BASE_ARRAYS + tuple(a for m in registry.computed_in(NAME) for a in m.arrays),
    reads=READS,
    reads_for=reads_for,
    values=(
        Value("metrics_record", Record, lambda s: s.f.record(NAME, "metrics.json")),
        Value("ape", Columns, lambda s: s.f.table(NAME, "ape.csv")),
        Value("rpe_segments", Columns, lambda s: s.f.table(NAME, "rpe_segments.csv")),
        Value("rpe_time", Columns, lambda s: s.f.table(NAME, "rpe_time.csv")),
    ),
    result="metrics_record",
)
