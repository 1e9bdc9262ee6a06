"""Grid execution benchmark (issue: grid execution at the cost of the work). Figures go in
docs/performance.md and the closing note, never in a timed test.

    python benchmarks/grid.py [--skip-evo] [--skip-large] [--no-check] [--cases 1000,10000] [--out DIR]

1. The 52-case EuRoC grid from ../shared/data (rpg vio_mono, vio_stereo, vislam_rp, vislam_ba x10,
   OpenVINS MH_01 and MH_04): `snakemake --cores 2`, the library in a loop (`epa eval`, two at a
   time), and `evo_ape` + `evo_rpe` in a loop (two at a time), on the same cases.
2. The bundled 18-case example: wall time at --cores 1 and 2, the dry run, the per-stage-job
   overhead = (wall at --cores 1 - dry run - the stages' own time in one process) / stage jobs,
   and the --cores 2 run's timeline (when the first job started, the stages ended, each
   once-per-grid rule ended).
3. Simulated grids of short cases (default 1,000 and 10,000): dry run, full run on 2 cores, peak
   memory of the Snakemake process, and a check that the tables equal per-case execution (every
   stage run case by case in one process, then the same table code).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("EPA_SHARED_DATA", ROOT.parent / "shared" / "data"))


def tool(name: str) -> str:
    """A command as a virtual environment runs it: the console script beside this interpreter (not a
    version manager's shim found first on PATH, pyenv's costing 0.05-0.1 s a call here), else the name.
    Every tool compared (epa, evo, snakemake) is started the same way."""
    console = Path(sys.executable).with_name(name)
    return str(console) if console.exists() else name


# the `snakemake` command users run (its console script, not `python -m snakemake`: multiprocessing
# treats the two differently in the worker pool, see epa.workflow.jobs._without_main_module)
_SNAKEMAKE = tool("snakemake")
SNAKEMAKE = [
    *([_SNAKEMAKE] if os.path.isabs(_SNAKEMAKE) else [sys.executable, "-m", "snakemake"]),
    "-s",
    str(ROOT / "Snakefile"),
]


def run(cmd, cwd=None, check=True) -> tuple[float, int, str]:
    """Wall seconds and peak RSS (MB, the largest process) of a command."""
    t0 = time.perf_counter()
    out = subprocess.run(
        ["/usr/bin/time", "-f", "%M", *cmd], cwd=cwd, capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    if check and out.returncode != 0:
        raise SystemExit(
            f"failed: {' '.join(map(str, cmd))}\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}"
        )
    rss_kb = int(out.stderr.strip().splitlines()[-1]) if out.stderr.strip() else 0
    return wall, rss_kb // 1024, out.stdout + out.stderr


def smk(cwd, *args):
    return run([*SNAKEMAKE, "--directory", str(cwd), "--configfile", str(cwd / "cfg.yaml"), *args])


def write_cfg(cwd: Path, extra: str = "") -> None:
    (cwd / "cfg.yaml").write_text(
        f"truth_dir: truth\nalgorithms_dir: algorithms\nresults_dir: results\n{extra}"
    )


# ----------------------------------------------------------------------------- the EuRoC grid
def euroc_grid(cwd: Path) -> list[tuple[Path, Path]]:
    """The 52 real cases, laid out as a grid (files linked, not copied into the project)."""
    gt = DATA / "rpng_open_vins/ov_data/euroc_mav"
    rpg = DATA / "uzh-rpg_rpg_trajectory_evaluation/results"
    seqs = {
        "MH_01": "MH_01_easy",
        "MH_03": "MH_03_medium",
        "MH_04": "MH_04_difficult",
        "MH_05": "MH_05_difficult",
    }
    (cwd / "truth").mkdir(parents=True)
    for short, name in seqs.items():
        os.symlink(gt / f"{name}.txt", cwd / "truth" / f"{short}.txt")
    runs: dict[tuple[str, str, str], Path] = {}
    for alg in ("vio_mono", "vio_stereo"):
        for s in ("MH_01", "MH_03", "MH_05"):
            runs[alg, s, "run0"] = (
                rpg / f"euroc_mono_stereo/laptop/{alg}/laptop_{alg}_{s}/stamped_traj_estimate.txt"
            )
    for s in seqs:
        runs["vislam_rp", s, "run0"] = (
            rpg
            / f"euroc_vislam_mono/laptop/vislam_rp/laptop_vislam_rp_{s}/stamped_traj_estimate0.txt"
        )
        for k in range(10):
            runs["vislam_ba", s, f"run{k}"] = (
                rpg / f"euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_{s}/"
                f"stamped_ba_estimate{k}.txt"
            )
    runs["openvins", "MH_01", "run0"] = (
        DATA / "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv"
    )
    runs["openvins", "MH_04", "run0"] = DATA / "qmy0519_open_vins-master/traj_estimate.txt"
    pairs = []
    for (alg, s, r), src in runs.items():
        dst = cwd / "algorithms" / alg / s / f"{r}{src.suffix}"
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.symlink(src, dst)
        pairs.append((cwd / "truth" / f"{s}.txt", dst))
    return pairs


def in_pairs(cmds, workers=2) -> float:
    t0 = time.perf_counter()
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(lambda c: subprocess.run(c, capture_output=True), cmds))
    return time.perf_counter() - t0


def bench_euroc(tmp: Path, skip_evo: bool) -> dict:
    from epa.artifacts import files
    from epa.readers import text

    cwd = tmp / "euroc"
    pairs = euroc_grid(cwd)
    write_cfg(cwd)
    wf, rss, _ = smk(cwd, "--cores", "2", "--quiet")
    lib = in_pairs(
        [
            [tool("epa"), "eval", str(r), str(e), "--out", str(tmp / "lib" / f"{k}")]
            for k, (r, e) in enumerate(pairs)
        ]
    )
    out = {"cases": len(pairs), "workflow_s": wf, "workflow_rss_mb": rss, "library_loop_s": lib}
    if not skip_evo:
        evo_cmds = []
        for k, (r, e) in enumerate(pairs):
            # evo reads TUM; the OpenVINS CSV is converted once, outside the timing
            tum = tmp / "evo" / f"{k}.tum"
            tum.parent.mkdir(exist_ok=True)
            files.write_tum(tum, text.read_trajectory(e))
            evo_cmds += [
                [tool("evo_ape"), "tum", str(r), str(tum), "-a"],
                [
                    tool("evo_rpe"),
                    "tum",
                    str(r),
                    str(tum),
                    "-a",
                    "--delta",
                    "8",
                    "--delta_unit",
                    "m",
                    "--all_pairs",
                ],
            ]
        out["evo_loop_s"] = in_pairs(evo_cmds)
    return out


def in_process(grid_dir: Path, results_dir: Path) -> tuple[float, dict, list[str]]:
    """Every stage of every case, case by case in this process; seconds, config, case keys."""
    from epa.artifacts.case import CaseFolder
    from epa.workflow import chain, settings
    from epa.workflow import discovery as epa_cases

    cfg = settings.resolve(
        {"truth_dir": str(grid_dir / "truth"), "algorithms_dir": str(grid_dir / "algorithms")}
    )
    _, cases = epa_cases.discover(grid_dir / "truth", grid_dir / "algorithms")
    t0 = time.perf_counter()
    for c in cases:
        data = chain.CaseData(CaseFolder.of(results_dir, c))
        for name in chain.NAMES:
            chain.run_stage(name, data, cfg)
    return time.perf_counter() - t0, cfg, sorted(c.key for c in cases)


# ----------------------------------------------------------------------------- the example
def bench_example(tmp: Path) -> dict:
    from epa import simulate
    from epa.workflow import chain

    cwd = tmp / "example"
    simulate.simulate(cwd / "sim")
    (cwd / "truth").symlink_to(cwd / "sim/truth")
    (cwd / "algorithms").symlink_to(cwd / "sim/algorithms")
    write_cfg(cwd)
    smk(cwd, "-n", "--cores", "2", "--quiet")  # warm the file cache
    dry, _, _ = smk(cwd, "-n", "--cores", "2", "--quiet")
    out = {"dry_run_s": dry}
    for cores in (1, 2):
        shutil.rmtree(cwd / "results", ignore_errors=True)
        shutil.rmtree(cwd / ".snakemake", ignore_errors=True)
        started = time.time()
        out[f"cores{cores}_s"], _, _ = smk(cwd, "--cores", str(cores), "--quiet")
    out["timeline_cores2"] = timeline(cwd / "results", started)
    # the stages' own time, in one process, writing the same artifacts
    out["stages_in_process_s"], _, keys = in_process(cwd, tmp / "inproc")
    jobs = len(keys) * len(chain.NAMES)
    out["overhead_per_stage_job_s"] = (out["cores1_s"] - dry - out["stages_in_process_s"]) / jobs
    return out


GRID_RULES = ("tables", "figures", "paper")


def timeline(results: Path, started: float) -> dict:
    """Where a run's time went, in seconds from its start, from the files it wrote: each stage job's
    end (its manifest) less its wall seconds (its benchmark file) is its start; the once-per-grid
    rules' benchmark files are written as each ends."""
    jobs = []
    for manifest in results.glob("batches/*/*.json"):
        bench = manifest.parent / "benchmarks" / f"{manifest.stem}.tsv"
        wall, cpu = map(float, bench.read_text().splitlines()[1].split("\t")[:2])
        end = manifest.stat().st_mtime - started
        jobs.append((manifest.stem, end - wall, end, cpu))
    stages = [j for j in jobs if j[0] != "report"]
    done = {r: (results / "benchmarks" / f"{r}.tsv").stat().st_mtime - started for r in GRID_RULES}
    return {
        "first_job_start_s": round(min(j[1] for j in jobs), 2),
        "stages_end_s": round(max(j[2] for j in stages), 2),
        "stage_and_report_cpu_s": round(sum(j[3] for j in jobs), 2),
        **{f"{r}_end_s": round(t, 2) for r, t in done.items()},
    }


