"""The tables rule: read every case, write every table."""

from __future__ import annotations

import csv
import logging
from pathlib import Path

from epa import readers
from epa.artifacts import files
from epa.core.errors import EpaError
from epa.metrics import accuracy, registry
from epa.outputs.tables import rpg as rpg_tables
from epa.outputs.tables import tidy
from epa.outputs.tables.across_runs import write_across_runs
from epa.outputs.tables.comparison import comparison_tex, comparison_text, comparisons
from epa.outputs.tables.latex import build_tables, restyle, tex_document
from epa.outputs.tables.ov_eval import ov_eval_text
from epa.outputs.tables.results import (
    CaseResult,
    collect,
    failed_cases,
    has_result,
    segments_by_dataset,
)
from epa.outputs.tables.summary import (
    SUCCESS_CURVE_COLUMNS,
    records_csv,
    success_curves,
    summary_csv,
)
from epa.outputs.tables.text import report_text

log = logging.getLogger(__name__)


def enabled_metrics(cfg: dict) -> tuple:
    return tuple(m for m in registry.REGISTRY if m.enabled(cfg))


def table_names(cfg: dict) -> tuple[str, ...]:
    """The .tex files the tables rule writes under these settings."""
    return cell_tables(cfg) + mode_tables(cfg)


def cell_tables(cfg: dict) -> tuple[str, ...]:
    """The tables whose cells are also a tables/<name>.csv (all but the mode's own)."""
    return accuracy.base_tables(cfg["metrics"]["time_delta"]) + tuple(
        t.name for m in enabled_metrics(cfg) for t in m.tables
    )


def mode_tables(cfg: dict) -> tuple[str, ...]:
    """The .tex files of the mode's own summary (mode rpg: rpg's tables)."""
    return rpg_tables.TABLES if cfg.get("mode") == "rpg" else ()


def mode_files(cfg: dict) -> tuple[str, ...]:
    """The text files of the mode's own summary, relative to the results folder."""
    return rpg_tables.FILES if cfg.get("mode") == "rpg" else ()


def write_all(
    grid: list[CaseResult], results_dir, cfg: dict, idle_truths: dict | None = None
) -> None:
    """error_comparison.txt, summary.csv and tables/<name>.tex under ``results_dir``."""
    results_dir = Path(results_dir)
    segments = grid_segments(grid, cfg["metrics"]["segments"])
    decimals = cfg["tables"]["decimals"]
    spread = cfg["tables"]["spread"]
    style = cfg["tables"]["style"]
    time_delta = cfg["metrics"]["time_delta"]  # names the time RPE's tables and columns
    text = (
        ov_eval_text(grid, segments, idle_truths)
        if cfg.get("mode") == "ov_eval"
        else report_text(
            grid, segments, decimals, spread, enabled_metrics(cfg), time_delta=time_delta
        )
    )
    files.write_text(results_dir / "error_comparison.txt", text)
    files.write_text(
        results_dir / "summary.csv",
        summary_csv(grid, segments, time_delta, enabled_metrics(cfg)),
    )
    built = build_tables(
        grid, segments, decimals, metrics=enabled_metrics(cfg), spread=spread, time_delta=time_delta
    )
    for table in built:
        tex = tex_document(table.title, table.rows, table.ncols, table.note_rows())
        files.write_text(results_dir / "tables" / f"{table.name}.tex", restyle(tex, style))
        files.write_text(
            results_dir / "tables" / f"{table.name}.csv", tidy.table_csv(table, spread)
        )
    files.write_text(results_dir / "cells.csv", tidy.cells_csv(tidy.cell_rows(built, spread, grid)))
    files.write_text(
        results_dir / "success_curves.csv", records_csv(SUCCESS_CURVE_COLUMNS, success_curves(grid))
    )
    pairs = comparisons(grid, segments)
    files.write_text(results_dir / "comparison.txt", comparison_text(pairs))
    files.write_text(results_dir / "comparison.tex", restyle(comparison_tex(pairs), style))
    write_across_runs(grid, results_dir)
    if cfg.get("mode") == "rpg":
        rpg_tables.write_rpg_tables(grid, results_dir, cfg, files.write_text)


def grid_segments(grid: list[CaseResult], configured) -> list[float]:
    """The segment lengths of the tables' columns: the datasets' one list where they share it,
    else every length of any dataset in ascending order (a cell pools the datasets that have it)."""
    lists = {tuple(v) for v in segments_by_dataset(grid).values()}
    if len(lists) == 1:
        return list(lists.pop())
    if not lists:
        return [] if isinstance(configured, str) else list(configured)
    return sorted({length for lengths in lists for length in lengths})


