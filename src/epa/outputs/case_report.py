# ruff: noqa: E501  (the report's sentences stay whole, one per line)
"""The per-case report a person reads (``10_report/report_en.md``, ``report_zh.md``): the metrics as
compact tables, Steps 1-3 with their statuses and deviations in words, the figures (and the one
command that draws each one not drawn), and the case's provenance (epica version, input hashes).
Built from the case's records only; ``metrics_summary.csv`` keeps every key.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from epa import __version__
from epa.metrics import accuracy, registry
from epa.outputs import provenance, zh_reasons


def _as_is(reason: str) -> str:
    return reason


TEXT: dict[str, dict[str, Any]] = {
    "en": {
        "title": "Evaluation of",
        "lead": "Evaluated as `{source}`: {n} matched poses over {length:.1f} m of the reference.",
        "settings": "Settings: mode `{mode}`, association `{policy}` (within {max_diff} s), alignment `{align}`.",
        "metrics": "Metrics",
        "metrics_note": "Translation in m / rotation in deg over every matched pose (RPE: over every pair of that length); the drift rate is the RPE translation divided by the segment length.",
        "row": "",
        "rmse": "RMSE",
        "mean": "mean",
        "median": "median",
        "max": "max",
        "ate": "ATE (m / deg)",
        "ate_2d": "ATE 2D (xy m / yaw deg)",
        "rpe_seg": "RPE {L} m (m / deg)",
        "rpe_time": "RPE {delta} s (m / deg)",
        "drift_rate": "drift rate {L} m (%)",
        "valid": "Drift-valid only (fail segments left out)",
        "no_fail": "No fail segment: the drift-valid metrics are the ones above.",
        "success": "Success rate: {d} % of the path (threshold-free area {a} %), {t} % of the time.",
        "global_failed": "Globally failed: the whole-run fit is dominated by a failure, so the drift-valid metrics are left out.",
        "steps": "Steps 1-3",
        "step1": "Step 1, time offset",
        "step2": "Step 2, extrinsic",
        "step3": "Step 3, alignment",
        "s1_used": "estimated {ms:+.3f} ms and applied (status `{status}`: {meaning}); its deviation is {std} (one standard deviation over replicates), peak correlation {peak:.3f}.",
        "s1_not": "not applied (status `{status}`: {meaning}; {reason}); the configured offset {ms:+.3f} ms is used.",
        "s2_used": "{rot:.3f} deg and a lever arm of {trans:.4f} m, applied (status `{status}`: {meaning}); its deviation per axis x, y, z is {rstd} in rotation and {tstd} in translation.",
        "s2_not": "not applied (status `{status}`: {meaning}; {reason}).",
        "s2_found": "found {rot:.3f} deg and {trans:.4f} m but ",
        "s3": "`{method}` fit of the estimate onto the reference: yaw {yaw:.3f} deg, scale {scale:.6f}.",
        "fallback": "The case is evaluated the ov_eval way, with the configured alignment; dropped: {dropped}.",
        "s3_se3": "An SE3 fit of the same matched poses gives an ATE RMSE of {se3} m against {sim3} m under Sim3 (ratio {ratio}).",
        "s3_sim3": "A Sim3 fit beside it (the scale check) finds scale {scale} and an ATE RMSE of {sim3} m against {ate} m ({removed} % of it removed).",
        "scale_used": "The estimate is evaluated at scale {value}{std} (fitted by {by}).",
        "warning": "Warning",
        "meaning": {
            "trusted": "every check passed",
            "disabled": "switched off by the settings",
            "uncertain": "its deviation is above the configured limit",
            "not run": "Step 1 was not trusted",
            "too little motion": "the motion is too small to observe it",
            "unobservable": "the motion leaves a direction unobservable",
            "large residual": "the hand-eye residual is above the limit",
            "no overlap": "the stamps do not overlap",
            "outside window": "the best match lies outside the search window",
            "at window edge": "the peak lies on the edge of the search window",
            "weak peak": "the correlation peak is weak",
            "ambiguous": "a second peak is almost as high (periodic motion)",
        },
        "unobservable": "unobservable",
        "infinite": "unbounded (a replicate left the main peak)",
        "consistency": "Consistency",
        "efficiency": "Efficiency",
        "unavailable": "not available",
        "nees": "NEES orientation {r:.3f}, position {p:.3f} (3 = consistent); {o:.2f} % of the errors outside ±3σ.",
        "eff": "Frame time mean {m:.2f} ms (p95 {p:.2f} ms) at {hz:g} Hz; {over:.1f} % of the frames over the sensor period; EA-Drift {ea:.4f} %.",
        "fail": "Fail segments",
        "start": "start [s after the first matched pose]",
        "end": "end [s after the first matched pose]",
        "none": "none",
        "figures": "Figures",
        "not_drawn": "Not drawn (each bundle holds the figure's data; the command draws it, from this folder):",
        "off": "`report.figures` is off",
        "not_flagged": "the case is not flagged: `report.figures: flagged` draws only cases with fail segments, globally failed or with a metric warning",
        "all_cmd": "All of them at once: `epa fig --case ..`.",
        "no_bundle": "{name}: no data ({why})",
        "no_cov": "the estimate has no covariance",
        "pdf": "Vector PDFs are not drawn (`report.pdf` is off); from this folder: `{cmd}` (likewise for the others).",
        "provenance": "Provenance",
        "prov_lead": "epica {version}. The inputs, as read:",
        "file": "file",
        "bytes": "bytes",
        "grid_prov": "The whole run's provenance (versions of every dependency, the resolved settings): `{path}`; `epa verify` checks the hashes and regenerates the numbers.",
        "missing": "missing",
        "every_key": "Every number of every record: `metrics_summary.csv` (section, metric, value) and `metrics.json`.",
        # the records' reasons and warnings, said in this language (the records keep English)
        "say": _as_is,
        "sep": "; ",
    },
    "zh": {
        "title": "评估：",
        "lead": "评估方式 `{source}`：{n} 个匹配位姿，参考轨迹长 {length:.1f} m。",
        "settings": "设置：模式 `{mode}`，关联 `{policy}`（{max_diff} s 以内），对齐 `{align}`。",
        "metrics": "指标",
        "metrics_note": "平移 m / 旋转 deg，基于所有匹配位姿（RPE：该长度的所有位姿对）；漂移率为 RPE 平移除以区段长度。",
        "row": "",
        "rmse": "RMSE",
        "mean": "均值",
        "median": "中位数",
        "max": "最大值",
        "ate": "ATE (m / deg)",
        "ate_2d": "ATE 2D (xy m / 航向 deg)",
        "rpe_seg": "RPE {L} m (m / deg)",
        "rpe_time": "RPE {delta} s (m / deg)",
        "drift_rate": "漂移率 {L} m (%)",
        "valid": "仅漂移有效部分（去除失效区段）",
        "no_fail": "无失效区段：漂移有效指标与上表相同。",
        "success": "成功率：路径的 {d} %（无阈值面积 {a} %），时间的 {t} %。",
        "global_failed": "整体失效：整段拟合被失效主导，漂移有效指标不予报告。",
        "steps": "步骤 1-3",
        "step1": "步骤 1，时间偏移",
        "step2": "步骤 2，外参",
        "step3": "步骤 3，对齐",
        "s1_used": "估计为 {ms:+.3f} ms 并已使用（状态 `{status}`：{meaning}）；其偏差为 {std}（重复估计的一个标准差），峰值相关 {peak:.3f}。",
        "s1_not": "未使用（状态 `{status}`：{meaning}；{reason}）；使用配置的偏移 {ms:+.3f} ms。",
        "s2_used": "旋转 {rot:.3f} deg，杆臂 {trans:.4f} m，已使用（状态 `{status}`：{meaning}）；各轴 x, y, z 的偏差：旋转 {rstd}，平移 {tstd}。",
        "s2_not": "未使用（状态 `{status}`：{meaning}；{reason}）。",
        "s2_found": "求得 {rot:.3f} deg 与 {trans:.4f} m，但",
        "s3": "估计轨迹到参考轨迹的 `{method}` 拟合：航向 {yaw:.3f} deg，尺度 {scale:.6f}。",
        "fallback": "本例按 ov_eval 方式评估，对齐方式按配置不变；未使用：{dropped}。",
        "s3_se3": "对同一组匹配位姿做 SE3 拟合，ATE RMSE 为 {se3} m，Sim3 下为 {sim3} m（比值 {ratio}）。",
        "s3_sim3": "另做 Sim3 拟合（尺度检查）：尺度 {scale}，ATE RMSE 为 {sim3} m，原为 {ate} m（消除 {removed} %）。",
        "scale_used": "估计轨迹按尺度 {value}{std} 评估（由 {by} 拟合）。",
        "warning": "警告",
        "meaning": {
            "trusted": "全部检查通过",
            "disabled": "已在设置中关闭",
            "uncertain": "偏差超过配置的上限",
            "not run": "步骤 1 不可信",
            "too little motion": "运动太小，无法观测",
            "unobservable": "运动使某一方向不可观",
            "large residual": "手眼残差超过上限",
            "no overlap": "时间戳没有重叠",
            "outside window": "最佳匹配在搜索窗口之外",
            "at window edge": "峰值位于搜索窗口边缘",
            "weak peak": "相关峰值太弱",
            "ambiguous": "第二峰几乎同样高（周期运动）",
        },
        "unobservable": "不可观",
        "infinite": "无界（某次重复估计离开了主峰）",
        "consistency": "一致性",
        "efficiency": "效率",
        "unavailable": "不可用",
        "nees": "NEES 姿态 {r:.3f}，位置 {p:.3f}（3 = 一致）；{o:.2f} % 的误差超出 ±3σ。",
        "eff": "平均帧时间 {m:.2f} ms（p95 {p:.2f} ms），传感器 {hz:g} Hz；{over:.1f} % 的帧超过传感器周期；EA-Drift {ea:.4f} %。",
        "fail": "失效区段",
        "start": "开始 [s，自首个匹配位姿起]",
        "end": "结束 [s，自首个匹配位姿起]",
        "none": "无",
        "figures": "图",
        "not_drawn": "未绘制（每个 bundle 含该图的数据；在本文件夹运行命令即可绘制）：",
        "off": "`report.figures` 已关闭",
        "not_flagged": "该案例未被标记：`report.figures: flagged` 只为有失效区段、整体失效或有指标警告的案例绘图",
        "all_cmd": "一次全部绘制：`epa fig --case ..`。",
        "no_bundle": "{name}：无数据（{why}）",
        "no_cov": "估计轨迹没有协方差",
        "pdf": "未绘制矢量 PDF（`report.pdf` 已关闭）；在本文件夹运行：`{cmd}`（其他图同理）。",
        "provenance": "来源",
        "prov_lead": "epica {version}。读取的输入：",
        "file": "文件",
        "bytes": "字节",
        "grid_prov": "整次运行的来源（所有依赖的版本、解析后的设置）：`{path}`；`epa verify` 校验哈希并重新生成数字。",
        "missing": "缺失",
        "every_key": "每条记录的每个数字：`metrics_summary.csv`（section, metric, value）与 `metrics.json`。",
        "say": zh_reasons.say,
        "sep": "；",
    },
}


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _f(v, digits: int = 4) -> str:
    x = _num(v)
    if math.isnan(x):
        return "–"
    if math.isinf(x):
        return "∞"
    return f"{x:.{digits}g}"


def _pair(rec: dict | None, stat: str, a: str = "trans_m", b: str = "rot_deg") -> str:
    rec = rec or {}
    ta, tb = rec.get(a) or {}, rec.get(b) or {}
    if not ta and not tb:
        return "–"
    return f"{_f(ta.get(stat))} / {_f(tb.get(stat), 3)}"


STATS = ("rmse", "mean", "median", "max")


def metrics_table(m: dict, T: dict) -> list[str]:
    """Rows ATE, ATE 2D, RPE per segment length, time RPE (over the record's ``metrics.time_delta``),
    drift rate per length; columns RMSE, mean, median, max."""
    lines = [
        f"| {T['row']} | " + " | ".join(T[s] for s in STATS) + " |",
        "|---|" + "---:|" * len(STATS),
    ]

    def row(label, cells):
        lines.append(f"| {label} | " + " | ".join(cells) + " |")

    if m.get("ate"):
        row(T["ate"], [_pair(m["ate"], s) for s in STATS])
    if m.get("ate_2d"):
        row(T["ate_2d"], [_pair(m["ate_2d"], s, "trans_xy_m", "yaw_deg") for s in STATS])
    segs = m.get("rpe_distance") or {}
    for L, rec in segs.items():
        row(T["rpe_seg"].format(L=L), [_pair(rec, s) for s in STATS])
    time_rpe = accuracy.time_rpe_in(m)
    if time_rpe is not None and time_rpe[1]:
        name, rec = time_rpe
        row(T["rpe_time"].format(delta=name.removesuffix("s")), [_pair(rec, s) for s in STATS])
    for L, rec in segs.items():
        trans = (rec or {}).get("trans_m") or {}
        length = _num(L)
        row(
            T["drift_rate"].format(L=L),
            [_f(_num(trans.get(s)) / length * 100, 3) if length > 0 else "–" for s in STATS],
        )
    return lines


def metric_warnings(doc: dict, say=_as_is) -> list[str]:
    """The warnings of a case: drift detection's (its thresholds do not fit the dataset), then the
    registered metrics' (their records' ``warning``), in registry order; each said by ``say``."""
    drift = doc.get("drift")
    warning = drift.get("warning") if isinstance(drift, dict) else None
    out = [f"drift: {say(warning)}"] if warning else []
    for metric in registry.REGISTRY:
        metrics = doc.get("metrics", {})
        record = metrics.get(metric.key) if metric.stage == "metrics" else doc.get(metric.stage)
        if isinstance(record, dict) and record.get("warning"):
            out.append(f"{metric.key}: {say(record['warning'])}")
    return out


def _meaning(status, T) -> str:
    return T["meaning"].get(str(status), str(status))


def _axes(values, factor: float, unit: str, T: dict) -> str:
    if not values:
        return "–"
    return (
        " / ".join(T["unobservable"] if v is None else f"{_num(v) * factor:.3g}" for v in values)
        + f" {unit}"
    )


def steps_lines(m: dict, T: dict) -> list[str]:
    sync, calib, align = m.get("sync", {}), m.get("calibrate", {}), m.get("alignment", {})
    s1 = sync.get("step1", {})
    std = _num(s1.get("std"))
    std_txt = T["infinite"] if math.isinf(std) else f"{std * 1000:.3f} ms"
    if s1.get("used"):
        one = T["s1_used"].format(
            ms=_num(s1.get("offset")) * 1000,
            status=s1.get("status"),
            meaning=_meaning(s1.get("status"), T),
            std=std_txt,
            peak=_num(s1.get("peak_corr")),
        )
    else:
        one = T["s1_not"].format(
            status=s1.get("status"),
            meaning=_meaning(s1.get("status"), T),
            reason=T["say"](s1.get("reason", "")),
            ms=_num(sync.get("offset_s")) * 1000,
        )
    ext = calib.get("extrinsic") or {}
    plan = calib.get("plan") or {}
    status = calib.get("step2_status")
    if ext and plan.get("apply_extrinsic"):
        two = T["s2_used"].format(
            rot=_num(ext.get("rotation_deg")),
            trans=_num(ext.get("translation_norm_m")),
            status=status,
            meaning=_meaning(status, T),
            rstd=_axes(ext.get("rotation_std_deg"), 1, "deg", T),
            tstd=_axes(ext.get("translation_std_m"), 1000, "mm", T),
        )
    else:
        found = (
            T["s2_found"].format(
                rot=_num(ext.get("rotation_deg")), trans=_num(ext.get("translation_norm_m"))
            )
            if ext
            else ""
        )
        # a position-only estimate's Step 2 is off for its own reason, not by the settings
        meaning = T["say"](calib.get("step2_reason")) or _meaning(status, T)
        two = found + T["s2_not"].format(
            status=status, meaning=meaning, reason=T["say"](plan.get("reason", ""))
        )
    three = step3_text(m, align, T)
    lines = [
        f"- **{T['step1']}**: {one}",
        f"- **{T['step2']}**: {two}",
        f"- **{T['step3']}**: {three}",
    ]
    if plan.get("fallback"):
        dropped = T["sep"].join(T["say"](d) for d in plan.get("dropped") or []) or "-"
        lines.append(f"- {T['fallback'].format(dropped=dropped)}")
    return lines


def step3_text(m: dict, align: dict, T: dict) -> str:
    """Step 3's line: the fit, the scale check beside it, and the scale the case was evaluated with."""
    three = T["s3"].format(
        method=align.get("method"),
        yaw=_num(align.get("yaw_deg")),
        scale=_num(align.get("scale")),
    )
    check = m.get("sim3_check") or {}
    if check.get("available") and "ate_se3" in check:
        ratio = check.get("ate_ratio")
        three += " " + T["s3_se3"].format(
            se3=_f(check["ate_se3"]["trans_m"]["rmse"]),
            sim3=_f((m.get("ate") or {}).get("trans_m", {}).get("rmse")),
            ratio="–" if ratio is None else f"{_num(ratio):.3g}",
        )
    elif check.get("available"):
        removed = check.get("error_removed")
        three += " " + T["s3_sim3"].format(
            scale=f"{_num(check['scale']):.4g}",
            sim3=_f(check["ate_sim3_rmse_m"]),
            ate=_f(check["ate_rmse_m"]),
            removed="–" if removed is None else f"{100 * _num(removed):.0f}",
        )
    used = check.get("evaluated_scale")
    if used:
        std = used.get("std")
        three += " " + T["scale_used"].format(
            value=f"{_num(used['value']):.6g}",
            std="" if std is None else f" ± {_num(std):.2g}",
            by=" + ".join(
                {"step2": "Step 2", "step3": "Step 3"}[k] for k in used["fitted_by"].split("+")
            ),
        )
    return three


