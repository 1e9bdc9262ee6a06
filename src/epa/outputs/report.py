"""Per-case report (``10_report/``) and grid figures, built from the stage artifacts only: nothing is
recomputed here but plot coordinates (the first-pose overlay of the "before" view).

Per case: ``metrics.json`` (every stage's record in one document), ``metrics_summary.csv``
(section, metric, value), ``report_en.md`` / ``report_zh.md``, ``figures/<name>.png|pdf`` with each
figure's bundle in ``bundles/<name>.json``, and ``<run>.zip`` (every artifact plus a manifest).
"""

from __future__ import annotations

import csv
import hashlib
import io as _io
import json
import zipfile
from pathlib import Path

import numpy as np

from epa.artifacts import files as io
from epa.artifacts.case import CaseData, CaseFolder
from epa.metrics.accuracy import segment_key
from epa.outputs import figures, tables

CASE_FIGURES = ("trajectory", "ape_time", "rpe_box", "xcorr", "steps", "sigma3")
GRID_FIGURES = ("ate", "success_rate", "success_curve", "drift_rate", "rmse_time")


# ----------------------------------------------------------------------------- case artifacts
# ----------------------------------------------------------------------------- case bundles
def case_bundles(data: CaseData) -> dict[str, dict]:
    """Every per-case figure's bundle, from a case's artifacts."""
    p = data.folder.path
    ref, aligned, ape, fail = data.matched[0], data.aligned, data.ape, data.fail_segments
    drift = io.read_json(p("drift", "drift.json"))
    sync = io.read_json(p("sync", "sync.json"))
    t0 = float(ref.t[0])
    k = figures.thin(len(ref))
    out = {
        "trajectory": figures.bundle(
            "trajectory",
            "Reference and aligned estimate, coloured by APE",
            {"ref": ref.p[k], "est": aligned.p[k], "err": ape["trans_m"][k]},
        )
    }
    out["ape_time"] = figures.bundle(
        "ape_time",
        "APE over time, fail segments shaded",
        {
            "t": ape["t"][k] - t0,
            "ape": ape["trans_m"][k],
            "fail_start": np.asarray(fail.get("t_start", []), float) - t0,
            "fail_end": np.asarray(fail.get("t_end", []), float) - t0,
            "threshold": (drift.get("knee") or {}).get("threshold_m"),
        },
    )
    seg = io.read_csv(p("metrics", "rpe_segments.csv"))
    lengths = sorted({float(x) for x in seg["length_m"]}) if len(seg.get("length_m", [])) else []
    out["rpe_box"] = figures.bundle(
        "rpe_box",
        "RPE per segment length",
        {"lengths": lengths, "trans": [seg["trans_m"][seg["length_m"] == L] for L in lengths]},
    )
    xc = io.read_csv(p("sync", "xcorr.csv"))
    step1 = sync.get("step1", {})
    out["xcorr"] = figures.bundle(
        "xcorr",
        "Step 1: angular-speed cross-correlation",
        {
            "lag": xc.get("lag_s", []),
            "corr": xc.get("corr", []),
            "peak": step1.get("estimated") if step1.get("used") else None,
            "reason": step1.get("reason", ""),
        },
    )
    est_m = data.matched[1]  # the estimate as read, at the matched poses
    # "before": the estimate as read, put on the reference by its first pose only
    r0 = ref.r[0] @ est_m.r[0].T
    before = (est_m.p - est_m.p[0]) @ r0.T + ref.p[0]
    out["steps"] = figures.bundle(
        "steps",
        "Before and after Steps 1-3 (top view)",
        {"ref": ref.p[k], "before": before[k], "after": aligned.p[k]},
    )
    n = data.nees
    if n:
        kk = figures.thin(len(n["t"]))  # drawn as a band: 1000 samples suffice
        out["sigma3"] = figures.bundle(
            "sigma3",
            "Per-axis error and its ±3σ bound",
            {
                "t": n["t"][kk] - n["t"][0],
                **{c: n[c][kk] for c in n if c.startswith(("err_", "sigma_"))},
            },
        )
    return out


