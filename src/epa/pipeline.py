"""One function per stage, on in-memory values. The rule scripts and ``epa eval`` both call these,
in the same order, so the workflow and the command line can never disagree."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from epa import alignment, calibration, io, metrics, sync
from epa.errors import EpaError
from epa.trajectory import Trajectory

log = logging.getLogger("epa")


def load(ref_path, est_path, cfg: dict):
    c = cfg["load"]
    opts = dict(time_unit=c["time_unit"], on_unsorted=c["unsorted"], kitti_rate=c["kitti_rate"])
    ref = io.read_trajectory(ref_path, c["truth_format"], **opts)
    # KITTI estimates rarely ship their own times file: they are index-aligned with the reference's.
    est_times = io.kitti_times_for(Path(est_path)) or io.kitti_times_for(Path(ref_path))
    est = io.read_trajectory(est_path, c["estimate_format"], kitti_times=est_times, **opts)
    info = {"ref_file": Path(ref_path).name, "est_file": Path(est_path).name, "n_ref": len(ref), "n_est": len(est),
            "ref_length_m": ref.length(), "est_length_m": est.length(),
            "ref_span_s": [float(ref.t[0]), float(ref.t[-1])], "est_span_s": [float(est.t[0]), float(est.t[-1])]}
    return ref, est, info


def crop(ref: Trajectory, est: Trajectory, cfg: dict):
    c = cfg["crop"]
    t0 = ref.t[0]
    lo = -np.inf if c["start"] is None else t0 + c["start"]
    hi = np.inf if c["end"] is None else t0 + c["end"]
    ref_c = ref.select((ref.t >= lo) & (ref.t <= hi))
    est_keep = (est.t >= lo) & (est.t <= hi) & (est.t >= est.t[0] + c["skip_first"])
    est_c = est.select(est_keep)
    if len(ref_c) < 2 or len(est_c) < 2:
        raise EpaError(f"the crop window leaves {len(ref_c)} reference and {len(est_c)} estimate poses")
    return ref_c, est_c, {"settings": c, "n_ref": len(ref_c), "n_est": len(est_c)}


def sync_stage(ref: Trajectory, est: Trajectory, cfg: dict):
    """Step 1 (unless disabled or in ov_eval mode), then association. Returns matched (ref, est)."""
    c = cfg["sync"]
    ov_mode = cfg["mode"] == "ov_eval"
    policy = "ov_eval" if ov_mode else c["policy"]
    max_diff = 0.02 if ov_mode else c["max_diff"]
    info: dict = {"mode": cfg["mode"], "policy": policy}
    curve = None
    if c["estimate_offset"] and not ov_mode:
        est_off = sync.estimate_offset(ref, est, window=c["window"], resample_dt=c["resample_dt"],
                                       min_motion=c["min_motion"], min_corr=c["min_corr"],
                                       min_peak_ratio=c["min_peak_ratio"], fallback=c["offset"])
        if not est_off.used:
            log.warning("Step 1 not used: %s; using the configured offset %.6f s", est_off.reason, c["offset"])
        info["step1"] = est_off.to_dict()
        offset = est_off.offset
        curve = {"lag_s": est_off.curve_lag, "corr": est_off.curve_corr}
    else:
        info["step1"] = {"used": False, "reason": "disabled", "offset": c["offset"], "estimated": None}
        offset = c["offset"]
    i_ref, i_est = sync.associate(ref, est, policy=policy, max_diff=max_diff, offset=offset)
    info.update(offset_s=offset, max_diff_s=sync.POLICIES[policy] if max_diff is None else max_diff,
                n_matched=int(len(i_ref)), n_ref=len(ref), n_est=len(est))
    if len(i_ref) < c["min_pairs"]:
        raise EpaError(f"only {len(i_ref)} poses matched within {info['max_diff_s']} s (offset {offset:.6f} s);"
                       f" {c['min_pairs']} needed: check the time unit, the offset or the files")
    return ref.select(i_ref), est.select(i_est), info, curve


def calibrate_stage(ref: Trajectory, est: Trajectory, cfg: dict, sync_info: dict):
    """Step 2, with the fallback: an untrusted Step 1 or Step 2 means the case is evaluated the
    ov_eval way (no offset, no extrinsic, SE3) and marked ``eval_source: ov_eval``."""
    c = cfg["calibrate"]
    info: dict = {"mode": cfg["mode"]}
    step1 = sync_info.get("step1", {})
    if cfg["mode"] == "ov_eval":
        info.update(eval_source="ov_eval", reason="ov_eval mode", extrinsic=None)
        return est, info
    if cfg["sync"]["estimate_offset"] and not step1.get("used", False):
        info.update(eval_source="ov_eval", reason=f"Step 1 not trusted: {step1.get('reason')}", extrinsic=None)
        return est, info
    if not c["enabled"]:
        info.update(eval_source="epa", reason="Step 2 disabled", extrinsic=None)
        return est, info
    ext = calibration.solve(ref, est, pair_step=c["pair_step"], min_rotation_deg=c["min_rotation_deg"],
                            scale=c["scale"], max_rot_residual_deg=c["max_rot_residual_deg"],
                            max_trans_residual_m=c["max_trans_residual_m"], max_condition=c["max_condition"],
                            min_pairs=c["min_pairs"], outlier_iterations=c["outlier_iterations"])
    info["extrinsic"] = ext.to_dict()
    if ext.translation_unobservable():
        log.warning("Step 2: translation unobservable along %s (left at 0)", ext.info["translation_unobservable_directions"])
    if not ext.trusted:
        log.warning("Step 2 not trusted: %s; evaluating the ov_eval way", ext.reason)
        info.update(eval_source="ov_eval", reason=f"Step 2 not trusted: {ext.reason}")
        return est, info
    info.update(eval_source="epa", reason="Steps 1 and 2 applied")
    return ext.apply(est), info


def align_stage(ref: Trajectory, est: Trajectory, cfg: dict, calib_info: dict):
    c = cfg["align"]
    fallback = cfg["mode"] == "epa" and calib_info.get("eval_source") == "ov_eval"
    method = "se3" if fallback else c["method"]
    fit = alignment.fit(ref, est, method=method, first_n=-1 if fallback else c["first_n"])
    return fit, fit.apply(est), {"method": method, "first_n": c["first_n"], "fallback_se3": fallback,
                                 **fit.to_dict()}


def metrics_stage(ref: Trajectory, est: Trajectory, cfg: dict):
    c = cfg["metrics"]
    return metrics.evaluate(ref, est, segments=c["segments"], segment_tol=c["segment_tol"],
                            time_delta=c["time_delta"], time_tol=c["time_tol"], rpe=c["rpe"])


def drift_stage(tables: dict, cfg: dict):
    from epa import drift

    ape, seg, tp = tables["ape"], tables["rpe_segments"], tables["rpe_time"]
    det = drift.detect(ape["t"], ape["dist_m"], ape["trans_m"], ape["rot_deg"], tp["i"].astype(int),
                       tp["j"].astype(int), tp["trans_m"], cfg["drift"])
    valid, seg_valid, time_valid = drift.valid_metrics(det, ape["trans_m"], ape["rot_deg"], seg, tp,
                                                       cfg["metrics"]["segments"])
    fs = det["fail_segments"]
    summary = {"thresholds": det["thresholds"], "success_rate_distance_pct": det["success_rate_distance_pct"],
               "success_rate_time_pct": det["success_rate_time_pct"], "global_failed": det["global_failed"],
               "ape_p5_m": det["ape_p5_m"], "knee": det["knee"], "n_fail_segments": int(len(fs["index_start"])),
               "first_fail_t": float(fs["t_start"][0] - ape["t"][0]) if len(fs["t_start"]) else None,
               # a fail segment that reaches the last pose: the run never recovered from there
               "diverged_at_s": (float(fs["t_start"][-1] - ape["t"][0])
                                 if len(fs["t_start"]) and fs["index_end"][-1] == len(ape["t"]) - 1 else None),
               "drift_valid": valid}
    if det["global_failed"]:
        summary["status"] = (f"globally failed: 5th percentile APE {det['ape_p5_m']:.3g} m >"
                             f" {cfg['drift']['global_fail_p5_m']} m")
    artifacts = {"fail_segments": fs, "pose_valid": {"t": ape["t"], "valid": ~det["invalid"]},
                 "rpe_segments": {**seg, "valid": seg_valid}, "rpe_time": {**tp, "valid": time_valid}}
    return summary, artifacts


def evaluate_case(ref_path, est_path, cfg: dict) -> dict:
    """Every stage in one process (``epa eval``): the same functions the rules call."""
    ref, est, load_info = load(ref_path, est_path, cfg)
    ref, est, _ = crop(ref, est, cfg)
    ref_m, est_m, sync_info, _ = sync_stage(ref, est, cfg)
    est_c, calib_info = calibrate_stage(ref_m, est_m, cfg, sync_info)
    _, aligned, align_info = align_stage(ref_m, est_c, cfg, calib_info)
    summary, tables = metrics_stage(ref_m, aligned, cfg)
    drift_summary, _ = drift_stage(tables, cfg)
    return {**case_record(sync_info, calib_info, align_info, summary), "load": load_info, "sync": sync_info,
            "calibrate": calib_info, "drift": drift_summary}


def case_record(sync_info: dict, calib_info: dict, align_info: dict, summary: dict) -> dict:
    """metrics.json: the metrics plus what Steps 1-3 did, so one file tells the whole case."""
    ext = calib_info.get("extrinsic") or {}
    applied = calib_info.get("eval_source") == "epa" and bool(ext)
    return {"n_matched": summary["n_matched"], "eval_source": calib_info.get("eval_source", "epa"),
            "time_offset_s": sync_info["offset_s"],
            "extrinsic_rot_deg": ext.get("rotation_deg") if applied else None,
            "extrinsic_trans_m": ext.get("translation_norm_m") if applied else None,
            "alignment": align_info, **{k: v for k, v in summary.items() if k != "n_matched"}}