def figure_lines(drawn, bundles, every: tuple, cfg_report: dict, T: dict) -> list[str]:
    """The drawn figures, then each one of ``every`` not drawn with the command that draws it."""
    lines = [f"![{n}](figures/{n}.png)" for n in drawn]
    missing = [n for n in every if n not in drawn]
    off = T["off"] if cfg_report.get("figures") == "none" else T["not_flagged"]
    if missing:
        lines += ["", T["not_drawn"], ""]
        for n in missing:
            if n in bundles:
                lines.append(f"- `epa fig bundles/{n}.json --out figures/{n}` ({off})")
            else:
                why = T["no_cov"] if n == "sigma3" else T["unavailable"]
                lines.append("- " + T["no_bundle"].format(name=n, why=why))
    if any(n in bundles for n in missing):
        lines += ["", T["all_cmd"]]
    if drawn and not cfg_report.get("pdf", True):
        cmd = f"epa fig bundles/{drawn[0]}.json --out figures/{drawn[0]} --pdf"
        lines += ["", T["pdf"].format(cmd=cmd)]
    return lines


def case_inputs(case_root: Path, load: dict, cfg: dict) -> list[dict]:
    """The case's input files with size and sha256: from ``provenance.json`` beside the case
    (``epa eval --out``), else from the load record and the grid's settings."""
    prov = case_root / provenance.PROVENANCE
    if prov.is_file():
        return json.loads(prov.read_text(encoding="utf-8")).get("inputs", [])
    est = load.get("est_path")
    if not est:
        return []
    ref = None
    if cfg.get("truth_dir") and load.get("ref_file"):
        ref = Path(cfg["truth_dir"]) / load["ref_file"]
    algorithm = case_root.parts[-3] if len(case_root.parts) >= 3 else None
    timing = provenance.run_timing(cfg, est, algorithm) if "load" in cfg else None
    paths = provenance.case_inputs(ref if ref is not None and ref.exists() else est, est, timing)
    return [provenance.file_record(p) for p in paths]


