"""error_comparison.txt in EPA's layout (mode epa)."""

from __future__ import annotations

import re

import numpy as np

from epa.metrics.accuracy import segment_key, time_rpe_name
from epa.outputs.tables import marks
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
    datasets = sorted({c.dataset for c in grid})
    loads: dict[str, dict] = {}  # each dataset's first loaded reference, in one pass
    for c in grid:
        if c.load and c.dataset not in loads:
            loads[c.dataset] = c.load
    lines = [_reference_line(loads.get(ds), ds) for ds in datasets] + [RULE_SHORT]
    sources = {"epa": 0, "ov_eval": 0, "rpg": 0}
    # every case of a cell in grid order, grouped once: a scan of the grid for every cell made this
    # quadratic (12.5 s of the tables rule's 72 s on 10,000 cases)
    by_cell: dict[tuple[str, str], list[CaseResult]] = {}
    for c in grid:
        by_cell.setdefault((c.algorithm, c.dataset), []).append(c)
    for alg in sorted({c.algorithm for c in grid}):
        lines.append(f"[COMP]: processing {alg} algorithm")
        for ds in datasets:
            cases = by_cell.get((alg, ds), [])
            if cases:
                lines += _algorithm_on_dataset(cases, segments, time_delta, sources)
    lines += [
        RULE_LONG,
        f"TOOL SOURCE: {_sources(sources)}",
        RULE_LONG,
    ]
    for table in build_tables(
        grid, segments, decimals, metrics, spread, text=True, time_delta=time_delta
    ):
        lines += [
            RULE_LONG,
            table.title,
            RULE_LONG,
            *(_MARKS.sub(r" [\1]", r.replace(" $\\pm$ ", " ± ")) for r in table.rows),
            *((f"[{k}] " if k else "") + text for k, text in table.notes),
            RULE_LONG,
        ]
    return "\n".join(lines + count_lines(grid)) + "\n"


_MARKS = re.compile(r"\\textsuperscript\{([a-z,]+)\}")  # a cell's marks (marks.tex)


def count_lines(grid: list[CaseResult]) -> list[str]:
    """The end of error_comparison.txt: how many cases fell back to the ov_eval way and how many a
    metric flagged, each only when there are any (then a rule)."""
    evals = [marks.evaluation(c) for c in grid if c.ok]
    fallback = sum(e.fallback for e in evals)
    flagged = sum(bool(e.warnings) for e in evals)
    out = []
    if fallback:
        out.append(
            f"FELL BACK (STEP 1 OR 2 NOT TRUSTED, EVALUATED THE OV_EVAL WAY): {fallback} of"
            f" {len(evals)} cases with a result"
        )
    if flagged:
        out.append(
            f"FLAGGED (A METRIC WARNED, SEE summary.csv NOTES): {flagged} of {len(evals)} cases"
            " with a result"
        )
    return out + [RULE_LONG] if out else []


def _reference_line(info: dict | None, dataset: str) -> str:
    if not info:
        return f"[COMP]: reference of {dataset} could not be loaded"
    return (
        f"[COMP]: {info['n_ref']} poses in {info['ref_file']} => length of"
        f" {info['ref_length_m']:.2f} meters"
    )


def _algorithm_on_dataset(
    cases: list[CaseResult], segments, time_delta: float, sources: dict
) -> list[str]:
    """One algorithm's block for one dataset; adds its runs' evaluation sources to ``sources``."""
    c0 = cases[0]
    runs = [c for c in cases if c.ok]
    lines = [f"[COMP]: processing {c0.algorithm} algorithm => {c0.dataset} dataset"]
    ate = ate_cell(runs, False)
    if ate.values is None:
        lines.append("        ATE: - / - (0 runs)")
    else:
        # a position-only estimate has no orientation error
        ori = "-" if ate.values[0] is None else f"{ate.values[0]:.3f}"
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
        lines += _relative_lines(runs, segments, time_delta)
    lines += [f"        {c.run}: {c.status}" for c in cases if c.status != "ok"]
    return lines


def _relative_lines(runs: list[CaseResult], segments, time_delta: float) -> list[str]:
    lines = []
    for s in segments:
        rot, trans = pooled(runs, "segments", False, s)
        if rot.size:
            lines.append(
                f"        RPE: seg {segment_key(s)} - median_ori = {_ori(rot, np.median, 4)} | "
                f"median_pos = {np.median(trans):.4f} ({rot.size} samples)"
            )
        else:
            lines.append(f"        RPE: seg {segment_key(s)} - no segment this long (0 samples)")
    rot, trans = pooled(runs, "time", False)
    if rot.size:
        lines.append(
            f"        RPE time {time_rpe_name(time_delta)} - mean_ori = {_ori(rot, np.mean, 3)} |"
            f" mean_pos = {trans.mean():.3f} ({rot.size} samples)"
        )
    sr_d = nanmean(c.drift["success_rate_distance_pct"] for c in runs)
    sr_t = nanmean(c.drift["success_rate_time_pct"] for c in runs)
    lines.append(f"        SR - distance = {sr_d:.2f}% | time = {sr_t:.2f}%")
    return lines


def _ori(rot: np.ndarray, of, decimals: int) -> str:
    """A rotation statistic; ``-`` where every error is NaN: a position-only estimate has none."""
    return "-" if np.isnan(rot).all() else f"{of(rot):.{decimals}f}"