# ----------------------------------------------------------------------------- large simulated grids
def short_grid(cwd: Path, n_cases: int, seed: int = 0) -> None:
    """n_cases short cases: 20 s references at 50 Hz, estimates at 20 Hz with noise and drift."""
    from epa import simulate
    from epa.artifacts import files
    from epa.core.trajectory import Trajectory

    rng = np.random.default_rng(seed)
    n_alg, n_run = 10, 10
    n_ds = max(1, n_cases // (n_alg * n_run))
    (cwd / "truth").mkdir(parents=True)
    t_ref = np.arange(0, 20, 0.02)
    t_est = np.arange(0.01, 20, 0.05)
    for d in range(n_ds):
        r, p = simulate.truth_pose("drone_figure8", t_ref + d)
        files.write_tum(cwd / "truth" / f"seq{d:03d}.txt", Trajectory.from_rp(1e9 + t_ref, r, p))
        re, pe = simulate.truth_pose("drone_figure8", t_est + d)
        for a in range(n_alg):
            folder = cwd / "algorithms" / f"alg{a:02d}" / f"seq{d:03d}"
            folder.mkdir(parents=True)
            for k in range(n_run):
                noisy = pe + rng.normal(0, 0.02, pe.shape) + np.outer(t_est, rng.normal(0, 0.01, 3))
                files.write_tum(folder / f"run{k}.txt", Trajectory.from_rp(1e9 + t_est, re, noisy))


def bench_large(tmp: Path, n_cases: int, check: bool = True) -> dict:
    from epa.outputs import tables

    cwd = tmp / f"grid{n_cases}"
    short_grid(cwd, n_cases)
    write_cfg(cwd)
    out = {"cases": n_cases}
    out["dry_run_s"], out["dry_run_rss_mb"], _ = smk(cwd, "-n", "--cores", "2", "--quiet")
    out["run_s"], out["run_rss_mb"], _ = smk(cwd, "--cores", "2", "--quiet")
    if not check:
        return out
    # per-case execution of the same cases, then the same table code
    ref_dir = cwd / "per_case"
    out["per_case_in_process_s"], cfg, keys = in_process(cwd, ref_dir)
    tables.make(keys, ref_dir, cfg)
    same = all(
        (cwd / "results" / f).read_bytes() == (ref_dir / f).read_bytes()
        for f in ("error_comparison.txt", "summary.csv")
    )
    out["tables_identical_to_per_case"] = same
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-evo", action="store_true")
    ap.add_argument("--skip-large", action="store_true")
    ap.add_argument("--cases", default="1000,10000")
    ap.add_argument("--out", help="keep the grids here (default: a temporary folder)")
    ap.add_argument(
        "--no-check", action="store_true", help="skip the per-case comparison of the large grids"
    )
    args = ap.parse_args()
    tmp = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="epa_grid_"))
    tmp.mkdir(parents=True, exist_ok=True)
    print("example:", bench_example(tmp), flush=True)
    if DATA.is_dir():
        print("euroc:", bench_euroc(tmp, args.skip_evo), flush=True)
    else:
        print(f"euroc: skipped, no {DATA}")
    if not args.skip_large:
        for n in (int(x) for x in args.cases.split(",")):
            print(f"grid {n}:", bench_large(tmp, n, check=not args.no_check), flush=True)


if __name__ == "__main__":
    main()