# ----------------------------------------------------------------------------- documents
def case_document(case: CaseFolder) -> dict:
    """Every stage's record of a case, as one document."""
    doc = {}
    for stage, name in (
        ("metrics", "metrics.json"),
        ("drift", "drift.json"),
        ("consistency", "consistency.json"),
        ("efficiency", "efficiency.json"),
    ):
        path = case.path(stage, name)
        if path.exists():
            doc[stage] = io.read_json(path)
    return doc


def _numbers(prefix: str, obj):
    """(dotted name, value) of every number in a nested record."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _numbers(f"{prefix}.{k}" if prefix else str(k), v)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield prefix, obj


SETTINGS_AND_MATRICES = ("load", "sync", "calibrate", "alignment", "thresholds", "rpe")


def summary_rows(doc: dict) -> list[tuple[str, str, float]]:
    """(section, metric, value) for every number in the document, except matrices and settings."""
    return [
        (section, name, value)
        for section, record in doc.items()
        for name, value in _numbers(
            "", {k: v for k, v in record.items() if k not in SETTINGS_AND_MATRICES}
        )
    ]


def summary_csv(doc: dict) -> str:
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["section", "metric", "value"])
    for section, metric, value in summary_rows(doc):
        w.writerow([section, metric, f"{value:.9g}" if isinstance(value, float) else value])
    return buf.getvalue()


TEXT = {
    "en": {
        "title": "Evaluation of",
        "settings": "Settings",
        "steps": "Steps 1-3",
        "metrics": "Metrics",
        "fail": "Fail segments",
        "figures": "Figures",
        "undrawn": "Not drawn ({why}): {names}. Draw them with `{command}` in the case folder"
        " (the one holding 10_report/).",
        "none": "none",
        "offset": "Step 1 time offset",
        "extrinsic": "Step 2 extrinsic",
        "align": "Step 3 alignment",
        "used": "used",
        "not_used": "not used",
        "source": "evaluated as",
        "metric": "metric",
        "value": "value",
        "start": "start [s]",
        "end": "end [s]",
        "consistency": "Consistency",
        "efficiency": "Efficiency",
        "unavailable": "not available",
        "status": "status",
        "std": "std",
        "per_axis": "per axis x, y, z",
        "unobservable": "unobservable",
    },
    "zh": {
        "title": "评估：",
        "settings": "设置",
        "steps": "步骤 1-3",
        "metrics": "指标",
        "fail": "失效区段",
        "figures": "图",
        "undrawn": "未绘制（{why}）：{names}。在案例文件夹（包含 10_report/ 的文件夹）中运行 `{command}` 绘制。",
        "none": "无",
        "offset": "步骤 1 时间偏移",
        "extrinsic": "步骤 2 外参",
        "align": "步骤 3 对齐",
        "used": "已使用",
        "not_used": "未使用",
        "source": "评估方式",
        "metric": "指标",
        "value": "数值",
        "start": "开始 [s]",
        "end": "结束 [s]",
        "consistency": "一致性",
        "efficiency": "效率",
        "unavailable": "不可用",
        "status": "状态",
        "std": "标准差",
        "per_axis": "各轴 x, y, z",
        "unobservable": "不可观",
    },
}


def _num(v) -> float:
    """A record's number as a float ("inf" is how JSON artifacts hold infinity; None is nan)."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _axis_std(values, factor: float, unit: str, T: dict) -> str:
    return (
        " / ".join(T["unobservable"] if v is None else f"{_num(v) * factor:.3g}" for v in values)
        + f" {unit}"
    )


