"""results/comparison.txt and .tex: every pair of algorithms compared."""

from __future__ import annotations

import numpy as np

from epa.metrics import statistics
from epa.metrics.accuracy import segment_key
from epa.outputs.tables.cells import nanmean, num, ok_runs, run_ate, stat
from epa.outputs.tables.latex import latex_escape, tex_document
from epa.outputs.tables.results import CaseResult
from epa.outputs.tables.text import RULE_LONG


def _run_rpe(c, segments) -> float:
    """One run's distance RPE: the mean over the segment lengths of its mean translation error (m)."""
    return nanmean(
        stat(c.metrics, "rpe_distance", segment_key(s), "trans_m", "mean") for s in segments
    )


def comparisons(grid: list[CaseResult], segments) -> list[tuple[str, str, dict]]:
    """Every pair of algorithms compared on the ATE (translation RMSE per run) of the datasets both
    have successful runs on (see :func:`epa.metrics.statistics.compare`)."""
    algs = sorted({c.algorithm for c in grid})

    def by_dataset(alg, of):
        out: dict[str, list[float]] = {}
        for c in ok_runs(grid, alg):
            v = num(of(c))
            if np.isfinite(v):
                out.setdefault(c.dataset, []).append(v)
        return out

    ate = {a: by_dataset(a, lambda c: run_ate(c)[1]) for a in algs}
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
