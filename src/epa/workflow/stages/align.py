"""Step 3: the world-frame fit of the calibrated estimate onto the reference (05_align/).
Row k of ``aligned.tum`` is matched with row k of ``04_calibrate/pairs.csv``. In mode rpg the fit is
rpg_trajectory_evaluation's (``align.method`` and ``align.first_n`` are its ``align_type`` and
``align_num_frames``), in rpg's arithmetic."""

from __future__ import annotations

from epa.artifacts.case import CaseData, Record
from epa.artifacts.stage import Stage, Value
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory, position_only
from epa.steps import align as alignment
from epa.steps import rpg
from epa.steps.plan import alignment_of

NAME = "align"


def compute(ref: Trajectory, est: Trajectory, cfg: dict, calib_info: dict):
    plan = calib_info["plan"]
    method, first_n = alignment_of(plan, cfg)
    if plan["eval_source"] == "rpg":
        _orientation_needed(ref, est, method, first_n)
        fit, aligned = rpg.fit(ref, est, method, first_n)
    else:
        fit = alignment.fit(ref, est, method=method, first_n=first_n)
        # mode ov_eval prints ov_eval's table: its orientations turned by matrices, as before
        aligned = fit.apply(est, matrices=cfg["mode"] == "ov_eval")
    return aligned, {
        "method": method,
        "first_n": first_n,
        "fallback": plan["fallback"],
        **fit.to_dict(),
    }


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    ref, est = data.calibrated
    aligned, info = compute(ref, est, cfg, data.calibrate_record)
    data.aligned, data.transform = aligned, info
    data.folder.write_record(NAME, "transform.json", info)
    if write_arrays:
        data.folder.write_tum(NAME, "aligned.tum", aligned)


def _orientation_needed(ref: Trajectory, est: Trajectory, method: str, first_n: int) -> None:
    """rpg aligns se3 / posyaw on one pose by its orientations: a position-only side has none."""
    which = position_only(ref, est)
    if which and first_n == 1 and method in ("se3", "posyaw"):
        raise EpaError(
            f"align.first_n 1 with {method} in mode rpg aligns on the first pose's orientation, and"
            f" {which} (no orientation); align on 2 or more poses"
        )


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("mode", "align"),
    records=("transform.json",),
    arrays=("aligned.tum",),
    reads=("calibrated", "calibrate_record"),
    values=(
        Value("transform", Record, lambda s: s.f.record(NAME, "transform.json")),
        Value("aligned", Trajectory, lambda s: s.f.tum(NAME, "aligned.tum")),
    ),
)
