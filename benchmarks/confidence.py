"""What the confidence figures cost (issue: confidence). Figures go in docs/performance.md and the
closing note, never in a timed test.

    python benchmarks/confidence.py [--base REV] [--repeat 3]

Runs every stage of the bundled 18-case example and of rpg's 50 EuRoC estimates (when ../shared/data
is there) case by case in one process, once with this checkout's library and once with the library
of commit REV (default: the last commit without the confidence figures), and prints each stage's
total time (the best of --repeat runs). The Step 1 jackknife, the Step 2 covariances and the
success-rate curve live in the sync, calibrate and drift stages.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"

CHILD = r"""
import json, sys, time
from pathlib import Path
from epa.workflow import chain
from epa.workflow import jobs as grid
from epa.workflow import settings
from epa import simulate

out, repeat = Path(sys.argv[1]), int(sys.argv[2])
grids = {}
manifest = simulate.simulate(out / "example")
grids["example"] = ([{"key": k, "truth": str(out / "example/truth" / (k.split("/")[1] + ".txt")),
                      "estimate": str(next((out / "example/algorithms").glob(k + ".*")))} for k in manifest["cases"]],
                    out / "example/truth", out / "example/algorithms")
euroc = Path(sys.argv[3])
if euroc.is_dir():
    gt = euroc / "rpng_open_vins/ov_data/euroc_mav"
    rpg = euroc / "uzh-rpg_rpg_trajectory_evaluation/results"
    names = {"MH_01": "MH_01_easy.txt", "MH_03": "MH_03_medium.txt", "MH_04": "MH_04_difficult.txt",
             "MH_05": "MH_05_difficult.txt"}
    cases = []
    for f in sorted(rpg.rglob("*.txt")):
        seq = next(s for s in names if s in str(f))
        key = f"{f.parent.parent.name}/{seq}/{f.stem}"
        cases.append({"key": key, "truth": str(gt / names[seq]), "estimate": str(f)})
    grids["euroc"] = (cases, gt, rpg)
result = {}
for name, (cases, truth, algs) in grids.items():
    cfg = settings.resolve({"truth_dir": str(truth), "algorithms_dir": str(algs), "report": {"per_case": False}})
    best = {}
    for r in range(repeat):
        root = out / f"{name}{r}"
        previous = None
        for stage in [s for s in chain.NAMES if s != "report"]:
            manifest_path = root / "batches" / f"{stage}.json"
            t0 = time.perf_counter()
            grid.run_job(stage, cases, root, cfg, manifest_path, previous, root / f"{stage}.log")
            best[stage] = min(best.get(stage, 1e9), time.perf_counter() - t0)
            previous = manifest_path
    result[name] = {"cases": len(cases), "stages": best}
print(json.dumps(result))
"""


def measure(src: Path, repeat: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PYTHONPATH": str(src)}
        out = subprocess.run(
            [sys.executable, "-c", CHILD, tmp, str(repeat), str(DATA)],
            env=env,
            check=True,
            capture_output=True,
            text=True,
            cwd=tmp,
        )
        return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", default="3a80efe", help="the commit to compare with")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), args.base],
            check=True,
            capture_output=True,
        )
        try:
            before = measure(base / "src", args.repeat)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], check=True
            )
    now = measure(ROOT / "src", args.repeat)
    for name in now:
        print(
            f"\n{name}: {now[name]['cases']} cases, stage time in one process (s), best of {args.repeat}"
        )
        print(f"{'stage':12} {args.base:>10} {'now':>10} {'change':>10}")
        for stage, t in now[name]["stages"].items():
            b = before[name]["stages"].get(stage, float("nan"))
            print(f"{stage:12} {b:10.2f} {t:10.2f} {t - b:+10.2f}")
        total_b, total_n = sum(before[name]["stages"].values()), sum(now[name]["stages"].values())
        print(f"{'total':12} {total_b:10.2f} {total_n:10.2f} {total_n - total_b:+10.2f}")


if __name__ == "__main__":
    main()
