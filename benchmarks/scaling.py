"""Each stage's cost against the number of poses, against its budget and against the last recorded
baseline (issue: cost). Figures go in docs/performance.md and the closing note, never in a timed test.

    python benchmarks/scaling.py [--sizes 10000,100000,1000000] [--repeat 3] [--artifacts]
    python benchmarks/scaling.py --record-baseline   # after a deliberate change: the new reference
    python benchmarks/scaling.py --example    # each stage over the example's 18 cases, as jobs run

A simulated pair at 200 Hz (the reference) and 200 Hz (the estimate: noise, a 30 ms clock offset,
a 10 deg / 5 cm extrinsic, OpenVINS covariance on every pose and a per-frame timing file, so that
every stage has its work) runs through every stage as ``epa eval`` runs it (``--artifacts``: also
writing every per-pose file, as a workflow job does). Printed per stage: seconds, microseconds per
pose, the growth exponent between sizes (1.0 = linear), the stage's budget and its cost against
``scaling_baseline.json`` (recorded on this project's 2-core machine; another machine should record
its own). Flagged with ``!!``: a stage over budget, growing faster than about linearly, or 3x its
baseline; loading beyond 2x pandas' C parser on the same files (the floor for reading text);
a peak memory above 2 GB.
"""

import argparse
import gc
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from epa import simulate
from epa.artifacts import files
from epa.core import runtime
from epa.core.trajectory import Trajectory
from epa.steps.calibrate import Extrinsic
from epa.workflow import chain, settings

# Microseconds per pose each stage may spend (about 1 µs per pose per quantity it computes); the
# report stage draws figures, so it is left out (benchmarks/figures.py measures it).
BUDGET_US = {
    "load": 4.0,  # 8 + 20 columns and the timing file; also checked against the C parser (LOAD_LIMIT)
    "crop": 0.5,
    "sync": 4.0,  # angular speed, resampling, FFT correlation, jackknife, association
    "calibrate": 4.0,  # interpolation, motion pairs, Kabsch, least squares, covariance
    "align": 1.0,
    "metrics": 6.0,  # ATE, ATE 2D, 6 segment lengths of RPE, 1 s RPE
    "drift": 2.0,
    "consistency": 1.0,  # NEES of position and orientation: two 3x3 solves a pose
    "efficiency": 0.5,
}
LOAD_LIMIT = 2.0  # loading against pandas' C parser on the same files
MEMORY_LIMIT_MB = 2000  # the whole run, at the largest size
REGRESSION_LIMIT = 3.0  # against scaling_baseline.json
BASELINE = Path(__file__).with_name("scaling_baseline.json")
# CPU seconds of this process (all its threads): a busy machine stretches wall time, much less this.
CLOCK = time.process_time
GROWTH_LIMIT = 1.25  # t ~ n^k: above this a stage is flagged as superlinear


def make_pair(folder: Path, n: int) -> tuple[Path, Path]:
    t = np.arange(n) / 200.0
    r, p = simulate.truth_pose("drone_figure8", t % 150.0)
    ref = Trajectory.from_rp(1e9 + t, r, p)
    rng = np.random.default_rng(0)
    c, s = np.cos(np.radians(10.0)), np.sin(np.radians(10.0))
    ext = Extrinsic(
        R=np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), t=np.array([0.05, 0, 0])
    )
    # camera poses of the body
    q_c, p_c = ext.to_sensor_rows(ref.q.T, p + rng.normal(0, 0.01, p.shape))
    cov = np.broadcast_to(np.diag([3e-5, 3e-5, 3e-5]), (n, 3, 3))  # orientation (rad^2), position
    est = Trajectory(
        1e9 + t - 0.03, p_c, np.ascontiguousarray(q_c.T), cov_rot=cov, cov_pos=cov * 4.0
    )
    files.write_tum(folder / "ref.txt", ref)
    files.write_trajectory(folder / "est.txt", est, "openvins")
    ms = 20.0 * np.exp(rng.normal(0, 0.2, n))  # <run>_timing.txt: stamp and milliseconds per frame
    files.write_text(
        timing_path(folder / "est.txt"),
        "".join(f"{a:.6f} {b:.3f}\n" for a, b in zip(est.t, ms)),
    )
    return folder / "ref.txt", folder / "est.txt"


def stage_times(ref_path, est_path, out: Path, cfg: dict, artifacts: bool) -> dict[str, float]:
    times: dict[str, float] = {}
    clock = {"stage": None, "t": 0.0}

    def on_stage(name):
        now = CLOCK()
        if clock["stage"]:
            times[clock["stage"]] = now - clock["t"]
        clock.update(stage=name, t=now)

    chain.run_case(ref_path, est_path, out, cfg, write_arrays=artifacts, on_stage=on_stage)
    on_stage(None)
    return times


def timing_path(est_path: Path) -> Path:
    """The estimate's timing file by the naming rule the load stage follows (<run>_timing.txt)."""
    return est_path.with_name(est_path.stem + "_timing.txt")


def c_parser_floor(ref_path, est_path) -> float:
    """pandas' C parser on the files the load stage reads: both trajectories and the timing file."""
    import pandas as pd

    t0 = CLOCK()
    for p in (ref_path, est_path, timing_path(est_path)):
        pd.read_csv(p, sep=" ", header=None, comment="#", engine="c").to_numpy()
    return CLOCK() - t0


