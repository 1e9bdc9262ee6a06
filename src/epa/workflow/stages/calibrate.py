"""Step 2: the hand-eye extrinsic on the matched poses, then the evaluation plan (04_calibrate/).
``est.tum`` is the matched estimate with the extrinsic applied (only when the plan applies it)."""

from __future__ import annotations

import logging
import math

from epa.artifacts.case import Both, CaseData, Indices, Record
from epa.artifacts.stage import Stage, Value
from epa.core.trajectory import Trajectory, position_only
from epa.steps import calibrate as calibration
from epa.steps.plan import evaluation_plan
from epa.workflow.stages.sync import associate, matched_by

log = logging.getLogger(__name__)

NAME = "calibrate"


def extrinsic_step(
    ref: Trajectory, est: Trajectory, cfg: dict, offset_std: float = 0.0
) -> calibration.Extrinsic:
    """Step 2 under the ``calibrate`` settings, on matched poses; ``offset_std``: Step 1's deviation."""
    c = cfg["calibrate"]
    return calibration.solve(
        ref,
        est,
        pair_step=c["pair_step"],
        min_rotation_deg=c["min_rotation_deg"],
        scale=c["scale"],
        max_rot_residual_deg=c["max_rot_residual_deg"],
        max_trans_residual_m=c["max_trans_residual_m"],
        max_condition=c["max_condition"],
        min_pairs=c["min_pairs"],
        outlier_iterations=c["outlier_iterations"],
        max_rot_std_deg=c["max_rot_std_deg"],
        max_trans_std_m=c["max_trans_std_m"],
        max_scale_std=c["max_scale_std"],
        offset_std=offset_std,
    )


# Motion pairs in one time block (under 2 pair_step s of rotating motion) leave the uncertainty
# undefined: the residuals' spread is estimated across blocks, so every covariance entry is NaN.
UNDEFINED_UNCERTAINTY = (
    "a null uncertainty entry is undefined (every motion pair in one time block: the residuals'"
    " spread across blocks, which the uncertainty is made of, cannot be estimated)"
)


def position_only_reason(which: str) -> str:
    """Why Step 2 is off where a side is position-only (docs/inputs.md says more)."""
    return (
        f"{which}: the hand-eye equations need both sides' relative rotations; a lever arm alone"
        " would have to be fitted jointly with Step 3's alignment, which is not done (an offset of"
        " the tracked point from the body stays in the translation errors)"
    )


def extrinsic_record(ext: calibration.Extrinsic) -> dict:
    """The extrinsic's record (calibrate.json's ``extrinsic``): an undefined uncertainty entry is
    None, with a note, never NaN."""
    undefined: list = []

    def defined(value):
        if isinstance(value, dict):
            return {k: defined(v) for k, v in value.items()}
        if isinstance(value, list):
            return [defined(v) for v in value]
        if isinstance(value, float) and math.isnan(value):
            undefined.append(value)
            return None
        return value

    record = defined(ext.to_dict())
    return {**record, "notes": [UNDEFINED_UNCERTAINTY]} if undefined else record