def provenance_lines(inputs: list[dict], grid_provenance: str | None, T: dict) -> list[str]:
    lines = [T["prov_lead"].format(version=__version__), ""]
    lines += [f"| {T['file']} | {T['bytes']} | sha256 |", "|---|---:|---|"]
    for rec in inputs:
        if rec.get("missing"):
            lines.append(f"| `{rec['path']}` | – | {T['missing']} |")
        else:
            lines.append(f"| `{rec['path']}` | {rec['size']} | `{rec['sha256']}` |")
    if grid_provenance:
        lines += ["", T["grid_prov"].format(path=grid_provenance)]
    return lines


def report_md(
    doc: dict,
    case_name: str,
    drawn: list[str],
    lang: str,
    fail: dict,
    *,
    t0: float,
    bundles=(),
    every_figure: tuple = (),
    cfg_report: dict | None = None,
    inputs: list[dict] | None = None,
    grid_provenance: str | None = None,
) -> str:
    T = TEXT[lang]
    m = doc.get("metrics", {})
    lines = lead_lines(doc, case_name, T)
    lines += drift_lines(doc.get("drift", {}), T)
    lines += [T["every_key"], "", f"## {T['steps']}", "", *steps_lines(m, T)]
    for key in ("consistency", "efficiency"):
        lines += ["", f"## {T[key]}", "", record_line(key, doc.get(key, {}), T)]
    lines += ["", f"## {T['fail']}", ""]
    lines += fail_lines(fail, T, t0)
    lines += ["", f"## {T['figures']}", ""]
    lines += figure_lines(drawn, set(bundles), every_figure, cfg_report or {}, T)
    lines += ["", f"## {T['provenance']}", ""]
    lines += provenance_lines(inputs or [], grid_provenance, T)
    return "\n".join(lines) + "\n"


