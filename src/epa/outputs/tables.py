"""error_comparison.txt (seed 000 layout), one LaTeX table per .tex file, and summary.csv.

Aggregation rules: an ATE cell is the mean over runs of each run's RMSE; an RPE / drift-rate /
1 s RPE cell is the mean of the errors pooled over runs (and, for the per-algorithm segment
tables, over datasets); a success-rate cell is the mean over runs; the Average column is the mean
over the datasets that have a number; a cell with no successful run prints ``- / -``.
"""

from __future__ import annotations

import csv
import io as _io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from epa import io
from epa.chain import CaseFolder, case_dir, read_record
from epa.metrics.accuracy import segment_key

RULE_SHORT = "=" * 38
RULE_LONG = "=" * 44
_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
                  "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}


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
            res.metrics = io.read_json(case.path("metrics", "metrics.json"))
            res.drift = drift
            res.segments = {**io.read_csv(case.path("metrics", "rpe_segments.csv")),
                            **io.read_csv(case.path("drift", "rpe_segments_valid.csv"))}
            res.time = {**io.read_csv(case.path("metrics", "rpe_time.csv")),
                        **io.read_csv(case.path("drift", "rpe_time_valid.csv"))}
            if res.drift.get("status"):
                res.status = res.drift["status"]
            for stage in ("consistency", "efficiency"):
                path = case.path(stage, stage + ".json")
                if path.exists():
                    record, failed = read_record(path)
                    setattr(res, stage, record if failed is None else {"available": False, "failed": failed})
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
    ``pair`` cells hold rot / trans; the others a single number."""

    def __init__(self, values=None, pair: bool = True):
        self.values, self.pair = values, pair

    def fmt(self, decimals: int) -> str:
        if self.values is None:
            return "- / -" if self.pair else "-"
        return " / ".join("nan" if np.isnan(v) else f"{v:.{decimals}f}" for v in self.values)



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
    return _stat(c.metrics, "ate_2d", "yaw_deg", "rmse"), _stat(c.metrics, "ate_2d", "trans_xy_m", "rmse")


def _mean_over_runs(runs, of) -> _Cell:
    """The cell of a per-run pair: its mean over the runs (ov_eval's ATE cells)."""
    if not runs:
        return _Cell(None)
    return _Cell(tuple(_nanmean(v) for v in zip(*(of(c) for c in runs))))


def _ate(runs, valid: bool) -> _Cell:
    return _mean_over_runs(runs, lambda c: _run_ate(c, valid))


def _ate_2d(runs) -> _Cell:
    return _mean_over_runs(runs, _run_ate_2d)


def _pooled(runs, table: str, valid: bool, length=None):
    rot, trans = [], []
    for c in runs:
        t = getattr(c, table)
        sel = np.ones(len(t.get("rot_deg", [])), bool)
        if length is not None:
            sel &= t["length_m"] == float(length)
        if valid:
            sel &= t["valid"] > 0
        rot.append(t["rot_deg"][sel])
        trans.append(t["trans_m"][sel])
    return (np.concatenate(rot) if rot else np.zeros(0)), (np.concatenate(trans) if trans else np.zeros(0))


def _mean_pair(runs, table, valid, length=None) -> _Cell:
    if not runs:
        return _Cell(None)
    rot, trans = _pooled(runs, table, valid, length)
    if _all_nan_valid(runs, valid) or rot.size == 0:
        return _Cell((np.nan, np.nan))
    return _Cell((float(rot.mean()), float(trans.mean())))


def _drift_rate(runs, valid, length) -> _Cell:
    if not runs:
        return _Cell(None, pair=False)
    _, trans = _pooled(runs, "segments", valid, length)
    if _all_nan_valid(runs, valid) or trans.size == 0:
        return _Cell((np.nan,), pair=False)
    return _Cell((float(np.mean(trans / float(length)) * 100),), pair=False)


def _all_nan_valid(runs, valid):
    return valid and all(c.drift["global_failed"] or not (_num(c.drift["success_rate_distance_pct"]) > 0) for c in runs)


def _nees(runs) -> _Cell:
    have = [c.consistency for c in runs if c.consistency.get("available")]
    if not have:
        return _Cell(None)
    return _Cell((_nanmean(h["nees_rot_mean"] for h in have), _nanmean(h["nees_pos_mean"] for h in have)))


def _ea_drift(runs) -> _Cell:
    have = [c.efficiency for c in runs if c.efficiency.get("available")]
    return _Cell((_nanmean(h["ea_drift"] for h in have),), pair=False) if have else _Cell(None, pair=False)


def _runtime(grid, alg) -> list[_Cell]:
    """Frame times pooled over every run of an algorithm (each run's statistics, frame-weighted)."""
    eff = [c.efficiency for c in grid if c.algorithm == alg and c.efficiency.get("available")]
    frames = np.array([e["frames"] for e in eff], float)
    w = frames / frames.sum()
    return [_Cell((float(np.sum(w * [e["frame_time_mean_ms"] for e in eff])),), pair=False),
            _Cell((float(np.sum(w * [e["frame_time_p95_ms"] for e in eff])),), pair=False),
            _Cell((float(max(e["frame_time_max_ms"] for e in eff)),), pair=False),
            _Cell((float(np.sum(w * [e["frames_over_period_pct"] for e in eff])),), pair=False)]


def _kitti(runs) -> _Cell:
    """KITTI devkit metric, mean over runs: (rotation deg/100 m, translation %)."""
    have = [c.metrics["kitti"] for c in runs if (c.metrics.get("kitti") or {}).get("n_segments")]
    if not have:
        return _Cell(None)
    return _Cell((_nanmean(k["rot_deg_per_100m"] for k in have), _nanmean(k["trans_pct"] for k in have)))


def _success(runs) -> _Cell:
    if not runs:
        return _Cell(None, pair=False)
    return _Cell((_nanmean(c.drift["success_rate_distance_pct"] for c in runs),), pair=False)


# ----------------------------------------------------------------------------- rendering
def _latex_rows(header: list[str], rows: list[tuple[str, list[_Cell]]], decimals: int) -> list[str]:
    lines = [" & " + " & ".join(r"\textbf{" + latex_escape(h) + "}" for h in header) + r" \\ \hline"]
    for name, cells in rows:
        lines.append(latex_escape(name) + " & " + " & ".join(c.fmt(decimals) for c in cells) + r" \\")
    return lines


def build_tables(grid: list[CaseResult], segments, decimals: int = 3,
                 kitti: bool = False) -> list[tuple[str, str, list[str], int]]:
    """(file name, title, latex row lines, number of columns) for every table, in report order."""
    algs = sorted({c.algorithm for c in grid})
    datasets = sorted({c.dataset for c in grid})
    seg_labels = [f"{segment_key(s)}m" for s in segments]
    out = []

    def per_dataset(name, title, fn, pair=True, dec=decimals):
        rows = []
        for a in algs:
            cells = [fn(_ok_runs(grid, a, d)) for d in datasets]
            rows.append((a, cells + [_average(cells, pair)]))
        out.append((name, title, _latex_rows(datasets + ["Average"], rows, dec), len(datasets) + 2))

    def per_segment(name, title, fn):
        rows = [(a, [fn(_ok_runs(grid, a), s) for s in segments]) for a in algs]
        out.append((name, title, _latex_rows(seg_labels, rows, decimals), len(segments) + 1))

    def has(alg, stage):
        return any(c.algorithm == alg and getattr(c, stage).get("available") for c in grid)

    def marked(rows_of, stage, missing, pair):
        """Rows for algorithms with the data; the others named, their cells empty, never faked."""
        rows = []
        for a in algs:
            cells = [rows_of(_ok_runs(grid, a, d)) if has(a, stage) else _Cell(None, pair) for d in datasets]
            rows.append((a if has(a, stage) else f"{a} ({missing})", cells + [_average(cells, pair)]))
        return rows

    extra = [("nees", "NEES LATEX TABLE (ORI / POS, 3 = CONSISTENT)",
              marked(_nees, "consistency", "no covariance", True), datasets + ["Average"]),
             ("ea_drift", "EA-DRIFT LATEX TABLE (% PER-FRAME NORMALISED, SEE DOCS)",
              marked(_ea_drift, "efficiency", "no timing", False), datasets + ["Average"])]
    runtime_rows = [(a, _runtime(grid, a)) for a in algs if has(a, "efficiency")]
    extra.append(("runtime", "RUNTIME LATEX TABLE (FRAME TIME MS: MEAN, P95, MAX; % FRAMES OVER SENSOR PERIOD)",
                  runtime_rows, ["mean", "p95", "max", "over period %"]))

    for prefix, valid, tag in (("", False, "FULL TRAJECTORY"), ("valid_", True, "DRIFT-VALID ONLY")):
        if valid:
            per_dataset("success_rate", "DRIFT-VALID SUCCESS RATE LATEX TABLE (% PATH LENGTH)", _success, pair=False,
                        dec=2)
        per_dataset(prefix + "ate", f"{tag} ATE LATEX TABLE (ROT DEG / TRANS M)", lambda r: _ate(r, valid))
        if not valid:
            per_dataset("ate_2d", "FULL TRAJECTORY ATE 2D LATEX TABLE (YAW DEG / XY M)", _ate_2d)
        per_segment(prefix + "rpe_distance", f"{tag} DISTANCE RPE LATEX TABLE (ROT DEG / TRANS M)",
                    lambda r, s: _mean_pair(r, "segments", valid, s))
        per_segment(prefix + "drift_rate", f"{tag} DISTANCE DRIFT RATE LATEX TABLE (% TRANS / DIST)",
                    lambda r, s: _drift_rate(r, valid, s))
        per_dataset(prefix + "rpe_time_1s", f"{tag} 1S TIME RPE LATEX TABLE (ROT DEG / TRANS M)",
                    lambda r: _mean_pair(r, "time", valid))
    for name, title, rows, header in extra:
        out.append((name, title, _latex_rows(header, rows, decimals), len(header) + 1))
    if kitti:
        per_dataset("kitti", "KITTI ODOMETRY LATEX TABLE (ROT DEG/100M / TRANS %, 100-800 M SEGMENTS)", _kitti)
    return out


def _stat(d: dict, *keys):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return np.nan
        d = d[k]
    return _num(d)


def report_text(grid: list[CaseResult], segments, decimals: int = 3) -> str:
    lines = []
    datasets = sorted({c.dataset for c in grid})
    for ds in datasets:
        info = next((c.load for c in grid if c.dataset == ds and c.load), None)
        if info:
            lines.append(f"[COMP]: {info['n_ref']} poses in {info['ref_file']} => length of {info['ref_length_m']:.2f} meters")
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
                lines.append(f"        ATE: - / - (0 runs)")
            else:
                lines.append(f"        ATE: mean_ori = {ate.values[0]:.3f} | mean_pos = {ate.values[1]:.3f} ({len(runs)} runs)")
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
                        lines.append(f"        RPE: seg {segment_key(s)} - median_ori = {np.median(rot):.4f} | "
                                     f"median_pos = {np.median(trans):.4f} ({rot.size} samples)")
                    else:
                        lines.append(f"        RPE: seg {segment_key(s)} - no segment this long (0 samples)")
                rot, trans = _pooled(runs, "time", False)
                if rot.size:
                    lines.append(f"        RPE time 1s - mean_ori = {rot.mean():.3f} | mean_pos = {trans.mean():.3f}"
                                 f" ({rot.size} samples)")
                sr_d = _nanmean(c.drift["success_rate_distance_pct"] for c in runs)
                sr_t = _nanmean(c.drift["success_rate_time_pct"] for c in runs)
                lines.append(f"        SR - distance = {sr_d:.2f}% | time = {sr_t:.2f}%")
            for c in cases:
                if c.status != "ok":
                    lines.append(f"        {c.run}: {c.status}")
    lines += [RULE_LONG, f"TOOL SOURCE: epa={sources['epa']}, ov_eval={sources['ov_eval']}", RULE_LONG]
    for _, title, rows, _ in build_tables(grid, segments, decimals):
        lines += [RULE_LONG, title, RULE_LONG, *rows, RULE_LONG]
    return "\n".join(lines) + "\n"


def _ov_stats(values) -> tuple[float, float]:
    """Mean and standard deviation as ov_eval's Statistics: the sample deviation (n - 1), nan for one value."""
    v = np.asarray(list(values), float)
    return float(v.mean()), (float(v.std(ddof=1)) if v.size > 1 else np.nan)


def _c(x: float, fmt: str) -> str:
    """A number as C's printf prints it (glibc prints the NaN of 0/0 as -nan)."""
    return "-nan" if np.isnan(x) else fmt % x


def ov_eval_text(grid: list[CaseResult], segments) -> str:
    """error_comparison.txt in mode ov_eval: what ov_eval's error_comparison (v2.7 and later) prints,
    line for line ([COMP] lines, ATE, ATE 2D and RPE tables), so a diff shows only the numbers.
    Deviations: a cell without a successful run reads `- / -`, where ov_eval would stop or print 0."""
    datasets = sorted({c.dataset for c in grid})
    algs = sorted({c.algorithm for c in grid})
    lines = []
    for ds in datasets:
        info = next((c.load for c in grid if c.dataset == ds and c.load), None)
        if info:
            lines.append(f"[COMP]: {info['n_ref']} poses in {info['ref_file']} => length of {info['ref_length_m']:.2f} meters")
    cells: dict[str, dict] = {"ate": {}, "ate_2d": {}}
    for alg in algs:
        lines += [RULE_SHORT, f"[COMP]: processing {alg} algorithm"]
        for ds in datasets:
            runs = _ok_runs(grid, alg, ds)
            if not runs:
                lines.append(f"[COMP]: {alg} dataset does not have any runs for {ds}!!!!!")
                continue
            lines.append(f"[COMP]: processing {alg} algorithm => {ds} dataset")
            for name, label, fmt_std, of in (("ate", "ATE", "%.3f", _run_ate), ("ate_2d", "ATE 2D", "%.5f", _run_ate_2d)):
                ori, pos = zip(*(of(c) for c in runs))
                (m_ori, s_ori), (m_pos, s_pos) = _ov_stats(ori), _ov_stats(pos)
                cells[name][(alg, ds)] = (m_ori, m_pos)
                lines.append(f"\t{label}: mean_ori = {m_ori:.3f} | mean_pos = {m_pos:.3f} ({len(runs)} runs)")
                lines.append(f"\t{label}: std_ori  = {_c(s_ori, fmt_std)} | std_pos  = {_c(s_pos, fmt_std)}")
            for seg in segments:
                rot, trans = _pooled(runs, "segments", False, seg)
                med = (np.median(rot), np.median(trans)) if rot.size else (0.0, 0.0)
                lines.append(f"\tRPE: seg {int(seg)} - median_ori = {med[0]:.4f} | median_pos = {med[1]:.4f} "
                             f"({rot.size} samples)")
    lines += ["", ""]
    header = "".join(f" & \\textbf{{{latex_escape(ds)}}}" for ds in datasets) + " & \\textbf{Average} \\\\\\hline"
    for name, title in (("ate", "ATE LATEX TABLE"), ("ate_2d", "ATE 2D LATEX TABLE")):
        lines += [RULE_LONG, title, RULE_LONG, header]
        for alg in algs:
            row, have = latex_escape(alg), [cells[name][(alg, ds)] for ds in datasets if (alg, ds) in cells[name]]
            for ds in datasets:
                v = cells[name].get((alg, ds))
                row += " & - / -" if v is None else f" & {v[0]:.3f} / {v[1]:.3f}"
            row += (f" & {np.mean([v[0] for v in have]):.3f} / {np.mean([v[1] for v in have]):.3f} \\\\" if have
                    else " & - / - \\\\")
            lines.append(row)
        lines.append(RULE_LONG)
    lines += [RULE_LONG, "RPE LATEX TABLE", RULE_LONG,
              "".join(f" & \\textbf{{{int(seg)}m}}" for seg in segments) + " \\\\\\hline"]
    for alg in algs:
        row = latex_escape(alg)
        for seg in segments:
            rot, trans = _pooled(_ok_runs(grid, alg), "segments", False, seg)
            row += f" & {rot.mean():.3f} / {trans.mean():.3f}" if rot.size else " & - / -"
        lines.append(row + " \\\\")
    lines.append(RULE_LONG)
    return "\n".join(lines) + "\n"


def tex_document(title: str, rows: list[str], ncols: int) -> str:
    """A table that \\input's into a paper: a tabular with the report's rows, titled in a comment."""
    spec = "l" + "c" * (ncols - 1)
    return "\n".join([f"% {title}", r"\begin{tabular}{" + spec + "}", *rows, r"\end{tabular}", ""])


SUMMARY_FIXED = ["algorithm", "dataset", "run", "status", "eval_source", "n_matched", "ate_trans_rmse_m",
                 "ate_rot_rmse_deg", "time_rpe_1s_trans_mean_m", "time_rpe_1s_rot_mean_deg", "time_offset_s",
                 "extrinsic_rot_deg", "extrinsic_trans_m", "success_rate_distance_pct", "success_rate_time_pct",
                 "global_failed", "knee_threshold_m", "fail_segments", "diverged_at_s", "nees_rot_mean",
                 "nees_pos_mean", "outside_3sigma_pct", "ea_drift", "frame_time_mean_ms", "kitti_trans_pct",
                 "kitti_rot_deg_per_100m", "notes"]


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
            row.update(eval_source=m.get("eval_source"), n_matched=m.get("n_matched"),
                       ate_trans_rmse_m=_stat(m, "ate", "trans_m", "rmse"), ate_rot_rmse_deg=_stat(m, "ate", "rot_deg", "rmse"),
                       time_rpe_1s_trans_mean_m=_stat(m, "rpe_time_1s", "trans_m", "mean"),
                       time_rpe_1s_rot_mean_deg=_stat(m, "rpe_time_1s", "rot_deg", "mean"),
                       time_offset_s=m.get("time_offset_s"), extrinsic_rot_deg=m.get("extrinsic_rot_deg"),
                       extrinsic_trans_m=m.get("extrinsic_trans_m"),
                       success_rate_distance_pct=_num(d.get("success_rate_distance_pct")),
                       success_rate_time_pct=_num(d.get("success_rate_time_pct")),
                       global_failed=d.get("global_failed"), knee_threshold_m=_stat(d, "knee", "threshold_m"),
                       fail_segments=d.get("n_fail_segments"), diverged_at_s=d.get("diverged_at_s"))
            if c.consistency.get("available"):  # empty without covariance
                row.update({k: c.consistency[k] for k in ("nees_rot_mean", "nees_pos_mean", "outside_3sigma_pct")})
            if c.efficiency.get("available"):  # empty without timing
                row.update(ea_drift=c.efficiency["ea_drift"], frame_time_mean_ms=c.efficiency["frame_time_mean_ms"])
            kitti = m.get("kitti") or {}  # empty unless metrics.kitti is on
            row.update(kitti_trans_pct=kitti.get("trans_pct"), kitti_rot_deg_per_100m=kitti.get("rot_deg_per_100m"))
            # a stage after drift that failed (a broken timing file) leaves the accuracy standing
            row["notes"] = "; ".join(getattr(c, s)["failed"] for s in ("consistency", "efficiency")
                                     if getattr(c, s).get("failed")) or None
            for s in segments:
                L = segment_key(s)
                row[f"rpe_{L}m_trans_mean_m"] = _stat(m, "rpe_distance", L, "trans_m", "mean")
                row[f"rpe_{L}m_rot_mean_deg"] = _stat(m, "rpe_distance", L, "rot_deg", "mean")
                row[f"drift_rate_{L}m_pct"] = _stat(m, "drift_rate_pct", L)
        rows.append(row)
    return SUMMARY_FIXED + seg_cols, rows


def summary_csv(grid, segments) -> str:
    cols, rows = summary_rows(grid, segments)
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n", restval="")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else (f"{v:.9g}" if isinstance(v, float) else v)) for k, v in r.items()})
    return buf.getvalue()


TABLE_NAMES = ("ate", "ate_2d", "rpe_distance", "drift_rate", "rpe_time_1s", "success_rate",
               "valid_ate", "valid_rpe_distance", "valid_drift_rate", "valid_rpe_time_1s", "nees", "ea_drift", "runtime")


def table_names(cfg: dict) -> tuple[str, ...]:
    """The .tex files the tables rule writes under these settings."""
    return TABLE_NAMES + (("kitti",) if cfg["metrics"]["kitti"] else ())


def write_all(grid: list[CaseResult], results_dir, cfg: dict) -> None:
    """error_comparison.txt, summary.csv and tables/<name>.tex under ``results_dir``."""
    results_dir = Path(results_dir)
    segments = cfg["metrics"]["segments"]
    decimals = cfg["tables"]["decimals"]
    text = ov_eval_text(grid, segments) if cfg.get("mode") == "ov_eval" else report_text(grid, segments, decimals)
    io.write_text(results_dir / "error_comparison.txt", text)
    io.write_text(results_dir / "summary.csv", summary_csv(grid, segments))
    for name, title, rows, n in build_tables(grid, segments, decimals, kitti=cfg["metrics"]["kitti"]):
        io.write_text(results_dir / "tables" / f"{name}.tex", tex_document(title, rows, n))
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
                table = io.read_csv(nees) if c.consistency.get("available") and nees.exists() else {}
                runs[c.run] = {"t": ape["t"], "trans_m": ape["trans_m"], "rot_deg": ape["rot_deg"],
                               "nees_pos": table.get("nees_pos"), "nees_rot": table.get("nees_rot")}
            if not runs:
                continue
            summary, table = consistency.across_runs(runs)
            io.write_csv(results_dir / "consistency" / alg / f"{ds}.csv", table)
            rows.append({"algorithm": alg, "dataset": ds, **summary})
    cols = ["algorithm", "dataset", "runs", "n_common", "rmse_pos_m", "rmse_rot_deg", "nees_pos_mean", "nees_rot_mean"]
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n", restval="")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else (f"{r[k]:.9g}" if isinstance(r[k], float) else r[k])) for k in cols})
    io.write_text(results_dir / "consistency" / "summary.csv", buf.getvalue())


def make(keys: list[str], results_dir, cfg: dict) -> list[tuple[str, str]]:
    """The tables rule: read every case, write every table; returns the failed cases."""
    grid = collect(keys, results_dir)
    write_all(grid, results_dir, cfg)
    return failed_cases(grid)


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
