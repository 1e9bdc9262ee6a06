"""Benchmarks (figures go in the closing note, never in a timed test).

    python benchmarks/bench.py [--skip-evo]
    python benchmarks/bench.py --large [--repeat 3]

1. epa eval vs evo_ape + evo_rpe (8 m, all pairs) on a 100,000-pose simulated pair.
2. epa eval on one EuRoC case (../shared/data), wall time and peak memory.
3. Steps 1+2 vs the metrics stage on the 100,000-pose pair.

``--large``: only `epa eval` on a 1,000,000-pose simulated pair (300 MB of TUM text), each run's
wall time, CPU time (user + system) and peak memory (its maximum resident set).
"""

import argparse
import os
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


def timed(cmd):
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t0


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
    epa_s = timed(
        [tool("epa"), "eval", str(tmp / "ref.txt"), str(tmp / "est.txt"), "--out", str(tmp / "o")]
    )
    print(f"epa eval, 100k poses: {epa_s:.2f} s")
    if not args.skip_evo:
        evo_s = timed([tool("evo_ape"), "tum", str(tmp / "ref.txt"), str(tmp / "est.txt"), "-a"])
        evo_s += timed(
            [
                tool("evo_rpe"),
                "tum",
                str(tmp / "ref.txt"),
                str(tmp / "est.txt"),
                "-a",
                "--delta",
                "8",
                "--delta_unit",
                "m",
                "--all_pairs",
            ]
        )
        print(
            f"evo_ape + evo_rpe (8 m, all pairs): {evo_s:.2f} s  -> speed-up {evo_s / epa_s:.1f}x"
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
        cmd = [
            "/usr/bin/time",
            "-f",
            "%e s %M KB",
            tool("epa"),
            "eval",
            str(data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"),
            str(data / "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv"),
            "--out",
            str(tmp / "e"),
        ]
        out = subprocess.run(cmd, capture_output=True, text=True)
        print("epa eval, one EuRoC case (MH_01 OpenVINS):", out.stderr.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