def report_md(
    doc: dict,
    case_name: str,
    figure_names: list[str],
    lang: str,
    fail: dict,
    undrawn: tuple[list[str], str, str] | None = None,
) -> str:
    """A case's report in ``lang``; ``undrawn``: (figure names, why, the command that draws them)."""
    T = TEXT[lang]
    m = doc.get("metrics", {})
    sync, calib, align = m.get("sync", {}), m.get("calibrate", {}), m.get("alignment", {})
    step1 = sync.get("step1", {})
    ext = calib.get("extrinsic") or {}
    lines = [
        f"# {T['title']} {case_name}",
        "",
        f"## {T['settings']}",
        "",
        f"- mode `{sync.get('mode')}`, association `{sync.get('policy')}` (max {sync.get('max_diff_s')} s),"
        f" alignment `{align.get('method')}`",
        f"- {T['source']}: `{m.get('eval_source')}`",
        "",
        f"## {T['steps']}",
        "",
        f"- {T['offset']}: {_num(m.get('time_offset_s')) * 1000:.3f} ms"
        f" ({T['used'] if step1.get('used') else T['not_used']}: {step1.get('reason', '')};"
        f" peak {_num(step1.get('peak_corr')):.3f}, ratio {_num(step1.get('peak_ratio')):.3f});"
        f" {T['status']} `{step1.get('status')}`, {T['std']} {_num(step1.get('std')) * 1000:.3f} ms",
        f"- {T['extrinsic']}: "
        + (
            f"{_num(ext.get('rotation_deg')):.3f} deg, {_num(ext.get('translation_norm_m')):.4f} m"
            f" ({T['used'] if calib.get('plan', {}).get('apply_extrinsic') else T['not_used']}:"
            f" {calib.get('plan', {}).get('reason', '')})"
            if ext
            else T["none"]
        )
        + f"; {T['status']} `{calib.get('step2_status')}`",
        *(
            [
                f"  - {T['std']} ({T['per_axis']}): rotation {_axis_std(ext.get('rotation_std_deg'), 1, 'deg', T)},"
                f" translation {_axis_std(ext.get('translation_std_m'), 1000, 'mm', T)}"
            ]
            if ext.get("rotation_std_deg")
            else []
        ),
        f"- {T['align']}: {align.get('method')}, yaw {_num(align.get('yaw_deg')):.3f} deg,"
        f" scale {_num(align.get('scale')):.6f}",
        "",
        f"## {T['metrics']}",
        "",
        f"| {T['metric']} | {T['value']} |",
        "|---|---|",
    ]
    for section, metric, value in summary_rows(
        {k: doc[k] for k in ("metrics", "drift") if k in doc}
    ):
        if metric.endswith(("rmse", "mean", "median", "max", "_pct")) or metric in (
            "n_matched",
            "ref_length_m",
        ):
            lines.append(f"| {section}.{metric} | {value:.6g} |")
    for key in ("consistency", "efficiency"):
        rec = doc.get(key, {})
        lines += ["", f"## {T[key]}", ""]
        if not rec.get("available"):
            lines.append(f"{T['unavailable']}: {rec.get('reason', rec.get('failed', ''))}")
            continue
        for k, v in rec.items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                lines.append(f"- {k}: {v:.6g}")
    lines += ["", f"## {T['fail']}", ""]
    starts = np.asarray(fail.get("t_start", []), float)
    if starts.size:  # stamps of the reference clock, as in 07_drift/fail_segments.csv
        lines += [f"| {T['start']} | {T['end']} |", "|---|---|"]
        lines += [
            f"| {s:.3f} | {e:.3f} |" for s, e in zip(starts, np.asarray(fail["t_end"], float))
        ]
    else:
        lines.append(T["none"])
    lines += ["", f"## {T['figures']}", ""] + [f"![{n}](figures/{n}.png)" for n in figure_names]
    if undrawn and undrawn[0]:
        names, why, command = undrawn
        lines += ["", T["undrawn"].format(why=why, names=", ".join(names), command=command)]
    return "\n".join(lines) + "\n"


def flags(doc: dict) -> list[str]:
    """Why a reader would open this case: what drift detection and Steps 1-2 found (empty: nothing)."""
    m, drift = doc.get("metrics", {}), doc.get("drift", {})
    out = []
    if drift.get("global_failed"):
        out.append("globally failed")
    elif drift.get("n_fail_segments"):
        out.append(f"{drift['n_fail_segments']} fail segments")
    if (m.get("calibrate", {}).get("plan") or {}).get("fallback"):
        out.append("evaluated the ov_eval way (" + m["calibrate"].get("reason", "") + ")")
    return out