def lead_lines(doc: dict, case_name: str, T: dict) -> list[str]:
    """The title, what was evaluated and how, the metric warnings and the metrics table."""
    m = doc.get("metrics", {})
    sync, align = m.get("sync", {}), m.get("alignment", {})
    warnings = metric_warnings(doc, T["say"])
    return [
        f"# {T['title']} {case_name}",
        "",
        T["lead"].format(
            source=m.get("eval_source"),
            n=m.get("n_matched"),
            length=_num(m.get("ref_length_m")),
        ),
        T["settings"].format(
            mode=sync.get("mode"),
            policy=sync.get("policy"),
            max_diff=sync.get("max_diff_s"),
            align=align.get("method"),
        ),
        "",
        *(f"**{T['warning']}**: {w}" for w in warnings),
        *([""] if warnings else []),
        f"## {T['metrics']}",
        "",
        T["metrics_note"],
        "",
        *metrics_table(m, T),
        "",
    ]


def drift_lines(d: dict, T: dict) -> list[str]:
    """The success rates and, by what the drift stage found, the drift-valid metrics table."""
    if not d:
        return []
    lines = [
        T["success"].format(
            d=_f(d.get("success_rate_distance_pct")),
            a=_f(d.get("success_auc_pct")),
            t=_f(d.get("success_rate_time_pct")),
        )
    ]
    if d.get("global_failed"):
        lines += ["", T["global_failed"]]
    elif d.get("n_fail_segments"):
        lines += ["", f"### {T['valid']}", "", *metrics_table(d.get("drift_valid") or {}, T)]
    else:
        lines += ["", T["no_fail"]]
    return lines + [""]


