"""Cost of reports and figures against the metric stages (issue: reports and figures). Figures go in
docs/performance.md and the closing note, never in a timed test.

    python benchmarks/figures.py [--out DIR]

1. The bundled 18-case example (config/config.yaml's settings), `snakemake --cores 2`: job time
   summed from the `benchmark:` files, for the metric stages (load ... efficiency), the per-case
   `report` rule and the grid's `figures` rule; wall time with and without per-case reports.
2. In one process: the time to build each case figure's bundle and to draw each kind (median over
   the example's cases, after matplotlib is imported), and bytes per case folder.
3. With ``--grid RESULTS`` (a grid's results folder, its cases' reports written) only: the grid
   figures (two forked workers), CPU and wall seconds, without and with the per-dataset figures;
   then one dataset's cost in one process once its figures' layouts are kept (what each further
   dataset of a large grid costs a worker): reading its cases, and drawing its two figures as PNG
   and PDF with their bundles, CPU seconds, best of 3 passes over every dataset
   (docs/performance.md, "The per-dataset figures").
"""

from __future__ import annotations

import argparse
import csv
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [
    sys.executable,
    "-m",
    "snakemake",
    "-s",
    str(ROOT / "Snakefile"),
    "--profile",
    str(ROOT / "profiles/default"),
]
METRIC_STAGES = (
    "load",
    "crop",
    "sync",
    "calibrate",
    "align",
    "metrics",
    "drift",
    "consistency",
    "efficiency",
)


def job_seconds(results: Path) -> dict[str, float]:
    """Seconds per rule, summed over its jobs' benchmark files."""
    out: dict[str, float] = defaultdict(float)
    for tsv in results.rglob("benchmarks/*.tsv"):
        with open(tsv) as fh:
            row = next(csv.DictReader(fh, delimiter="\t"))
        out[tsv.stem] += float(row["s"])
    return dict(out)


def run_example(cwd: Path, per_case: bool) -> tuple[float, dict[str, float]]:
    cfg = yaml.safe_load((ROOT / "config/config.yaml").read_text())
    cfg.update(
        truth_dir=str(cwd / "sim/truth"),
        algorithms_dir=str(cwd / "sim/algorithms"),
        results_dir="results",
    )
    cfg["report"] = {"per_case": per_case}
    (cwd / "cfg.yaml").write_text(yaml.safe_dump(cfg))
    shutil.rmtree(cwd / "results", ignore_errors=True)
    shutil.rmtree(cwd / ".snakemake", ignore_errors=True)
    t0 = time.perf_counter()
    subprocess.run(
        [
            *SNAKEMAKE,
            "--directory",
            str(cwd),
            "--configfile",
            str(cwd / "cfg.yaml"),
            "--cores",
            "2",
            "--quiet",
        ],
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - t0, job_seconds(cwd / "results")


def in_process(results: Path) -> dict:
    from epa.artifacts.case import CaseFolder
    from epa.outputs import figures, report
    from epa.workflow.chain import CaseData

    figures._setup("paper")  # import matplotlib outside the timings
    build, draw, size = [], defaultdict(list), []
    with tempfile.TemporaryDirectory() as tmp:
        for case_root in sorted(results.glob("cases/*/*/*")):
            case = CaseFolder(case_root)
            t0 = time.perf_counter()
            bundles = report.case_bundles(CaseData(case))
            build.append(time.perf_counter() - t0)
            for name, b in bundles.items():
                t0 = time.perf_counter()
                figures.render(b, Path(tmp) / name, formats=("png",))
                draw[name].append(time.perf_counter() - t0)
            size.append(
                sum(p.stat().st_size for p in (case_root / "10_report").rglob("*") if p.is_file())
            )
    return {
        "bundles_s": statistics.median(build),
        "draw_s": {k: round(statistics.median(v), 3) for k, v in draw.items()},
        "report_folder_mb": {"median": statistics.median(size) / 1e6, "max": max(size) / 1e6},
    }


def grid_figures(results: Path, workers: int = 2, repeat: int = 2) -> dict:
    """The grid figures of a results folder without and with the per-dataset figures: (wall, CPU)
    seconds of each repetition, CPU including the forked workers'."""
    import resource

    from epa.outputs import figures, report

    def cpu():
        me, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
        return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime

    figures.prepare("wide")
    segments = yaml.safe_load((results / "config.resolved.yaml").read_text())["metrics"]["segments"]
    out: dict = {False: [], True: []}
    for _ in range(repeat):
        for per_dataset in (False, True):
            t, c = time.perf_counter(), cpu()
            report.write_grid_figures(results, segments, workers=workers, per_dataset=per_dataset)
            out[per_dataset].append((round(time.perf_counter() - t, 2), round(cpu() - c, 2)))
    return {"five figures": out[False], "with the per-dataset figures": out[True]}


def per_dataset(results: Path, repeat: int = 3) -> dict:
    """CPU seconds a dataset costs in one process, its layouts kept: reading its cases' files into
    its two bundles, and drawing them (PNG and PDF, bundles written); best of ``repeat`` passes."""
    import resource

    from epa.outputs import dataset_figures, figures, tables

    def cpu():
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    figures.prepare("wide")
    cells = dataset_figures.cells_by_dataset(
        dataset_figures.read_summary(results / "summary.csv"), tables.has_result
    )
    read, draw = [], []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for name, b in dataset_figures.dataset_bundles(results, *cells[0]).items():
            figures.render(b, out / name, style="wide")  # the layouts, made once
        for _ in range(repeat):
            t_read = t_draw = 0.0
            for d, here in cells:
                c = cpu()
                bundles = dataset_figures.dataset_bundles(results, d, here)
                t_read, c = t_read + cpu() - c, cpu()
                for name, b in bundles.items():
                    figures.write_bundle(out / "bundles" / f"{name}.json", b)
                    figures.render(b, out / name, style="wide")
                t_draw += cpu() - c
            read.append(t_read / len(cells))
            draw.append(t_draw / len(cells))
    cases = sum(len(runs) for _, here in cells for _, _, runs in here) / len(cells)
    return {
        "datasets": len(cells),
        "cases per dataset": cases,
        "read s": round(min(read), 4),
        "draw s": round(min(draw), 4),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="working folder (default: a temporary one)")
    ap.add_argument("--grid", type=Path, help="only time the grid figures of this results folder")
    args = ap.parse_args()
    if args.grid:
        print("grid figures (wall s, CPU s):", grid_figures(args.grid))
        print("one dataset, in one process (CPU s):", per_dataset(args.grid))
        return
    tmp = args.out or Path(tempfile.mkdtemp(prefix="epa-figbench-"))
    tmp.mkdir(parents=True, exist_ok=True)
    from epa import simulate

    cwd = tmp / "example"
    if not (cwd / "sim").exists():
        simulate.simulate(cwd / "sim")
    wall_off, _ = run_example(cwd, per_case=False)
    wall_on, jobs = run_example(cwd, per_case=True)
    metric = sum(jobs.get(s, 0.0) for s in METRIC_STAGES)
    print(
        f"example --cores 2: {wall_off:.1f} s without per-case reports, {wall_on:.1f} s with them"
    )
    print(
        f"job time: metric stages {metric:.1f} s; report {jobs.get('report', 0):.1f} s; "
        f"figures (grid) {jobs.get('figures', 0):.1f} s; tables {jobs.get('tables', 0):.1f} s"
    )
    print("in process:", in_process(cwd / "results"))
    if not args.out:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