def make(
    keys: list[str], results_dir, cfg: dict, idle_truths: dict | None = None, workers: int = 1
) -> list[tuple[str, str]]:
    """The tables rule: read every case, write every table; returns the failed cases.
    ``idle_truths`` ({dataset: path}, mode ov_eval): references without any run, read here for the
    [COMP] line ov_eval prints for every reference. ``workers``: processes that read the cases."""
    grid = collect(keys, results_dir, workers)
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

    ref = readers.read(path, readers.options(cfg, "reference", dataset=dataset))
    return {"ref_file": Path(path).name, "n_ref": len(ref), "ref_length_m": ref.length()}


def failure_report(summary_path, most: int = 20) -> str:
    """A short end-of-run list of the cases without a result, then per algorithm how many cases fell
    back to the ov_eval way or were flagged, and each flagged case's warning (which names the setting
    that fixes it), from cells.csv beside summary.csv; empty when every case has a result and none
    fell back or is flagged. With flags but no failure it starts with "every case has a result"."""
    with open(summary_path, encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    bad = [r for r in rows if not has_result(r["status"])]
    lines = []
    if bad:
        lines = [f"epica: {len(bad)} of {len(rows)} cases have no result (see {summary_path}):"]
        lines += [
            f"  {r['algorithm']}/{r['dataset']}/{r['run']}: {r['status']}" for r in bad[:most]
        ]
        if len(bad) > most:
            lines.append(f"  ... and {len(bad) - most} more")
    marked = _marked_report(Path(summary_path).parent, rows, most)
    if marked and not bad:
        lines = [f"epica: every case has a result ({len(rows)} cases)"]
    return "\n".join(lines + marked)


def _marked_report(results_dir: Path, rows: list[dict], most: int) -> list[str]:
    """The fallbacks and flags of the end-of-run summary (cells.csv's ``cases`` rows); the
    warnings of at most ``most`` flagged cases, read from their records."""
    path = results_dir / "cells.csv"
    if not path.is_file():  # tables written before cells.csv existed
        return []
    counts: dict[str, dict[str, int]] = {}
    flagged_cells = []
    with open(path, encoding="utf-8", newline="") as fh:
        for r in csv.DictReader(fh):
            if r["metric"] != "cases" or r["statistic"] not in ("fallback", "flagged"):
                continue
            n = int(r["value"])
            by = counts.setdefault(r["algorithm"], {"fallback": 0, "flagged": 0})
            by[r["statistic"]] += n
            if r["statistic"] == "flagged" and n:
                flagged_cells.append((r["algorithm"], r["dataset"]))
    cases: dict[str, int] = {}
    for r in rows:
        cases[r["algorithm"]] = cases.get(r["algorithm"], 0) + 1
    lines = []
    for alg, by in sorted(counts.items()):
        if by["fallback"] or by["flagged"]:
            lines.append(
                f"  {alg}: {by['fallback']} of {cases.get(alg, 0)} cases fell back to the ov_eval"
                f" way (Step 1 or 2 not trusted), {by['flagged']} flagged"
            )
    if not lines:
        return []
    out = ["epica: cases evaluated without Steps 1-2 or flagged (marked in the tables; cells.csv):"]
    out += lines
    warned = _flagged_warnings(results_dir, rows, set(flagged_cells), most + 1)
    # a warning names the setting that fixes it; here, for the case's own algorithm
    out += [
        f"  {key}: {text.replace('<algorithm>', key.split('/')[0])}" for key, text in warned[:most]
    ]
    if len(warned) > most:
        total = sum(by["flagged"] for by in counts.values())
        out.append(f"  ... and {total - most} more flagged")
    return out


def _flagged_warnings(results_dir: Path, rows: list[dict], cells: set, most: int) -> list:
    """(case key, "metric: warning") of the first ``most`` flagged cases of ``cells``."""
    from epa.artifacts.case import Case, CaseFolder

    out = []
    for r in rows:
        if (r["algorithm"], r["dataset"]) not in cells or not has_result(r["status"]):
            continue
        key = f"{r['algorithm']}/{r['dataset']}/{r['run']}"
        folder = CaseFolder.of(results_dir, Case.from_key(key))
        metrics, failed = folder.record_or_failure("metrics", "metrics.json")
        if folder.has("drift", "drift.json"):  # its thresholds do not fit the dataset
            drift, _ = folder.record_or_failure("drift", "drift.json")
            if isinstance(drift, dict) and drift.get("warning"):
                out.append((key, f"drift: {drift['warning']}"))
        for metric in registry.REGISTRY:
            if metric.stage == "metrics":
                record = (metrics or {}).get(metric.key) if failed is None else None
            elif folder.has(metric.stage, f"{metric.stage}.json"):
                record, _ = folder.record_or_failure(metric.stage, f"{metric.stage}.json")
            else:
                record = None
            if isinstance(record, dict) and record.get("warning"):
                out.append((key, f"{metric.key}: {record['warning']}"))
        if len(out) >= most:
            break
    return out
