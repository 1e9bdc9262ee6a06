"""Benchmarks (figures go in the closing note, never in a timed test).

    python benchmarks/bench.py [--skip-evo]
    python benchmarks/bench.py --large [--repeat 3]

1. epa eval, and epa ape + epa rpe (evo's command lines), vs evo_ape + evo_rpe (8 m, all pairs) on
   a 100,000-pose simulated pair; epica's commands: the best wall and CPU time (user + system, the
   process and its children) of RUNS runs.
2. epa eval on one EuRoC case (../shared/data), wall time and peak memory.
3. Steps 1+2 vs the metrics stage on the 100,000-pose pair.

``--large``: only `epa eval` on a 1,000,000-pose simulated pair (300 MB of TUM text), each run's
wall time, CPU time (user + system) and peak memory (its maximum resident set).
"""

import argparse
import os
import resource
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from grid import tool  # (benchmarks/grid.py: each tool started the same way)

from epa import simulate
from epa.artifacts import files
from epa.core.trajectory import Trajectory
from epa.steps import calibrate as calibration
from epa.steps import sync
from epa.workflow import settings
from epa.workflow.stages import metrics as metrics_stage

RUNS = 5  # epica's commands: best of (on a shared machine one run says little)


def timed(cmd):
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t0


def best_of(cmds, runs=RUNS) -> tuple[float, float]:
    """(wall, CPU) s of the commands run one after another: the best of ``runs`` rounds of each."""
    wall = cpu = float("inf")
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        for cmd in cmds:
            subprocess.run(cmd, check=True, capture_output=True)
        wall = min(wall, time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        used = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
        cpu = min(cpu, used)
    return wall, cpu


def big_pair(tmp: Path, n=100_000):
    t = np.arange(n) / 200.0
    r, p = simulate.truth_pose("drone_figure8", t % 150)
    ref = Trajectory.from_rp(1e9 + t, r, p)
    rng = np.random.default_rng(0)
    est = Trajectory.from_rp(1e9 + t, r, p + rng.normal(0, 0.02, p.shape))
    files.write_tum(tmp / "ref.txt", ref)
    files.write_tum(tmp / "est.txt", est)
    return ref, est


def measured(cmd) -> tuple[float, float, float, float]:
    """Wall seconds, user and system CPU seconds and peak resident memory (MB) of ``cmd``, from its
    own resource usage (os.wait4: the child alone, no /usr/bin/time needed)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err = proc.stderr.read() if proc.stderr is not None else b""
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}): {err.decode()[-2000:]}")
    return wall, usage.ru_utime, usage.ru_stime, usage.ru_maxrss / 1024  # Linux: kB


def large(repeat: int) -> None:
    """`epa eval` on a 1,000,000-pose pair: wall, CPU and peak memory of each run."""
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        big_pair(tmp, n=1_000_000)
        cmd = [tool("epa"), "eval", str(tmp / "ref.txt"), str(tmp / "est.txt"), "--out"]
        runs = [measured([*cmd, str(tmp / f"o{k}")]) for k in range(repeat)]
    for k, (wall, user, system, peak) in enumerate(runs, 1):
        print(
            f"epa eval, 1M poses, run {k}: {wall:.2f} s wall, {user:.2f} s user +"
            f" {system:.2f} s system, peak {peak:.0f} MB"
        )
    walls, peaks = [r[0] for r in runs], [r[3] for r in runs]
    print(
        f"epa eval, 1M poses: {min(walls):.2f}-{max(walls):.2f} s wall,"
        f" peak {min(peaks):.0f}-{max(peaks):.0f} MB (load average {os.getloadavg()[0]:.2f})"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--skip-evo", action="store_true", help="leave out evo_ape + evo_rpe")
    ap.add_argument("--large", action="store_true", help="only epa eval on a 1M-pose pair")
    ap.add_argument("--repeat", type=int, default=3, help="runs of --large (default 3)")
    args = ap.parse_args()
    if args.large:
        return large(args.repeat)
    tmp = Path(tempfile.mkdtemp())
    ref, est = big_pair(tmp)
    pair = [str(tmp / "ref.txt"), str(tmp / "est.txt")]
    epa_s, epa_cpu = best_of([[tool("epa"), "eval", *pair, "--out", str(tmp / "o")]])
    print(f"epa eval, 100k poses: {epa_s:.2f} s ({epa_cpu:.2f} s CPU; best of {RUNS})")
    ape = ["tum", *pair, "-a"]
    rpe = ["tum", *pair, "-a", "--delta", "8", "--delta_unit", "m", "--all_pairs"]
    each = [best_of([[tool("epa"), kind, *args]]) for kind, args in (("ape", ape), ("rpe", rpe))]
    both_s, both_cpu = best_of([[tool("epa"), "ape", *ape], [tool("epa"), "rpe", *rpe]])
    print(
        f"epa ape + epa rpe (8 m, all pairs): {both_s:.2f} s ({both_cpu:.2f} s CPU); ape"
        f" {each[0][0]:.2f} s ({each[0][1]:.2f}), rpe {each[1][0]:.2f} s ({each[1][1]:.2f})"
    )
    if not args.skip_evo:
        evo_s = timed([tool("evo_ape"), *ape]) + timed([tool("evo_rpe"), *rpe])
        print(
            f"evo_ape + evo_rpe (8 m, all pairs): {evo_s:.2f} s  -> speed-up {evo_s / epa_s:.1f}x"
            f" (epa eval), {evo_s / both_s:.1f}x (epa ape + epa rpe)"
        )
    cfg = settings.defaults()
    t0 = time.perf_counter()
    off = sync.estimate_offset(ref, est)
    ir, ie = sync.associate(ref, est, offset=off.offset)
    calibration.solve(ref.select(ir), est.select(ie))
    steps = time.perf_counter() - t0
    t0 = time.perf_counter()
    given = {  # what the stage gives its registered metrics (the scale check: an se3 case)
        "transform": lambda: {"method": "se3", "first_n": -1},
        "estimate_source": lambda: {},
        "calibrate_record": lambda: None,
    }
    metrics_stage.compute(ref.select(ir), est.select(ie), cfg, given)
    print(
        f"Steps 1+2: {steps:.2f} s; metrics stage: {time.perf_counter() - t0:.2f} s (same 100k pair)"
    )
    data = Path(__file__).resolve().parents[2] / "shared/data"
    if data.is_dir():
        rpg = "uzh-rpg_rpg_trajectory_evaluation/results/euroc_mono_stereo/laptop"
        estimates = {
            "MH_01 OpenVINS": "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv",
            "MH_01 rpg vio_stereo": f"{rpg}/vio_stereo/laptop_vio_stereo_MH_01/stamped_traj_estimate.txt",
        }
        for name, estimate in estimates.items():
            case = [
                tool("epa"),
                "eval",
                str(data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"),
                str(data / estimate),
                "--out",
                str(tmp / "e"),
            ]
            out = subprocess.run(
                ["/usr/bin/time", "-f", "%e s %M KB", *case], capture_output=True, text=True
            )
            case_s, case_cpu = best_of([case])
            print(
                f"epa eval, one EuRoC case ({name}):",
                out.stderr.strip().splitlines()[-1],
                f"(best of {RUNS}: {case_s:.2f} s, {case_cpu:.2f} s CPU)",
            )


if __name__ == "__main__":
    main()
