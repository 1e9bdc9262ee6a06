"""The marks of a table cell: how the cases it holds were evaluated, when that is not one recipe.

A cell is marked (a superscript letter in the .tex and the text tables, a footnote under the table,
the letters in the CSV's ``marks`` column) when its cases

- ``e``: were evaluated by different sources (``eval_source``: epa, and the ov_eval way a case falls
  back to when Step 1 or 2 is not trusted);
- ``a``: were aligned by different Step 3 methods (``05_align/transform.json`` ``method``);
- ``f``: hold a flagged case: drift's record or a registered metric's carries a ``warning`` (the
  scale check's, the drift thresholds' misfit, any other), even a cell of one case.

Every letter is of the cases a cell pools: a dataset's runs, or every run of the algorithm for its
Average and the per-segment and per-algorithm tables. Rows with Sim3-aligned cases are named in a
footnote with their mean fitted scale, not marked cell by cell (a grid of monocular systems would
mark every cell).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from epa.metrics import registry

SOURCES, ALIGNMENTS, FLAGGED = "e", "a", "f"
ORDER = (SOURCES, ALIGNMENTS, FLAGGED)


@dataclass(frozen=True)
class Evaluation:
    """How one case was evaluated, as its records say."""

    source: str  # metrics.json eval_source
    fallback: bool  # the ov_eval way because Step 1 or 2 was not trusted (not by choice)
    method: str | None  # Step 3's method (se3, sim3, posyaw, none)
    scale: float | None  # a Sim3 case's scale (Step 2's times Step 3's where both fitted one)
    warnings: tuple[tuple[str, str], ...]  # (metric key, warning) of every metric that warned


def evaluation(c) -> Evaluation:
    """A case's :class:`Evaluation`, made once per case (a cell of every table asks for it)."""
    kept = c._evaluation
    if kept is None:
        m = c.metrics
        align = m.get("alignment") or {}
        plan = (m.get("calibrate") or {}).get("plan") or {}
        # the scale the case was evaluated with: Step 2's times Step 3's (a monocular estimate's
        # Step 3 scale is about 1 once Step 2 solved it), else Step 3's Sim3 scale
        used = ((m.get("sim3_check") or {}).get("evaluated_scale") or {}).get("value")
        scale = align.get("scale") if align.get("method") == "sim3" else None
        scale = used if scale is not None and used is not None else scale
        warned = [("drift", str(c.drift["warning"]))] if c.drift.get("warning") else []
        for metric in registry.REGISTRY:
            record = c.record_of(metric)
            if isinstance(record, dict) and record.get("warning"):
                warned.append((metric.key, str(record["warning"])))
        kept = Evaluation(
            source=m.get("eval_source", "epa"),
            fallback=bool(plan.get("fallback")),
            method=align.get("method"),
            scale=None if scale is None else float(scale),
            warnings=tuple(warned),
        )
        c._evaluation = kept
    return kept


def of_cases(cases) -> str:
    """The marks of a cell holding ``cases`` (those with a result), as letters in :data:`ORDER`
    joined by commas; "" for none."""
    if not cases:
        return ""
    first = evaluation(cases[0])
    found = set()
    for c in cases:  # one pass: every table's every cell asks (0.3 s of 1,000 cases' tables)
        e = c._evaluation or evaluation(c)
        if e.source != first.source:
            found.add(SOURCES)
        if e.method != first.method:
            found.add(ALIGNMENTS)
        if e.warnings:
            found.add(FLAGGED)
    return ",".join(k for k in ORDER if k in found)


def tex(marks: str) -> str:
    """A cell's marks after its numbers in LaTeX."""
    return r"\textsuperscript{" + marks + "}" if marks else ""


def notes(cells_by_row: dict[str, list]) -> list[tuple[str, str]]:
    """(letter, what it means) for each letter the table's cells carry, in :data:`ORDER`, then
    ("", the rows with Sim3-aligned cases and their mean scale) where there are any.
    ``cells_by_row``: each row's algorithm and its cells (``marks``, ``cases``)."""
    used: dict[str, dict[int, object]] = {}  # letter -> the cases of the cells marked so, once
    sim3: dict[str, dict[int, float]] = {}  # algorithm -> the scale of each Sim3-aligned case
    for alg, cells in cells_by_row.items():
        for cell in cells:
            for c in cell.cases or ():
                if (scale := evaluation(c).scale) is not None:
                    sim3.setdefault(alg, {})[id(c)] = scale
            for k in filter(None, (cell.marks or "").split(",")):
                used.setdefault(k, {}).update((id(c), c) for c in cell.cases or ())
    out = []
    for k in ORDER:
        if k not in used:
            continue
        evals = [evaluation(c) for c in used[k].values()]
        if k == SOURCES:
            sources = ", ".join(sorted({e.source for e in evals}))
            what = (
                f"pools cases evaluated differently ({sources}; ov_eval: Step 1 or 2 not trusted,"
                " evaluated without them)"
            )
        elif k == ALIGNMENTS:
            methods = ", ".join(sorted({str(e.method) for e in evals}))
            what = f"pools cases of different Step 3 alignments ({methods})"
        else:
            keys = ", ".join(sorted({key for e in evals for key, _ in e.warnings}))
            what = (
                f"holds a flagged case: a metric warned ({keys}; see summary.csv's notes and the"
                " case report)"
            )
        out.append((k, what))
    if sim3:
        rows = ", ".join(f"{alg} {np.mean(list(s.values())):.3f}" for alg, s in sim3.items())
        out.append(("", f"Sim3-aligned rows (mean Sim3 scale of their cases): {rows}"))
    return out
