"""error_comparison.txt in the seed's layout (mode epa)."""

from __future__ import annotations

import numpy as np

from epa.metrics.accuracy import segment_key
from epa.outputs.tables.cells import ate_cell, nanmean, pooled
from epa.outputs.tables.latex import build_tables
from epa.outputs.tables.results import CaseResult

RULE_SHORT = "=" * 38

RULE_LONG = "=" * 44


def _sources(counts: dict) -> str:
    """``epa=N, ov_eval=M``, and ``rpg=K`` where mode rpg evaluated any."""
    text = f"epa={counts['epa']}, ov_eval={counts['ov_eval']}"
    return text + (f", rpg={counts['rpg']}" if counts["rpg"] else "")


def report_text(
    grid: list[CaseResult],
    segments,
    decimals: int = 3,
    spread: str = "none",
    metrics=(),
    *,
    time_delta: float,
) -> str:
    """error_comparison.txt (mode epa): per dataset and algorithm, then every table (the time RPE's
    named after ``time_delta``)."""
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
    sources = {"epa": 0, "ov_eval": 0, "rpg": 0}
    for alg in sorted({c.algorithm for c in grid}):
        lines.append(f"[COMP]: processing {alg} algorithm")
        for ds in datasets:
            cases = [c for c in grid if c.algorithm == alg and c.dataset == ds]
            if not cases:
                continue
            runs = [c for c in cases if c.ok]
            lines.append(f"[COMP]: processing {alg} algorithm => {ds} dataset")
            ate = ate_cell(runs, False)
            if ate.values is None:
                lines.append("        ATE: - / - (0 runs)")
            else:
                ori = (
                    "-" if ate.values[0] is None else f"{ate.values[0]:.3f}"
                )  # position-only: none
                lines.append(
                    f"        ATE: mean_ori = {ori} | mean_pos = {ate.values[1]:.3f} ({len(runs)} runs)"
                )
            src = {"epa": 0, "ov_eval": 0, "rpg": 0}
            for c in runs:
                src[c.metrics.get("eval_source", "epa")] += 1
            for k in sources:
                sources[k] += src[k]
            lines.append(f"        eval_source: {_sources(src)}")
            if runs:
                for s in segments:
                    rot, trans = pooled(runs, "segments", False, s)
                    if rot.size:
                        lines.append(
                            f"        RPE: seg {segment_key(s)} - median_ori = {_ori(rot, np.median, 4)} | "
                            f"median_pos = {np.median(trans):.4f} ({rot.size} samples)"
                        )
                    else:
                        lines.append(
                            f"        RPE: seg {segment_key(s)} - no segment this long (0 samples)"
                        )
                rot, trans = pooled(runs, "time", False)
                if rot.size:
                    lines.append(
                        f"        RPE time 1s - mean_ori = {_ori(rot, np.mean, 3)} | mean_pos = {trans.mean():.3f}"
                        f" ({rot.size} samples)"
                    )
                sr_d = nanmean(c.drift["success_rate_distance_pct"] for c in runs)
                sr_t = nanmean(c.drift["success_rate_time_pct"] for c in runs)
                lines.append(f"        SR - distance = {sr_d:.2f}% | time = {sr_t:.2f}%")
            for c in cases:
                if c.status != "ok":
                    lines.append(f"        {c.run}: {c.status}")
    lines += [
        RULE_LONG,
        f"TOOL SOURCE: {_sources(sources)}",
        RULE_LONG,
    ]
    for _, title, rows, _ in build_tables(
        grid, segments, decimals, metrics, spread, text=True, time_delta=time_delta
    ):
        lines += [
            RULE_LONG,
            title,
            RULE_LONG,
            *(r.replace(" $\\pm$ ", " ± ") for r in rows),
            RULE_LONG,
        ]
    return "\n".join(lines) + "\n"


def _ori(rot: np.ndarray, of, decimals: int) -> str:
    """A rotation statistic; ``-`` where every error is NaN: a position-only estimate has none."""
    return "-" if np.isnan(rot).all() else f"{of(rot):.{decimals}f}"
