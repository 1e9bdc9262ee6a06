"""Runs tartanair_tools' evaluator on the cases of tartanair_cases.py and writes its outputs here.

    $VENV/bin/python tests/oracles/tartanair/run_oracle.py TOOLS_EVALUATION_DIR DATA_DIR

(see README.md here for the environment)

TOOLS_EVALUATION_DIR: the ``evaluation/`` folder of castacks/tartanair_tools (unchanged).
Each case is run with scale=False and scale=True; ``random.seed(0)`` is called before each, since
the script draws its RPE pairs with the unseeded ``random`` module.
"""

import contextlib
import random
import sys
import tempfile
from io import StringIO
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, sys.argv[1])

import numpy as np  # noqa: E402
from tartanair_cases import CASES, equal_length  # noqa: E402
from tartanair_evaluator import TartanAirEvaluator  # noqa: E402

data = Path(sys.argv[2])
with tempfile.TemporaryDirectory() as tmp:
    for name in CASES:
        ref, est = equal_length(data, name)
        gt_file, est_file = Path(tmp) / "gt.txt", Path(tmp) / "est.txt"
        np.savetxt(gt_file, ref, fmt="%.17g")  # exact: loadtxt gives back the same floats
        np.savetxt(est_file, est, fmt="%.17g")
        for scale in (False, True):
            random.seed(0)
            printed = StringIO()
            with contextlib.redirect_stdout(printed):
                result = TartanAirEvaluator().evaluate_one_trajectory(
                    str(gt_file), str(est_file), scale=scale
                )
            lines = [f"n_poses {len(ref)}", *printed.getvalue().splitlines()]
            lines += [f"{k} {v!r}" for k, v in result.items()]
            (HERE / f"{name}_scale{int(scale)}.txt").write_text("\n".join(lines) + "\n")
            print(name, scale, result)