def compute(
    ref: Trajectory,
    est: Trajectory,
    cfg: dict,
    sync_info: dict,
    cropped=None,
    *,
    covariance: bool = True,
):
    """Step 2 and the evaluation plan on the matched (ref, est). ``cropped()`` gives the unmatched
    trajectories, needed only when the plan drops an estimated offset (Step 2 not trusted) and the
    poses are re-associated; the new indices are then returned, else None. ``covariance`` False:
    an estimate with the extrinsic applied holds no covariance (none is turned)."""
    c = cfg["calibrate"]
    step1_record = sync_info.get("step1", {})
    plan = evaluation_plan(cfg, step1_record)
    info: dict = {
        "mode": cfg["mode"],
        "extrinsic": None,
        "step2_status": (
            calibration.Step2Status.DISABLED
            if cfg["mode"] in ("ov_eval", "rpg") or not c["enabled"]
            else calibration.Step2Status.NOT_RUN
        ),
    }
    ext = None
    which = position_only(ref, est)
    if plan["eval_source"] == "epa" and c["enabled"] and which:
        info["step2_status"] = calibration.Step2Status.DISABLED
        info["step2_reason"] = position_only_reason(which)
    elif plan["eval_source"] == "epa" and c["enabled"]:
        # Step 2 compares each estimate pose with the reference at its very instant: a matched
        # reference pose may be up to max_diff away, which biases the lever arm (1 cm at 8 m/s and a
        # 50 Hz reference). Step 1's uncertainty is carried into Step 2's (a configured offset is exact).
        ref_at = (
            calibration.interpolator(cropped()[0])(est.t + sync_info["offset_s"])
            if cropped is not None
            else ref
        )
        ext = extrinsic_step(
            ref_at, est, cfg, (step1_record.get("std") or 0.0) if step1_record.get("used") else 0.0
        )
        info["extrinsic"] = extrinsic_record(ext)
        info["step2_status"] = ext.status
        plan = evaluation_plan(cfg, step1_record, ext)
        if not ext.trusted:
            log.warning("Step 2 %s: %s; evaluating the ov_eval way", ext.status, ext.reason)
    pairs = None
    if plan["offset_s"] != sync_info["offset_s"]:
        if cropped is None:
            raise ValueError("re-association needs the cropped trajectories")
        ref_c, est_c = cropped()
        i_ref, i_est, assoc = associate(ref_c, est_c, cfg["sync"], plan["offset_s"])
        ref, est, pairs = ref_c.select(i_ref), est_c.select(i_est), (i_ref, i_est)
        info["reassociated"] = assoc
    info.update(eval_source=plan["eval_source"], reason=plan["reason"], plan=plan)
    if plan["apply_extrinsic"]:
        if ext is None:  # evaluation_plan applies only an extrinsic Step 2 estimated
            raise TypeError("the plan applies an extrinsic that Step 2 did not estimate")
        est = ext.apply(est if covariance else est.without_covariance())
    return ref, est, info, pairs


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    folder = data.folder
    ref, est = data.sync_matched
    # The covariances are read in the matched estimate's own frames (consistency); turned into the
    # calibrated and aligned frames they are only written (est.tum, aligned.tum). Without arrays
    # (epa eval) neither carries them: at 1M poses 216 MB and Steps 2 and 3's turning them spared.
    ref, est, info, pairs = compute(
        ref, est, cfg, data.sync_record, cropped=lambda: data.cropped, covariance=write_arrays
    )
    data.calibrated = (ref, est if write_arrays else est.without_covariance())
    data.calibrate_record = info
    data.calibrate_pairs = pairs if pairs is not None else data.sync_pairs
    if pairs is not None:
        data.matched = (ref, est) if not info["plan"]["apply_extrinsic"] else data.matched
    else:  # sync's matched poses: in memory already (else the later stages select them again)
        data.matched = data.sync_matched
    folder.write_record(NAME, "calibrate.json", info)
    if write_arrays:
        # unchanged pairs are sync's (linked); re-associated ones, or no links, are written
        if pairs is not None or not folder.link("sync", "pairs.csv", NAME):
            ref_c, est_c = data.cropped
            i_ref, i_est = data.calibrate_pairs
            folder.write_pairs(NAME, i_ref, i_est, ref_c.t, est_c.t)
        if info["plan"]["apply_extrinsic"]:
            # the matched estimate with the extrinsic applied
            folder.write_tum(NAME, "est.tum", est)
        else:
            folder.remove(NAME, "est.tum")


def _calibrated(data: CaseData) -> Both:
    """(ref, est) matched, the estimate with Step 2's extrinsic applied when the plan applies it"""
    ref, est = data.matched
    if data.calibrate_record["plan"]["apply_extrinsic"]:
        est = data.f.tum(NAME, "est.tum")
    return ref, est


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("mode", "sync", "calibrate"),
    records=("calibrate.json",),
    arrays=("pairs.csv", "est.tum"),
    reads=("sync_matched", "sync_record", "sync_pairs", "cropped"),
    values=(
        Value("calibrate_record", Record, lambda s: s.f.record(NAME, "calibrate.json")),
        Value("calibrate_pairs", Indices, lambda s: s.f.pairs(NAME)),
        matched_by("matched", "calibrate_pairs"),
        Value("calibrated", Both, _calibrated, needs=("matched", "calibrate_record")),
    ),
)
