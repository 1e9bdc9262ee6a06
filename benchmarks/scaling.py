"""Each stage's cost against the number of poses, and against its budget (issue: cost). Figures go in
docs/performance.md and the closing note, never in a timed test.

    python benchmarks/scaling.py [--sizes 10000,100000,1000000] [--repeat 3] [--artifacts]
    python benchmarks/scaling.py --example    # each stage over the example's 18 cases, as jobs run

A simulated pair at 200 Hz (the reference) and 200 Hz (the estimate: noise, a 30 ms clock offset,
a 10 deg / 5 cm extrinsic) runs through every stage as ``epa eval`` runs it (``--artifacts``: also
writing every per-pose file, as a workflow job does). Printed per stage: seconds, microseconds per
pose, the growth exponent between sizes (1.0 = linear) and the stage's budget; a stage over budget or
growing faster than about linearly is flagged with ``!!``. Loading is also compared with pandas' C
parser on the same two files (the floor for reading text).
"""

import argparse
import gc
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from epa import simulate
from epa.artifacts import files
from epa.core.trajectory import Trajectory
from epa.steps.calibrate import Extrinsic
from epa.workflow import chain, settings

# Microseconds per pose each stage may spend (about 1 µs per pose per quantity it computes); the
# report stage draws figures, so it is left out (benchmarks/figures.py measures it).
BUDGET_US = {
    "load": 2.0,  # two files of 8 columns: within 2x of the C parser
    "crop": 0.5,
    "sync": 4.0,  # angular speed, resampling, FFT correlation, jackknife, association
    "calibrate": 4.0,  # interpolation, motion pairs, Kabsch, least squares, covariance
    "align": 1.0,
    "metrics": 6.0,  # ATE, ATE 2D, 6 segment lengths of RPE, 1 s RPE
    "drift": 2.0,
    "consistency": 0.5,
    "efficiency": 0.5,
}
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
    r_c, p_c = ext.to_sensor_rp(r, p + rng.normal(0, 0.01, p.shape))  # camera poses of the body
    est = Trajectory.from_rp(1e9 + t - 0.03, r_c, p_c)
    files.write_tum(folder / "ref.txt", ref)
    files.write_tum(folder / "est.txt", est)
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


def c_parser_floor(ref_path, est_path) -> float:
    import pandas as pd

    t0 = CLOCK()
    for p in (ref_path, est_path):
        pd.read_csv(p, sep=" ", header=None, comment="#", engine="c").to_numpy()
    return CLOCK() - t0


def example_stage_costs() -> None:
    """CPU seconds per stage summed over the bundled example's cases, each stage run as a workflow
    job runs it: fresh per-case state read from the previous stage's artifacts, every artifact
    written, pandas preloaded as in the workers."""
    import os

    import pandas  # noqa: F401 - the workers preload it

    from epa.artifacts.case import CaseData, CaseFolder
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
                chain.run_stage(stage, CaseData(CaseFolder.of(out, case)), cfg)
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
    args = ap.parse_args()
    if args.example:
        return example_stage_costs()
    sizes = [int(s) for s in args.sizes.split(",")]
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
    header = f"{'stage':<12}" + "".join(f"{n:>12,}" for n in sizes)
    print(f"\nCPU seconds per stage ({'with' if args.artifacts else 'without'} per-pose artifacts)")
    print(header + f"{'us/pose':>10}{'growth':>8}{'budget':>8}")
    flagged = []
    for stage in [s for s in chain.NAMES if s != "report"]:
        ts = [results[n].get(stage, np.nan) for n in sizes]
        per_pose = ts[-1] / sizes[-1] * 1e6
        growth = (
            np.log(ts[-1] / ts[-2]) / np.log(sizes[-1] / sizes[-2]) if len(sizes) > 1 else np.nan
        )
        over = per_pose > BUDGET_US[stage] or growth > GROWTH_LIMIT
        if over:
            flagged.append(stage)
        print(
            f"{stage:<12}"
            + "".join(f"{t:>12.3f}" for t in ts)
            + f"{per_pose:>10.2f}{growth:>8.2f}{BUDGET_US[stage]:>8.1f}"
            + ("  !!" if over else "")
        )
    print(
        f"{'C parser':<12}"
        + "".join(f"{floors[n]:>12.3f}" for n in sizes)
        + "  (pandas, the two files)"
    )
    ratio = results[sizes[-1]]["load"] / floors[sizes[-1]]
    print(f"load / C parser at {sizes[-1]:,} poses: {ratio:.2f}x; peak memory {peak_mb:.0f} MB")
    if flagged:
        print("over budget or superlinear: " + ", ".join(flagged))
    sys.exit(0)


if __name__ == "__main__":
    main()
