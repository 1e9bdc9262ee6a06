"""error_comparison.txt in mode ov_eval: what ov_eval's error_comparison prints, byte for byte."""

from __future__ import annotations

import numpy as np

from epa.metrics import ate_2d
from epa.outputs.tables.cells import ok_runs, pooled, run_ate
from epa.outputs.tables.latex import latex_escape
from epa.outputs.tables.results import CaseResult
from epa.outputs.tables.text import RULE_LONG, count_lines


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
            runs = ok_runs(grid, alg, ds)
            if not runs:
                out += f"{RED}[COMP]: {alg} dataset does not have any runs for {ds}!!!!!\n{RESET}"
                continue
            for c in runs:
                out += _ov_eval_warnings(c)
            for name, of in (
                ("ate", run_ate),
                ("ate_2d", lambda c: ate_2d.per_run(c.record_of(ate_2d.METRIC))),
            ):
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
        row, runs = latex_escape(alg), ok_runs(grid, alg)
        for seg in segments:
            rot, trans = pooled(runs, "segments", False, seg)
            row += f" & {rot.mean():.3f} / {trans.mean():.3f}" if rot.size else " & - / -"
        lines.append(row + " \\\\")
    lines.append(RULE_LONG)
    # epica's own lines after ov_eval's, only where a case fell back or is flagged
    return out + "\n".join(lines + count_lines(grid)) + "\n"