def case_zip(case_root: Path, out: Path) -> None:
    """Every artifact of the case and a manifest (file, bytes, sha256), for sharing one evaluation."""
    files = sorted(
        p
        for p in case_root.rglob("*")
        if p.is_file() and p != out and not p.name.startswith(".") and p.suffix != ".zip"
    )
    manifest = []
    tmp = out.with_name("." + out.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for f in files:
            data = f.read_bytes()
            rel = f.relative_to(case_root).as_posix()
            z.writestr(rel, data)
            manifest.append(
                {"file": rel, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
            )
        z.writestr(
            "MANIFEST.json",
            json.dumps({"format": "epica-case-bundle/1", "files": manifest}, indent=1),
        )
    tmp.replace(out)


def write_case_report(data: CaseData, name: str, cfg: dict) -> dict:
    """The report stage: documents, plot bundles, figures (``report.figures``: flagged cases, all
    or none) and the zip, from the case's artifacts (``data`` reads them)."""
    c = cfg["report"]
    case = data.folder
    folder = case.path("report", "report.json").parent
    doc = case_document(case)
    io.write_json(folder / "metrics.json", doc)
    io.write_text(folder / "metrics_summary.csv", summary_csv(doc))
    # Figures cost most of a report (0.3 s a case): by default only the cases a reader opens first,
    # those drift detection or Steps 1-2 flagged, are drawn; every case keeps its bundles.
    bundles = case_bundles(data)
    for fig_name, b in bundles.items():
        figures.write_bundle(folder / "bundles" / f"{fig_name}.json", b)
    why = flags(doc)
    draw = c["figures"] == "all" or (c["figures"] == "flagged" and why)
    drawn = list(bundles) if draw else []
    for fig_name in drawn:  # from the bundle as written: `epa fig` redraws the same bytes
        formats = ("png", "pdf") if c["pdf"] else ("png",)
        bundle = figures.read_bundle(folder / "bundles" / f"{fig_name}.json")
        figures.render(bundle, folder / "figures" / fig_name, formats=formats)
    reason = "report.figures: none" if c["figures"] == "none" else "the case is not flagged"
    # run in the case folder: the report reads the same wherever the results are
    undrawn = ([n for n in bundles if n not in drawn], reason, "epa fig --case .")
    for lang in ("en", "zh"):
        md = report_md(doc, name, drawn, lang, data.fail_segments, undrawn)
        io.write_text(folder / f"report_{lang}.md", md)
    if c["rerun"]:
        from epa.outputs import recording

        recording.write_rrd(data, name, folder / f"{name.replace('/', '_')}.rrd")
    if c["zip"]:  # last: it holds the other report files
        case_zip(case.root, folder / f"{name.replace('/', '_')}.zip")
    return {"figures": drawn, "flags": why, "zip": bool(c["zip"]), "rerun": bool(c["rerun"])}


# ----------------------------------------------------------------------------- grid figures
def _nanmean(values):
    """np.nanmean, without numpy's "Mean of empty slice" warning when every value is nan (an
    algorithm whose every run failed): nan, drawn as a gap."""
    a = np.asarray(values, float)
    return np.nanmean(a) if (~np.isnan(a)).any() else np.nan


def _column(row: dict, key: str) -> float:
    """A summary.csv row's number (nan where empty)."""
    try:
        return float(row[key])
    except (KeyError, ValueError):
        return np.nan


def grid_bundles(summary_csv_path, consistency_dir, segments) -> dict[str, dict]:
    """ATE per algorithm and dataset, drift rate against segment length, success rate, RMSE over
    time across runs, success against the drift threshold: from summary.csv, success_curves.csv and
    results/consistency/, one colour per algorithm."""
    with open(summary_csv_path, encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    ok = [r for r in rows if tables.has_result(r["status"])]
    algs = sorted({r["algorithm"] for r in rows})
    datasets = sorted({r["dataset"] for r in rows})

    def cells(key):
        """Per algorithm, per dataset: the runs' finite values of a summary.csv column."""
        return [
            [
                [
                    _column(r, key)
                    for r in ok
                    if r["algorithm"] == a and r["dataset"] == d and np.isfinite(_column(r, key))
                ]
                for d in datasets
            ]
            for a in algs
        ]

    success = [
        [[np.nanmean(v)] if v else [] for v in a] for a in cells("success_rate_distance_pct")
    ]
    ate = {"values": cells("ate_trans_rmse_m"), "ylabel": "ATE RMSE [m]", "log": True}
    rate = {"bars": True, "values": success, "ylabel": "success rate [% of path]"}
    return {
        "ate": figures.bundle(
            "grouped",
            "ATE per algorithm and dataset (runs)",
            {"datasets": datasets, "algorithms": algs, **ate, "colors": figures.OKABE_ITO},
        ),
        "success_rate": figures.bundle(
            "grouped",
            "Success rate per algorithm and dataset",
            {"datasets": datasets, "algorithms": algs, **rate, "colors": figures.OKABE_ITO},
        ),
        "drift_rate": _drift_rate_bundle(ok, algs, segments),
        "rmse_time": _rmse_time_bundle(Path(consistency_dir), algs, datasets),
        "success_curve": _success_curve_bundle(
            Path(summary_csv_path).parent / "success_curves.csv", algs, datasets
        ),
    }


def _drift_rate_bundle(ok: list[dict], algs: list[str], segments) -> dict:
    lines = []
    for k, a in enumerate(algs):
        ys = [
            _nanmean(
                [_column(r, f"drift_rate_{segment_key(s)}m_pct") for r in ok if r["algorithm"] == a]
                or [np.nan]
            )
            for s in segments
        ]
        lines.append({"label": a, "x": list(segments), "y": ys, "color": k})
    return figures.bundle(
        "lines",
        "Distance drift rate against segment length",
        {
            "panels": [{"lines": lines}],
            "xlabel": "segment length [m]",
            "ylabel": "drift rate [%]",
            "markers": True,
            "colors": figures.OKABE_ITO,
            "log": True,  # a diverged run would flatten the others
        },
    )


def _rmse_time_bundle(consistency_dir: Path, algs: list[str], datasets: list[str]) -> dict:
    panels = []
    for d in datasets:
        panel_lines = []
        for k, a in enumerate(algs):
            path = consistency_dir / a / f"{d}.csv"
            if path.exists():
                t = io.read_csv(path)
                if len(t.get("t", [])):
                    kk = figures.thin(len(t["t"]), 1500)
                    x, y = t["t"][kk] - t["t"][0], t["rmse_pos_m"][kk]
                    panel_lines.append({"label": a, "x": x, "y": y, "color": k})
        panels.append({"title": d, "lines": panel_lines})
    return figures.bundle(
        "lines",
        "RMSE over time across runs",
        {
            "panels": panels,
            "xlabel": "time [s]",
            "ylabel": "RMSE [m]",
            "colors": figures.OKABE_ITO,
            "log": True,
        },
    )


def _success_curve_bundle(curves_path: Path, algs: list[str], datasets: list[str]) -> dict:
    with open(curves_path, encoding="utf-8", newline="") as fh:
        curves = list(csv.DictReader(fh))
    panels = []
    for d in datasets:
        panel_lines = []
        for k, a in enumerate(algs):
            rows = [r for r in curves if r["algorithm"] == a and r["dataset"] == d]
            if rows:
                x = [_column(r, "factor") for r in rows]
                y = [_column(r, "success_rate_distance_pct") for r in rows]
                panel_lines.append({"label": a, "x": x, "y": y, "color": k})
        panels.append({"title": d, "lines": panel_lines})
    return figures.bundle(
        "lines",
        "Success rate against the drift threshold",
        {
            "panels": panels,
            "xlabel": "threshold / default",
            "ylabel": "success rate [% of path]",
            "colors": figures.OKABE_ITO,
            "logx": True,
            "sharey": True,
            "dashes": True,
            "ylim": [0, 102],
        },
    )


def write_grid_figures(results_dir, segments, style: str = "wide") -> list[Path]:
    results_dir = Path(results_dir)
    written = []
    for name, b in grid_bundles(
        results_dir / "summary.csv", results_dir / "consistency", segments
    ).items():
        figures.write_bundle(results_dir / "figures" / "bundles" / f"{name}.json", b)
        written += figures.render(b, results_dir / "figures" / name, style=style)
    return written
