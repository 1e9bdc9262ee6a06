"""error_comparison.txt (seed 000 layout), one LaTeX table per .tex file, and summary.csv.

Aggregation rules: an ATE cell is the mean over runs of each run's RMSE; an RPE / drift-rate /
1 s RPE cell is the mean of the errors pooled over runs (and, for the per-algorithm segment
tables, over datasets); a success-rate cell is the mean over runs; the Average column is the mean
over the datasets that have a number; a cell with no successful run prints ``- / -``.
"""

from __future__ import annotations

import csv
import io as _io
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from epa.artifacts import files as io
from epa.core.errors import EpaError
from epa.metrics import statistics
from epa.metrics.accuracy import segment_key
from epa.workflow.chain import CaseFolder, case_dir, read_record

log = logging.getLogger("epa")

RULE_SHORT = "=" * 38
RULE_LONG = "=" * 44
_LATEX_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
}


def latex_escape(text: str) -> str:
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in str(text))


def has_result(status: str) -> bool:
    """Whether a case's status carries numbers (a globally failed case still has them)."""
    return status == "ok" or status.startswith("globally failed")


@dataclass
class CaseResult:
    algorithm: str
    dataset: str
    run: str
    status: str = "ok"
    load: dict = field(default_factory=dict)
    sync: dict = field(default_factory=dict)  # 03_sync/sync.json
    metrics: dict = field(default_factory=dict)
    drift: dict = field(default_factory=dict)
    segments: dict = field(default_factory=dict)
    time: dict = field(default_factory=dict)
    consistency: dict = field(default_factory=dict)  # 08_consistency/consistency.json
    efficiency: dict = field(default_factory=dict)  # 09_efficiency/efficiency.json

    @property
    def ok(self) -> bool:
        return has_result(self.status)


def collect(keys: list[str], results_dir) -> list[CaseResult]:
    """Read every case's artifacts (``<results_dir>/cases/<algorithm>/<dataset>/<run>/``)."""
    out = []
    for key in keys:
        alg, ds, run = key.split("/")
        case = CaseFolder(case_dir(results_dir, key))
        res = CaseResult(alg, ds, run)
        load, load_failed = read_record(case.path("load", "load.json"))
        if load_failed is None:
            res.load = load
        drift, reason = read_record(case.path("drift", "drift.json"))
        if reason is not None:
            res.status = reason if reason.startswith("internal error") else "failed: " + reason
        else:
            res.sync = io.read_json(case.path("sync", "sync.json"))
            res.metrics = io.read_json(case.path("metrics", "metrics.json"))
            res.drift = drift
            res.segments = {
                **io.read_csv(case.path("metrics", "rpe_segments.csv")),
                **io.read_csv(case.path("drift", "rpe_segments_valid.csv")),
            }
            res.time = {
                **io.read_csv(case.path("metrics", "rpe_time.csv")),
                **io.read_csv(case.path("drift", "rpe_time_valid.csv")),
            }
            if res.drift.get("status"):
                res.status = res.drift["status"]
            for stage in ("consistency", "efficiency"):
                path = case.path(stage, stage + ".json")
                if path.exists():
                    record, failed = read_record(path)
                    setattr(
                        res,
                        stage,
                        record if failed is None else {"available": False, "failed": failed},
                    )
        out.append(res)
    return out


def failed_cases(grid: list[CaseResult]) -> list[tuple[str, str]]:
    """(case key, status) of every case without a result, for the end-of-run list."""
    return [(f"{c.algorithm}/{c.dataset}/{c.run}", c.status) for c in grid if not c.ok]


def _num(x) -> float:
    return np.nan if x is None else float(x)


def _nanmean(values) -> float:
    v = np.array([_num(x) for x in values], float)
    v = v[~np.isnan(v)]
    return float(v.mean()) if v.size else np.nan


class _Cell:
    """A table cell: missing (None: no successful run), or numbers that may be nan.
    ``pair`` cells hold rot / trans; the others a single number. ``runs`` (runs x numbers) holds
    each run's own value of those numbers, for the spread over runs."""

    def __init__(self, values=None, pair: bool = True, runs=None):
        self.values, self.pair = values, pair
        self.runs = None if runs is None else np.atleast_2d(np.asarray(runs, float))

    def fmt(self, decimals: int, spread: str = "none") -> str:
        if self.values is None:
            return "- / -" if self.pair else "-"
        parts = []
        for k, v in enumerate(self.values):
            text = "nan" if np.isnan(v) else f"{v:.{decimals}f}"
            if spread != "none" and self.runs is not None and not np.isnan(v):
                pm = statistics.spread(self.runs[:, k], spread)
                text += "" if np.isnan(pm) else f" $\\pm$ {pm:.{decimals}f}"
            parts.append(text)
        n = f" (n={len(self.runs)})" if spread != "none" and self.runs is not None else ""
        return " / ".join(parts) + n


def _average(cells: list[_Cell], pair=True) -> _Cell:
    have = [c.values for c in cells if c.values is not None]
    if not have:
        return _Cell(None, pair)
    arr = np.array(have, float)
    return _Cell(tuple(_nanmean(arr[:, k]) for k in range(arr.shape[1])), pair)


# ----------------------------------------------------------------------------- per-cell values
def _ok_runs(grid, alg, ds=None):
    return [c for c in grid if c.algorithm == alg and (ds is None or c.dataset == ds) and c.ok]