def example_stage_costs() -> None:
    """CPU seconds per stage summed over the bundled example's cases, each stage run as a workflow
    job runs it: fresh per-case state read from the previous stage's artifacts, every artifact
    written, pandas preloaded as in the workers."""
    import os

    import pandas  # noqa: F401 - the workers preload it

    from epa.artifacts.case import CaseFolder
    from epa.workflow import discovery

    root = Path(__file__).resolve().parents[1]
    os.chdir(root)
    cfg = settings.resolve(settings.load_yaml(root / "config/config.yaml"))
    cfg["report"]["per_case"] = False
    _, cases = discovery.discover(cfg["truth_dir"], cfg["algorithms_dir"])
    cpu: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as out:
        for stage in chain.NAMES[:-1]:
            for case in cases:
                t0 = CLOCK()
                chain.run_stage(stage, chain.CaseData(CaseFolder.of(out, case)), cfg)
                cpu[stage] = cpu.get(stage, 0.0) + CLOCK() - t0
    for stage, t in cpu.items():
        print(f"{stage:<12}{t:8.2f} s")
    print(f"{'all stages':<12}{sum(cpu.values()):8.2f} s over {len(cases)} cases (CPU)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="10000,100000,1000000")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--artifacts", action="store_true")
    ap.add_argument("--example", action="store_true", help="per-stage cost on the bundled example")
    ap.add_argument(
        "--record-baseline",
        action="store_true",
        help=f"write this run's µs per pose at the largest size to {BASELINE.name}",
    )
    args = ap.parse_args()
    if args.example:
        return example_stage_costs()
    sizes = [int(s) for s in args.sizes.split(",")]
    runtime.keep_freed_memory()  # as `epa eval` runs its one case (its second thread: CPU counts it)
    cfg = settings.defaults()
    cfg["report"]["per_case"] = False
    results: dict[int, dict[str, float]] = {}
    floors = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            folder = Path(tmp) / str(n)
            folder.mkdir()
            ref_path, est_path = make_pair(folder, n)
            best: dict[str, float] = {}
            for k in range(args.repeat):
                gc.collect()
                got = stage_times(ref_path, est_path, folder / f"out{k}", cfg, args.artifacts)
                best = {s: min(v, best.get(s, np.inf)) for s, v in got.items()}
            results[n] = best
            floors[n] = min(c_parser_floor(ref_path, est_path) for _ in range(args.repeat))
            total = sum(v for s, v in best.items() if s != "report")
            print(f"{n:>9,} poses: stages {total:.3f} s (best of {args.repeat})", flush=True)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    baseline = json.loads(BASELINE.read_text()) if BASELINE.exists() else {}
    base_us = baseline.get("us_per_pose", {}) if baseline.get("poses") == sizes[-1] else {}
    header = f"{'stage':<12}" + "".join(f"{n:>12,}" for n in sizes)
    print(f"\nCPU seconds per stage ({'with' if args.artifacts else 'without'} per-pose artifacts)")
    print(header + f"{'us/pose':>10}{'growth':>8}{'budget':>8}{'x base':>8}")
    flagged, per_pose_now = [], {}
    for stage in [s for s in chain.NAMES if s != "report"]:
        ts = [results[n].get(stage, np.nan) for n in sizes]
        per_pose = per_pose_now[stage] = ts[-1] / sizes[-1] * 1e6
        growth = (
            np.log(ts[-1] / ts[-2]) / np.log(sizes[-1] / sizes[-2]) if len(sizes) > 1 else np.nan
        )
        vs_base = per_pose / base_us[stage] if base_us.get(stage) else np.nan
        over = per_pose > BUDGET_US[stage] or growth > GROWTH_LIMIT or vs_base >= REGRESSION_LIMIT
        if over:
            flagged.append(stage)
        print(
            f"{stage:<12}"
            + "".join(f"{t:>12.3f}" for t in ts)
            + f"{per_pose:>10.2f}{growth:>8.2f}{BUDGET_US[stage]:>8.1f}{vs_base:>8.2f}"
            + ("  !!" if over else "")
        )
    print(
        f"{'C parser':<12}"
        + "".join(f"{floors[n]:>12.3f}" for n in sizes)
        + "  (pandas, the same three files)"
    )
    ratio = results[sizes[-1]]["load"] / floors[sizes[-1]]
    print(
        f"load / C parser at {sizes[-1]:,} poses: {ratio:.2f}x (limit {LOAD_LIMIT:g}x)"
        + ("  !!" if ratio > LOAD_LIMIT else "")
    )
    print(
        f"peak memory {peak_mb:.0f} MB (limit {MEMORY_LIMIT_MB:,} MB)"
        + ("  !!" if peak_mb > MEMORY_LIMIT_MB else "")
    )
    if ratio > LOAD_LIMIT and "load" not in flagged:
        flagged.append("load")
    if peak_mb > MEMORY_LIMIT_MB:
        flagged.append("memory")
    if not base_us:
        print(f"no baseline for {sizes[-1]:,} poses in {BASELINE.name} (--record-baseline)")
    if flagged:
        print(
            f"over budget, superlinear or {REGRESSION_LIMIT:g}x the baseline: " + ", ".join(flagged)
        )
    if args.record_baseline:
        BASELINE.write_text(
            json.dumps(
                {
                    "poses": sizes[-1],
                    "machine": "the project's 2-core machine (CPU seconds, best of --repeat)",
                    "us_per_pose": {k: round(v, 3) for k, v in per_pose_now.items()},
                },
                indent=2,
            )
            + "\n"
        )
        print(f"baseline written: {BASELINE}")
    sys.exit(0)


if __name__ == "__main__":
    main()