def record_line(key: str, rec: dict, T: dict) -> str:
    """The one line of the consistency or the efficiency record, or why it is unavailable."""
    if not rec.get("available"):
        return f"{T['unavailable']}: {T['say'](rec.get('reason', rec.get('failed', '')))}"
    if key == "consistency":
        return T["nees"].format(
            r=_num(rec.get("nees_rot_mean")),
            p=_num(rec.get("nees_pos_mean")),
            o=_num(rec.get("outside_3sigma_pct")),
        )
    return T["eff"].format(
        m=_num(rec.get("frame_time_mean_ms")),
        p=_num(rec.get("frame_time_p95_ms")),
        hz=_num(rec.get("sensor_rate_hz")),
        over=_num(rec.get("frames_over_period_pct")),
        ea=_num(rec.get("ea_drift")),
    )


def fail_lines(fail: dict, T: dict, t0: float) -> list[str]:
    """The fail segments, a row each, in seconds after ``t0`` (the first matched reference pose's
    stamp: the figures' zero; 07_drift/fail_segments.csv keeps the stamps), or the word for none."""
    starts = np.asarray(fail.get("t_start", []), float)
    if not starts.size:
        return [T["none"]]
    ends = np.asarray(fail["t_end"], float)
    return [f"| {T['start']} | {T['end']} |", "|---:|---:|"] + [
        f"| {s:.3f} | {e:.3f} |" for s, e in zip(starts - t0, ends - t0)
    ]
