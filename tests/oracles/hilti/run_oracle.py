"""Runs the Hilti SLAM Challenge 2022 evaluation on the cases of hilti_cases.py; writes its outputs here.

    $VENV/bin/python tests/oracles/hilti/run_oracle.py EVALUATION_2022_DIR DATA_DIR

($VENV: the environment README.md here describes.)

2022: batch_evaluation.evaluate_submission (unchanged) on a submission holding one case as
``exp07_long_corridor.txt`` against its control points under that name (the pole tip applied);
its results.csv row and the bin counts it returns. 2023 has no public script: evaluation.evaluate
(unchanged) on the control points named ``<case>_imu.txt`` (its branch without a lever arm), and
the 2023 README's table applied to its errors here.
Shims, not edits: ``collections.Iterable`` (gone in Python 3.10) set to ``collections.abc.Iterable``
for the script's plotting; ``dataframe_image`` (PNG export of the score table) a no-op module.
"""

import collections
import collections.abc
import sys
import tempfile
import types
from pathlib import Path

collections.Iterable = collections.abc.Iterable
sys.modules["dataframe_image"] = types.SimpleNamespace(export=lambda *a, **k: None)
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, sys.argv[1])

import numpy as np  # noqa: E402
from batch_evaluation import evaluate_submission  # noqa: E402
from evaluation import evaluate  # noqa: E402
from hilti_cases import CASES, control_points, estimate, reference  # noqa: E402

HEADER = "# timestamp_s x y z qx qy qz qw"
data = Path(sys.argv[2])
for name in CASES:
    cp = control_points(reference(data, name))
    with tempfile.TemporaryDirectory() as tmp:
        sub, gt = Path(tmp) / "sub", Path(tmp) / "gt"
        sub.mkdir(), gt.mkdir()
        np.savetxt(gt / "exp07_long_corridor.txt", cp, fmt="%.17g", header=HEADER[2:])
        np.savetxt(sub / "exp07_long_corridor.txt", estimate(data, name), fmt="%.17g")
        total = evaluate_submission(str(sub), str(gt), verbose=False)
        row = [r for r in (sub / "results.csv").read_text().splitlines() if "exp07" in r]
        lines = [f"n_control_points {len(cp)}", "results.csv " + row[0]]
        lines += [f"total {k} {v!r}" for k, v in total.items()]
        (HERE / f"{name}_2022.txt").write_text("\n".join(lines) + "\n")

        imu = gt / f"{name}_imu.txt"
        np.savetxt(imu, cp, fmt="%.17g", header=HEADER[2:])
        stats, dense, est_aligned, ref_sync = evaluate(
            str(sub / "exp07_long_corridor.txt"), str(imu), tmp
        )
        diff = np.linalg.norm(ref_sync.positions_xyz - est_aligned.positions_xyz, axis=1)
        bounds, award = (
            [0.005, 0.01, 0.03, 0.06, 0.10, 0.40],
            [20, 10, 6, 5, 3, 1, 0],
        )  # 2023 README
        counts = np.bincount(np.searchsorted(bounds, diff, side="right"), minlength=7)
        total_points = int(sum(c * a for c, a in zip(counts, award)))
        lines = [f"n_control_points {len(cp)}", f"n_matched {len(diff)}"]
        lines += [f"{k} {v!r}" for k, v in stats.items()]
        lines += [
            f"per_bin {counts.tolist()}",
            f"points {total_points}",
            f"score {total_points / (len(cp) / 5)!r}",
        ]
        (HERE / f"{name}_2023.txt").write_text("\n".join(lines) + "\n")
        print(name, open(HERE / f"{name}_2022.txt").read(), open(HERE / f"{name}_2023.txt").read())