def _run_ate(c, valid: bool = False) -> tuple[float, float]:
    """One run's ATE RMSE: rotation (deg), translation (m)."""
    src = c.drift["drift_valid"]["ate"] if valid else c.metrics["ate"]
    return src["rot_deg"]["rmse"], src["trans_m"]["rmse"]


def _run_ate_2d(c) -> tuple[float, float]:
    """One run's ATE 2D RMSE (ov_eval's): yaw (deg), planar position (m)."""
    return _stat(c.metrics, "ate_2d", "yaw_deg", "rmse"), _stat(
        c.metrics, "ate_2d", "trans_xy_m", "rmse"
    )


def _mean_over_runs(runs, of) -> _Cell:
    """The cell of a per-run pair: its mean over the runs (ov_eval's ATE cells)."""
    if not runs:
        return _Cell(None)
    per_run = [tuple(_num(x) for x in of(c)) for c in runs]
    return _Cell(tuple(_nanmean(v) for v in zip(*per_run)), runs=per_run)


def _ate(runs, valid: bool) -> _Cell:
    return _mean_over_runs(runs, lambda c: _run_ate(c, valid))


def _ate_2d(runs) -> _Cell:
    return _mean_over_runs(runs, _run_ate_2d)


def _per_run(runs, table: str, valid: bool, length=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each run's (rot, trans) errors of the pairs a pooled cell takes from it."""
    out = []
    for c in runs:
        t = getattr(c, table)
        sel = np.ones(len(t.get("rot_deg", [])), bool)
        if length is not None:
            sel &= t["length_m"] == float(length)
        if valid:
            sel &= t["valid"] > 0
        out.append((t["rot_deg"][sel], t["trans_m"][sel]))
    return out


def _pooled(runs, table: str, valid: bool, length=None):
    per_run = _per_run(runs, table, valid, length)
    return tuple(
        np.concatenate([r[k] for r in per_run]) if per_run else np.zeros(0) for k in (0, 1)
    )


def _pooled_cell(runs, table, valid, length, of, width: int) -> _Cell:
    """A cell pooling the pairs of all runs, ``of(rot, trans)`` giving its ``width`` numbers; its
    spread is over each run's own ``of`` (runs without pairs left out)."""
    per_run = _per_run(runs, table, valid, length)
    rot, trans = (np.concatenate([r[k] for r in per_run]) for k in (0, 1))
    if _all_nan_valid(runs, valid) or rot.size == 0:
        return _Cell((np.nan,) * width)
    return _Cell(of(rot, trans), runs=[of(r, t) for r, t in per_run if r.size])


def _mean_pair(runs, table, valid, length=None) -> _Cell:
    if not runs:
        return _Cell(None)
    return _pooled_cell(
        runs, table, valid, length, lambda rot, trans: (float(rot.mean()), float(trans.mean())), 2
    )


def _drift_rate(runs, valid, length) -> _Cell:
    if not runs:
        return _Cell(None, pair=False)
    cell = _pooled_cell(
        runs,
        "segments",
        valid,
        length,
        lambda _, trans: (float(np.mean(trans / float(length)) * 100),),
        1,
    )
    cell.pair = False
    return cell


def _all_nan_valid(runs, valid):
    return valid and all(
        c.drift["global_failed"] or not (_num(c.drift["success_rate_distance_pct"]) > 0)
        for c in runs
    )


def _nees(runs) -> _Cell:
    return _mean_over_runs(
        [c for c in runs if c.consistency.get("available")],
        lambda c: (c.consistency["nees_rot_mean"], c.consistency["nees_pos_mean"]),
    )


def _single_over_runs(runs, of) -> _Cell:
    """The cell of a per-run number: its mean over the runs."""
    cell = _mean_over_runs(runs, lambda c: (of(c),))
    cell.pair = False
    return cell


def _ea_drift(runs) -> _Cell:
    return _single_over_runs(
        [c for c in runs if c.efficiency.get("available")], lambda c: c.efficiency["ea_drift"]
    )


def _runtime(grid, alg) -> list[_Cell]:
    """Frame times pooled over every run of an algorithm (each run's statistics, frame-weighted)."""
    eff = [c.efficiency for c in grid if c.algorithm == alg and c.efficiency.get("available")]
    frames = np.array([e["frames"] for e in eff], float)
    w = frames / frames.sum()
    return [
        _Cell((float(np.sum(w * [e["frame_time_mean_ms"] for e in eff])),), pair=False),
        _Cell((float(np.sum(w * [e["frame_time_p95_ms"] for e in eff])),), pair=False),
        _Cell((float(max(e["frame_time_max_ms"] for e in eff)),), pair=False),
        _Cell((float(np.sum(w * [e["frames_over_period_pct"] for e in eff])),), pair=False),
    ]


def _kitti(runs) -> _Cell:
    """KITTI devkit metric, mean over runs: (rotation deg/100 m, translation %)."""
    return _mean_over_runs(
        [c for c in runs if (c.metrics.get("kitti") or {}).get("n_segments")],
        lambda c: (c.metrics["kitti"]["rot_deg_per_100m"], c.metrics["kitti"]["trans_pct"]),
    )


def _success(runs) -> _Cell:
    return _single_over_runs(runs, lambda c: c.drift["success_rate_distance_pct"])


def _success_auc(runs) -> _Cell:
    return _single_over_runs(runs, lambda c: c.drift.get("success_auc_pct"))


# ----------------------------------------------------------------------------- rendering
def _latex_rows(
    header: list[str], rows: list[tuple[str, list[_Cell]]], decimals: int, spread: str = "none"
) -> list[str]:
    lines = [
        " & " + " & ".join(r"\textbf{" + latex_escape(h) + "}" for h in header) + r" \\ \hline"
    ]
    for name, cells in rows:
        lines.append(
            latex_escape(name) + " & " + " & ".join(c.fmt(decimals, spread) for c in cells) + r" \\"
        )
    return lines


SPREAD_TITLE = {
    "none": "",
    "std": " [± SAMPLE STD OVER RUNS, n = RUNS]",
    "ci": " [± HALF-WIDTH OF THE 95% CI OF THE MEAN OVER RUNS, STUDENT T, n = RUNS]",
}


def build_tables(
    grid: list[CaseResult], segments, decimals: int = 3, kitti: bool = False, spread: str = "none"
) -> list[tuple[str, str, list[str], int]]:
    """(file name, title, latex row lines, number of columns) for every table, in report order.
    With ``spread`` (std / ci) each cell with runs also shows its spread over them and their number."""
    algs = sorted({c.algorithm for c in grid})
    datasets = sorted({c.dataset for c in grid})
    seg_labels = [f"{segment_key(s)}m" for s in segments]
    out = []

    def per_dataset(name, title, fn, pair=True, dec=decimals):
        rows = []
        for a in algs:
            cells = [fn(_ok_runs(grid, a, d)) for d in datasets]
            rows.append((a, cells + [_average(cells, pair)]))
        out.append(
            (
                name,
                title + SPREAD_TITLE[spread],
                _latex_rows(datasets + ["Average"], rows, dec, spread),
                len(datasets) + 2,
            )
        )

    def per_segment(name, title, fn):
        # these pool an algorithm's datasets: the spread is over every run of every dataset
        rows = [(a, [fn(_ok_runs(grid, a), s) for s in segments]) for a in algs]
        out.append(
            (
                name,
                title + SPREAD_TITLE[spread].replace("RUNS]", "RUNS OF ALL DATASETS]"),
                _latex_rows(seg_labels, rows, decimals, spread),
                len(segments) + 1,
            )
        )

    def has(alg, stage):
        return any(c.algorithm == alg and getattr(c, stage).get("available") for c in grid)

    def marked(rows_of, stage, missing, pair):
        """Rows for algorithms with the data; the others named, their cells empty, never faked."""
        rows = []
        for a in algs:
            cells = [
                rows_of(_ok_runs(grid, a, d)) if has(a, stage) else _Cell(None, pair)
                for d in datasets
            ]
            rows.append(
                (a if has(a, stage) else f"{a} ({missing})", cells + [_average(cells, pair)])
            )
        return rows

    extra = [
        (
            "nees",
            "NEES LATEX TABLE (ORI / POS, 3 = CONSISTENT)",
            marked(_nees, "consistency", "no covariance", True),
            datasets + ["Average"],
        ),
        (
            "ea_drift",
            "EA-DRIFT LATEX TABLE (% PER-FRAME NORMALISED, SEE DOCS)",
            marked(_ea_drift, "efficiency", "no timing", False),
            datasets + ["Average"],
        ),
    ]
    runtime_rows = [(a, _runtime(grid, a)) for a in algs if has(a, "efficiency")]
    extra.append(
        (
            "runtime",
            "RUNTIME LATEX TABLE (FRAME TIME MS: MEAN, P95, MAX; % FRAMES OVER SENSOR PERIOD)",
            runtime_rows,
            ["mean", "p95", "max", "over period %"],
        )
    )

    for prefix, valid, tag in (
        ("", False, "FULL TRAJECTORY"),
        ("valid_", True, "DRIFT-VALID ONLY"),
    ):
        if valid:
            per_dataset(
                "success_rate",
                "DRIFT-VALID SUCCESS RATE LATEX TABLE (% PATH LENGTH)",
                _success,
                pair=False,
                dec=2,
            )
            per_dataset(
                "success_auc",
                "SUCCESS RATE AREA LATEX TABLE (% PATH, MEAN OVER DRIFT THRESHOLDS x0.1-x10)",
                _success_auc,
                pair=False,
                dec=2,
            )
        per_dataset(
            prefix + "ate",
            f"{tag} ATE LATEX TABLE (ROT DEG / TRANS M)",
            lambda r, valid=valid: _ate(r, valid),
        )
        if not valid:
            per_dataset("ate_2d", "FULL TRAJECTORY ATE 2D LATEX TABLE (YAW DEG / XY M)", _ate_2d)
        per_segment(
            prefix + "rpe_distance",
            f"{tag} DISTANCE RPE LATEX TABLE (ROT DEG / TRANS M)",
            lambda r, s, valid=valid: _mean_pair(r, "segments", valid, s),
        )
        per_segment(
            prefix + "drift_rate",
            f"{tag} DISTANCE DRIFT RATE LATEX TABLE (% TRANS / DIST)",
            lambda r, s, valid=valid: _drift_rate(r, valid, s),
        )
        per_dataset(
            prefix + "rpe_time_1s",
            f"{tag} 1S TIME RPE LATEX TABLE (ROT DEG / TRANS M)",
            lambda r, valid=valid: _mean_pair(r, "time", valid),
        )
    for name, title, rows, header in extra:
        out.append(
            (
                name,
                title + (SPREAD_TITLE[spread] if name != "runtime" else ""),
                _latex_rows(header, rows, decimals, spread),
                len(header) + 1,
            )
        )
    if kitti:
        per_dataset(
            "kitti",
            "KITTI ODOMETRY LATEX TABLE (ROT DEG/100M / TRANS %, 100-800 M SEGMENTS)",
            _kitti,
        )
    return out


def _stat(d: dict, *keys):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return np.nan
        d = d[k]
    return _num(d)


def report_text(grid: list[CaseResult], segments, decimals: int = 3, spread: str = "none") -> str:
    lines = []
    datasets = sorted({c.dataset for c in grid})
    for ds in datasets:
        info = next((c.load for c in grid if c.dataset == ds and c.load), None)
        if info:
            lines.append(
                f"[COMP]: {info['n_ref']} poses in {info['ref_file']} => length of {info['ref_length_m']:.2f} meters"
            )
        else:
            lines.append(f"[COMP]: reference of {ds} could not be loaded")
    lines.append(RULE_SHORT)
    sources = {"epa": 0, "ov_eval": 0}
    for alg in sorted({c.algorithm for c in grid}):
        lines.append(f"[COMP]: processing {alg} algorithm")
        for ds in datasets:
            cases = [c for c in grid if c.algorithm == alg and c.dataset == ds]
            if not cases:
                continue
            runs = [c for c in cases if c.ok]
            lines.append(f"[COMP]: processing {alg} algorithm => {ds} dataset")
            ate = _ate(runs, False)
            if ate.values is None:
                lines.append("        ATE: - / - (0 runs)")
            else:
                lines.append(
                    f"        ATE: mean_ori = {ate.values[0]:.3f} | mean_pos = {ate.values[1]:.3f} ({len(runs)} runs)"
                )
            src = {"epa": 0, "ov_eval": 0}
            for c in runs:
                src[c.metrics.get("eval_source", "epa")] += 1
            for k in sources:
                sources[k] += src[k]
            lines.append(f"        eval_source: epa={src['epa']}, ov_eval={src['ov_eval']}")
            if runs:
                for s in segments:
                    rot, trans = _pooled(runs, "segments", False, s)
                    if rot.size:
                        lines.append(
                            f"        RPE: seg {segment_key(s)} - median_ori = {np.median(rot):.4f} | "
                            f"median_pos = {np.median(trans):.4f} ({rot.size} samples)"
                        )
                    else:
                        lines.append(
                            f"        RPE: seg {segment_key(s)} - no segment this long (0 samples)"
                        )
                rot, trans = _pooled(runs, "time", False)
                if rot.size:
                    lines.append(
                        f"        RPE time 1s - mean_ori = {rot.mean():.3f} | mean_pos = {trans.mean():.3f}"
                        f" ({rot.size} samples)"
                    )
                sr_d = _nanmean(c.drift["success_rate_distance_pct"] for c in runs)
                sr_t = _nanmean(c.drift["success_rate_time_pct"] for c in runs)
                lines.append(f"        SR - distance = {sr_d:.2f}% | time = {sr_t:.2f}%")
            for c in cases:
                if c.status != "ok":
                    lines.append(f"        {c.run}: {c.status}")
    lines += [
        RULE_LONG,
        f"TOOL SOURCE: epa={sources['epa']}, ov_eval={sources['ov_eval']}",
        RULE_LONG,
    ]
    for _, title, rows, _ in build_tables(grid, segments, decimals, spread=spread):
        lines += [
            RULE_LONG,
            title,
            RULE_LONG,
            *(r.replace(" $\\pm$ ", " ± ") for r in rows),
            RULE_LONG,
        ]
    return "\n".join(lines) + "\n"


def _c(x: float, fmt: str) -> str:
    """A number as C's printf prints it (glibc prints the NaN of 0/0 as -nan)."""
    return "-nan" if np.isnan(x) else fmt % x


# ov_core's colors.h: ov_eval colours its warnings and errors, also when its output goes to a file
YELLOW, RED, RESET = "\033[33m", "\033[31m", "\033[0m"


def _ov_eval_warnings(c: CaseResult) -> str:
    """What ov_eval's ResultTrajectory prints for one run at its INFO level: the length-ratio warning
    (its constructor, on the matched poses before alignment; without RESET, as written) and the
    coarse-reference warning (calculate_rpe: summed reference steps / matched poses above 0.5 m)."""
    out = ""
    lengths, n = c.sync.get("matched_length_m"), c.sync.get("n_matched")
    if not lengths or not n:
        return out
    ratio = lengths["est"] / lengths["ref"] if lengths["ref"] else np.nan
    if ratio > 1.1 or ratio < 0.9:
        out += (
            f"{YELLOW}[TRAJ]: Trajectory is a bad ratio of {ratio:.2f} length (est {lengths['est']:.2f}, "
            f"gt {lengths['ref']:.2f})\n{YELLOW}[TRAJ]: {c.load.get('est_path', c.load.get('est_file'))}\n"
        )
    step = lengths["ref"] / n
    if step > 0.5:
        out += (
            f"{YELLOW}[COMP]: average groundtruth position difference {step:.2f} > 0.50 is too large\n{RESET}"
            f"{YELLOW}[COMP]: this will prevent the RPE from finding valid trajectory segments!!!\n{RESET}"
            f"{YELLOW}[COMP]: the recommendation is to use a higher frequency groundtruth, or relax this "
            f"trajectory segment logic...\n{RESET}"
        )
    return out


def ov_eval_text(grid: list[CaseResult], segments, idle_truths: dict | None = None) -> str:
    """error_comparison.txt in mode ov_eval: what ov_eval's error_comparison (v2.7 and later) prints to
    its standard output, byte for byte, so a diff shows only the numbers. error_comparison fixes its
    print level at INFO, so its DEBUG lines (per-dataset means, the per-segment medians) never show;
    its warnings and errors keep their colour codes. Deviations: a cell without a successful run reads
    `- / -`, where ov_eval would stop (a run it cannot read) or print 0.000 (no RPE segment).
    ``idle_truths``: {dataset: load-like info} of the references no algorithm has a run for, which
    ov_eval lists too (a [COMP] line, an error per algorithm, a `- / -` column)."""
    idle_truths = idle_truths or {}
    datasets = sorted({c.dataset for c in grid} | set(idle_truths))
    algs = sorted({c.algorithm for c in grid})
    out = "Setting printing level to: INFO\n"
    for ds in datasets:
        info = next((c.load for c in grid if c.dataset == ds and c.load), idle_truths.get(ds))
        if info:
            out += (
                f"[COMP]: {info['n_ref']} poses in {info['ref_file']}"
                f" => length of {info['ref_length_m']:.2f} meters\n"
            )
    cells: dict[str, dict] = {"ate": {}, "ate_2d": {}}
    for alg in algs:
        for ds in datasets:
            runs = _ok_runs(grid, alg, ds)
            if not runs:
                out += f"{RED}[COMP]: {alg} dataset does not have any runs for {ds}!!!!!\n{RESET}"
                continue
            for c in runs:
                out += _ov_eval_warnings(c)
            for name, of in (("ate", _run_ate), ("ate_2d", _run_ate_2d)):
                ori, pos = zip(*(of(c) for c in runs))
                cells[name][(alg, ds)] = (float(np.mean(ori)), float(np.mean(pos)))
    lines = []
    header = (
        "".join(f" & \\textbf{{{latex_escape(ds)}}}" for ds in datasets)
        + " & \\textbf{Average} \\\\\\hline"
    )
    for name, title in (("ate", "ATE LATEX TABLE"), ("ate_2d", "ATE 2D LATEX TABLE")):
        lines += [RULE_LONG, title, RULE_LONG, header]
        for alg in algs:
            row, have = (
                latex_escape(alg),
                [cells[name][(alg, ds)] for ds in datasets if (alg, ds) in cells[name]],
            )
            for ds in datasets:
                v = cells[name].get((alg, ds))
                row += " & - / -" if v is None else f" & {v[0]:.3f} / {v[1]:.3f}"
            # no dataset at all: ov_eval divides 0 by 0 and glibc prints -nan
            mean = (
                (np.mean([v[0] for v in have]), np.mean([v[1] for v in have]))
                if have
                else (np.nan, np.nan)
            )
            lines.append(row + f" & {_c(mean[0], '%.3f')} / {_c(mean[1], '%.3f')} \\\\")
        lines.append(RULE_LONG)
    lines += [
        RULE_LONG,
        "RPE LATEX TABLE",
        RULE_LONG,
        "".join(f" & \\textbf{{{int(seg)}m}}" for seg in segments) + " \\\\\\hline",
    ]
    for alg in algs:
        row, runs = latex_escape(alg), _ok_runs(grid, alg)
        for seg in segments:
            rot, trans = _pooled(runs, "segments", False, seg)
            row += f" & {rot.mean():.3f} / {trans.mean():.3f}" if rot.size else " & - / -"
        lines.append(row + " \\\\")
    lines.append(RULE_LONG)
    return out + "\n".join(lines) + "\n"


SUCCESS_CURVE_COLUMNS = [
    "algorithm",
    "dataset",
    "runs",
    "factor",
    "success_rate_distance_pct",
    "auc_pct",
]


def success_curves(grid: list[CaseResult]) -> list[dict]:
    """results/success_curves.csv rows: per algorithm and dataset, the distance success rate (% path,
    mean over the successful runs) with every drift threshold multiplied by each factor, and the area."""
    from epa.metrics.drift import CURVE_FACTORS

    rows = []
    for alg in sorted({c.algorithm for c in grid}):
        for ds in sorted({c.dataset for c in grid}):
            curves = [
                c.drift["success_curve"]["success_rate_distance_pct"]
                for c in _ok_runs(grid, alg, ds)
                if c.drift.get("success_curve")
            ]
            if curves:
                mean = np.nanmean(np.array(curves, float), axis=0)
                rows += [
                    {
                        "algorithm": alg,
                        "dataset": ds,
                        "runs": len(curves),
                        "factor": float(f),
                        "success_rate_distance_pct": float(v),
                        "auc_pct": float(np.mean(mean)),
                    }
                    for f, v in zip(CURVE_FACTORS, mean)
                ]
    return rows


# ----------------------------------------------------------------------------- algorithm comparison
def _run_rpe(c, segments) -> float:
    """One run's distance RPE: the mean over the segment lengths of its mean translation error (m)."""
    return _nanmean(
        _stat(c.metrics, "rpe_distance", segment_key(s), "trans_m", "mean") for s in segments
    )


def comparisons(grid: list[CaseResult], segments) -> list[tuple[str, str, dict]]:
    """Every pair of algorithms compared on the ATE (translation RMSE per run) of the datasets both
    have successful runs on (see :func:`epa.metrics.statistics.compare`)."""
    algs = sorted({c.algorithm for c in grid})

    def by_dataset(alg, of):
        out = {}
        for c in _ok_runs(grid, alg):
            v = _num(of(c))
            if np.isfinite(v):
                out.setdefault(c.dataset, []).append(v)
        return out

    ate = {a: by_dataset(a, lambda c: _run_ate(c)[1]) for a in algs}
    rpe = {a: by_dataset(a, lambda c: _run_rpe(c, segments)) for a in algs}
    return [
        (a, b, statistics.compare(ate[a], ate[b], rpe[a], rpe[b]))
        for i, a in enumerate(algs)
        for b in algs[i + 1 :]
    ]


def _verdict(a: str, b: str, r: dict, short: bool = False) -> str:
    name = {"a": a, "b": b}
    if r["better_over_datasets"]:
        return f"{name[r['better_over_datasets']]} better over datasets"
    if r["better_on_dataset"]:
        return "differ on " + ", ".join(
            f"{d} ({name[w]} better)" for d, w in r["better_on_dataset"].items()
        )
    return (
        "cannot tell apart"
        if short
        else f"the data cannot tell {a} and {b} apart (no test below p = {statistics.ALPHA})"
    )


def comparison_text(pairs: list[tuple[str, str, dict]]) -> str:
    """results/comparison.txt: for each pair of algorithms, the wins, the tests and the verdict."""
    need = statistics.min_datasets_for()
    lines = [
        "ALGORITHM COMPARISON (ATE: translation RMSE per run; RPE: mean over the segment lengths of the",
        f"mean translation error; lower is better; two-sided tests at {statistics.ALPHA}, no correction",
        "for the number of pairs; a dataset counts when both algorithms have a successful run on it)",
        RULE_LONG,
    ]
    for a, b, r in pairs:
        n = len(r["datasets"])
        lines.append(f"{a} vs {b}: {n} shared dataset{'s' if n != 1 else ''}")
        if not n:
            lines += ["  nothing to compare", RULE_LONG]
            continue
        lines.append(
            f"  ATE better on: {a} {r['wins_a']}, {b} {r['wins_b']}"
            + (f", tied {r['ties']}" if r["ties"] else "")
        )
        lines.append(
            f"  median ratio {a} / {b}: ATE {r['median_ratio_ate']:.3f}, RPE {r['median_ratio_rpe']:.3f}"
        )
        p = f"p = {r['p_datasets']:.3f}"
        lines.append(
            f"  over datasets (Wilcoxon signed-rank, exact, paired by dataset): {p}"
            + (
                ""
                if r["datasets_testable"]
                else f" (only {n} datasets: at least {need} are needed to reach"
                f" p < {statistics.ALPHA})"
            )
        )
        for d, e in r["per_dataset"].items():
            test = (
                f"Mann-Whitney p = {e['p_runs']:.3f}"
                if "p_runs" in e
                else "no test (fewer than 2 runs each)"
            )
            lines.append(
                f"  {d}: ATE {e['mean_a']:.4f} vs {e['mean_b']:.4f} m over {e['runs_a']} / {e['runs_b']} runs,"
                f" {test}"
            )
        lines += [f"  verdict: {_verdict(a, b, r)}", RULE_LONG]
    return "\n".join(lines) + "\n"


def comparison_tex(pairs: list[tuple[str, str, dict]]) -> str:
    """results/comparison.tex: one row per pair of algorithms."""
    header = [
        "pair",
        "datasets",
        "ATE wins",
        "median ATE ratio",
        "median RPE ratio",
        "p (datasets)",
        "verdict",
    ]
    rows = [" & ".join(r"\textbf{" + h + "}" for h in header) + r" \\ \hline"]
    for a, b, r in pairs:
        if not r["datasets"]:
            continue
        rows.append(
            " & ".join(
                [
                    f"{latex_escape(a)} vs {latex_escape(b)}",
                    str(len(r["datasets"])),
                    f"{r['wins_a']}--{r['wins_b']}",
                    f"{r['median_ratio_ate']:.3f}",
                    f"{r['median_ratio_rpe']:.3f}",
                    f"{r['p_datasets']:.3f}",
                    latex_escape(_verdict(a, b, r, short=True)),
                ]
            )
            + r" \\"
        )
    return tex_document("ALGORITHM COMPARISON (see comparison.txt)", rows, len(header))


def tex_document(title: str, rows: list[str], ncols: int) -> str:
    """A table that \\input's into a paper: a tabular with the report's rows, titled in a comment."""
    spec = "l" + "c" * (ncols - 1)
    return "\n".join([f"% {title}", r"\begin{tabular}{" + spec + "}", *rows, r"\end{tabular}", ""])


SUMMARY_FIXED = [
    "algorithm",
    "dataset",
    "run",
    "status",
    "eval_source",
    "n_matched",
    "ate_trans_rmse_m",
    "ate_rot_rmse_deg",
    "time_rpe_1s_trans_mean_m",
    "time_rpe_1s_rot_mean_deg",
    "time_offset_s",
    "time_offset_std_s",
    "step1_status",
    "extrinsic_rot_deg",
    "extrinsic_trans_m",
    "extrinsic_rot_std_deg",
    "extrinsic_trans_std_m",
    "step2_status",
    "success_rate_distance_pct",
    "success_auc_pct",
    "success_rate_time_pct",
    "global_failed",
    "knee_threshold_m",
    "fail_segments",
    "diverged_at_s",
    "nees_rot_mean",
    "nees_pos_mean",
    "outside_3sigma_pct",
    "ea_drift",
    "frame_time_mean_ms",
    "kitti_trans_pct",
    "kitti_rot_deg_per_100m",
    "notes",
]


def _largest(values):
    """The largest per-axis deviation; None when an axis has none (unobservable) or none exist."""
    return None if not values or any(v is None for v in values) else max(values)


def _confidence(m: dict) -> dict:
    """summary.csv's Step 1 / Step 2 confidence columns from a case's metrics.json."""
    step1, calib = m.get("sync", {}).get("step1", {}), m.get("calibrate", {})
    ext = calib.get("extrinsic") or {}
    return {
        "time_offset_std_s": step1.get("std"),
        "step1_status": step1.get("status"),
        "extrinsic_rot_std_deg": _largest(ext.get("rotation_std_deg")),
        "extrinsic_trans_std_m": _largest(ext.get("translation_std_m")),
        "step2_status": calib.get("step2_status"),
    }


def summary_rows(grid: list[CaseResult], segments) -> tuple[list[str], list[dict]]:
    seg_cols = []
    for s in segments:
        L = segment_key(s)
        seg_cols += [f"rpe_{L}m_trans_mean_m", f"rpe_{L}m_rot_mean_deg", f"drift_rate_{L}m_pct"]
    rows = []
    for c in grid:
        m, d = c.metrics, c.drift
        row = {"algorithm": c.algorithm, "dataset": c.dataset, "run": c.run, "status": c.status}
        if c.ok:
            row.update(
                eval_source=m.get("eval_source"),
                n_matched=m.get("n_matched"),
                ate_trans_rmse_m=_stat(m, "ate", "trans_m", "rmse"),
                ate_rot_rmse_deg=_stat(m, "ate", "rot_deg", "rmse"),
                time_rpe_1s_trans_mean_m=_stat(m, "rpe_time_1s", "trans_m", "mean"),
                time_rpe_1s_rot_mean_deg=_stat(m, "rpe_time_1s", "rot_deg", "mean"),
                time_offset_s=m.get("time_offset_s"),
                extrinsic_rot_deg=m.get("extrinsic_rot_deg"),
                extrinsic_trans_m=m.get("extrinsic_trans_m"),
                **_confidence(m),
                success_rate_distance_pct=_num(d.get("success_rate_distance_pct")),
                success_rate_time_pct=_num(d.get("success_rate_time_pct")),
                global_failed=d.get("global_failed"),
                knee_threshold_m=_stat(d, "knee", "threshold_m"),
                fail_segments=d.get("n_fail_segments"),
                diverged_at_s=d.get("diverged_at_s"),
            )
            if c.consistency.get("available"):  # empty without covariance
                row.update(
                    {
                        k: c.consistency[k]
                        for k in ("nees_rot_mean", "nees_pos_mean", "outside_3sigma_pct")
                    }
                )
            if c.efficiency.get("available"):  # empty without timing
                row.update(
                    ea_drift=c.efficiency["ea_drift"],
                    frame_time_mean_ms=c.efficiency["frame_time_mean_ms"],
                )
            kitti = m.get("kitti") or {}  # empty unless metrics.kitti is on
            row.update(
                kitti_trans_pct=kitti.get("trans_pct"),
                kitti_rot_deg_per_100m=kitti.get("rot_deg_per_100m"),
            )
            # a stage after drift that failed (a broken timing file) leaves the accuracy standing
            row["notes"] = (
                "; ".join(
                    getattr(c, s)["failed"]
                    for s in ("consistency", "efficiency")
                    if getattr(c, s).get("failed")
                )
                or None
            )
            for s in segments:
                L = segment_key(s)
                row[f"rpe_{L}m_trans_mean_m"] = _stat(m, "rpe_distance", L, "trans_m", "mean")
                row[f"rpe_{L}m_rot_mean_deg"] = _stat(m, "rpe_distance", L, "rot_deg", "mean")
                row[f"drift_rate_{L}m_pct"] = _stat(m, "drift_rate_pct", L)
        rows.append(row)
    return SUMMARY_FIXED + seg_cols, rows


def records_csv(cols: list[str], rows: list[dict]) -> str:
    """CSV of dict rows: missing values empty, floats to 9 significant digits."""
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n", restval="")
    w.writeheader()
    for r in rows:
        w.writerow(
            {
                k: (
                    "" if r.get(k) is None else (f"{r[k]:.9g}" if isinstance(r[k], float) else r[k])
                )
                for k in cols
            }
        )
    return buf.getvalue()


def summary_csv(grid, segments) -> str:
    return records_csv(*summary_rows(grid, segments))


TABLE_NAMES = (
    "ate",
    "ate_2d",
    "rpe_distance",
    "drift_rate",
    "rpe_time_1s",
    "success_rate",
    "success_auc",
    "valid_ate",
    "valid_rpe_distance",
    "valid_drift_rate",
    "valid_rpe_time_1s",
    "nees",
    "ea_drift",
    "runtime",
)


def table_names(cfg: dict) -> tuple[str, ...]:
    """The .tex files the tables rule writes under these settings."""
    return TABLE_NAMES + (("kitti",) if cfg["metrics"]["kitti"] else ())


def write_all(
    grid: list[CaseResult], results_dir, cfg: dict, idle_truths: dict | None = None
) -> None:
    """error_comparison.txt, summary.csv and tables/<name>.tex under ``results_dir``."""
    results_dir = Path(results_dir)
    segments = cfg["metrics"]["segments"]
    decimals = cfg["tables"]["decimals"]
    spread = cfg["tables"]["spread"]
    text = (
        ov_eval_text(grid, segments, idle_truths)
        if cfg.get("mode") == "ov_eval"
        else report_text(grid, segments, decimals, spread)
    )
    io.write_text(results_dir / "error_comparison.txt", text)
    io.write_text(results_dir / "summary.csv", summary_csv(grid, segments))
    for name, title, rows, n in build_tables(
        grid, segments, decimals, kitti=cfg["metrics"]["kitti"], spread=spread
    ):
        io.write_text(results_dir / "tables" / f"{name}.tex", tex_document(title, rows, n))
    io.write_text(
        results_dir / "success_curves.csv", records_csv(SUCCESS_CURVE_COLUMNS, success_curves(grid))
    )
    pairs = comparisons(grid, segments)
    io.write_text(results_dir / "comparison.txt", comparison_text(pairs))
    io.write_text(results_dir / "comparison.tex", comparison_tex(pairs))
    write_across_runs(grid, results_dir)


def write_across_runs(grid: list[CaseResult], results_dir) -> None:
    """results/consistency/<algorithm>/<dataset>.csv: RMSE(t) and (with covariance) NEES(t) over the
    reference stamps all runs share; results/consistency/summary.csv: their averages over time."""
    from epa.metrics import consistency

    results_dir = Path(results_dir)
    rows = []
    for alg in sorted({c.algorithm for c in grid}):
        for ds in sorted({c.dataset for c in grid if c.algorithm == alg}):
            runs = {}
            for c in _ok_runs(grid, alg, ds):
                case = CaseFolder(case_dir(results_dir, f"{c.algorithm}/{c.dataset}/{c.run}"))
                ape = io.read_csv(case.path("metrics", "ape.csv"))
                nees = case.path("consistency", "nees.csv")
                table = (
                    io.read_csv(nees) if c.consistency.get("available") and nees.exists() else {}
                )
                runs[c.run] = {
                    "t": ape["t"],
                    "trans_m": ape["trans_m"],
                    "rot_deg": ape["rot_deg"],
                    "nees_pos": table.get("nees_pos"),
                    "nees_rot": table.get("nees_rot"),
                }
            if not runs:
                continue
            summary, table = consistency.across_runs(runs)
            io.write_csv(results_dir / "consistency" / alg / f"{ds}.csv", table)
            rows.append({"algorithm": alg, "dataset": ds, **summary})
    cols = [
        "algorithm",
        "dataset",
        "runs",
        "n_common",
        "rmse_pos_m",
        "rmse_rot_deg",
        "nees_pos_mean",
        "nees_rot_mean",
    ]
    io.write_text(results_dir / "consistency" / "summary.csv", records_csv(cols, rows))


def make(
    keys: list[str], results_dir, cfg: dict, idle_truths: dict | None = None
) -> list[tuple[str, str]]:
    """The tables rule: read every case, write every table; returns the failed cases.
    ``idle_truths`` ({dataset: path}, mode ov_eval): references without any run, read here for the
    [COMP] line ov_eval prints for every reference."""
    grid = collect(keys, results_dir)
    idle = {}
    for ds, path in (idle_truths or {}).items():
        try:
            idle[ds] = reference_info(path, cfg, ds)
        except EpaError as exc:  # no case needs it: a warning, not a failed grid
            log.warning(
                "reference %s without runs left out of error_comparison.txt: %s", ds, exc.one_line()
            )
    write_all(grid, results_dir, cfg, idle)
    return failed_cases(grid)


def reference_info(path, cfg: dict, dataset: str) -> dict:
    """A reference's pose count and path length, as the load stage records them."""
    from epa import readers

    ref = readers.read(path, readers.options(cfg, "reference", dataset=dataset))
    return {"ref_file": Path(path).name, "n_ref": len(ref), "ref_length_m": ref.length()}


def failure_report(summary_path, most: int = 20) -> str:
    """A short end-of-run list of the cases without a result (empty when every case has one)."""
    with open(summary_path, encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    bad = [r for r in rows if not has_result(r["status"])]
    if not bad:
        return ""
    lines = [f"epica: {len(bad)} of {len(rows)} cases have no result (see {summary_path}):"]
    lines += [f"  {r['algorithm']}/{r['dataset']}/{r['run']}: {r['status']}" for r in bad[:most]]
    if len(bad) > most:
        lines.append(f"  ... and {len(bad) - most} more")
    return "\n".join(lines)
