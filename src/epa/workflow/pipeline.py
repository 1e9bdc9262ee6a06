"""The computation of each stage, on in-memory values (no files). :mod:`epa.workflow.chain` wires them into
the stage sequence that both ``epa eval`` and the workflow run."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from epa import readers
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import accuracy, efficiency
from epa.readers import bags, text
from epa.readers import timing as timing_files
from epa.steps import align as alignment
from epa.steps import calibrate as calibration
from epa.steps import sync

log = logging.getLogger("epa")


def load_reference(ref_path, cfg: dict, opts: dict | None = None) -> tuple[Trajectory, list[str]]:
    notes: list[str] = []
    opts = readers.options(cfg, "reference") if opts is None else opts
    return readers.read(ref_path, opts, notes=notes), notes


def load(
    ref_path,
    est_path,
    cfg: dict,
    reference: tuple[Trajectory, list[str]] | None = None,
    *,
    ref_opts: dict | None = None,
    est_opts: dict | None = None,
):
    """Read the reference (unless already read: ``reference``, as load_reference returns it) and the
    estimate, each with its source settings (:func:`epa.readers.options`). ``ref_notes`` /
    ``est_notes`` in the record list what was inferred rather than read."""
    ref_opts = readers.options(cfg, "reference") if ref_opts is None else ref_opts
    est_opts = readers.options(cfg, "estimate") if est_opts is None else est_opts
    ref, ref_notes = load_reference(ref_path, cfg, ref_opts) if reference is None else reference
    # KITTI estimates rarely ship their own times file: they are index-aligned with the reference's.
    est_times = None
    if not bags.is_bag(est_path):
        est_times = text.kitti_times_for(Path(est_path)) or (
            None if bags.is_bag(ref_path) else text.kitti_times_for(Path(ref_path))
        )
    est_notes: list[str] = []
    est = readers.read(est_path, est_opts, notes=est_notes, kitti_times=est_times)
    info = {
        "ref_file": Path(ref_path).name,
        "est_file": Path(est_path).name,
        "est_path": str(est_path),
        "n_ref": len(ref),
        "n_est": len(est),
        "ref_length_m": ref.length(),
        "est_length_m": est.length(),
        "ref_span_s": [float(ref.t[0]), float(ref.t[-1])],
        "est_span_s": [float(est.t[0]), float(est.t[-1])],
        "ref_notes": ref_notes,
        "est_notes": est_notes,
    }
    info["sources"] = {
        "reference": ref_opts,
        "estimate": est_opts,
    }  # the settings each side was read with
    info["covariance"] = est.cov_rot is not None
    timing = None
    try:  # a bad timing file costs the case its efficiency, not its accuracy: the efficiency stage reports it
        timing_path = readers.timing_file(est_path, est_opts)
        if timing_path is not None:
            t, ms, what = timing_files.read_timing(timing_path)
            timing = {"t": t, "frame_ms": ms}
            info["timing"] = {"file": timing_path.name, "read_as": what, "frames": int(len(t))}
    except EpaError as exc:
        info["timing_error"] = {"path": exc.path, "line": exc.line, "message": exc.message}
    return ref, est, info, timing


def crop(ref: Trajectory, est: Trajectory, cfg: dict):
    c = cfg["crop"]
    t0 = ref.t[0]
    lo = -np.inf if c["start"] is None else t0 + c["start"]
    hi = np.inf if c["end"] is None else t0 + c["end"]
    ref_c = ref.select((ref.t >= lo) & (ref.t <= hi))
    est_keep = (est.t >= lo) & (est.t <= hi) & (est.t >= est.t[0] + c["skip_first"])
    est_c = est.select(est_keep)
    if len(ref_c) < 2 or len(est_c) < 2:
        raise EpaError(
            f"the crop window leaves {len(ref_c)} reference and {len(est_c)} estimate poses"
        )
    return ref_c, est_c, crop_info(cfg, {"n_ref": len(ref_c), "n_est": len(est_c)})


def crops(cfg: dict) -> bool:
    """Whether the crop settings cut anything at all."""
    c = cfg["crop"]
    return c["start"] is not None or c["end"] is not None or c["skip_first"] > 0


def crop_info(cfg: dict, counts: dict) -> dict:
    return {"settings": cfg["crop"], "n_ref": counts["n_ref"], "n_est": counts["n_est"]}


def sync_stage(ref: Trajectory, est: Trajectory, cfg: dict):
    """Step 1 (when ``sync.estimate_offset``), then association. Returns the matched indices
    (i_ref, i_est), the record and the correlation curve."""
    c = cfg["sync"]
    info: dict = {"mode": cfg["mode"], "policy": c["policy"]}
    curve = None
    if c["estimate_offset"]:
        est_off = offset_step(ref, est, cfg)
        if not est_off.used:
            log.warning(
                "Step 1 not used: %s; using the configured offset %.6f s",
                est_off.reason,
                c["offset"],
            )
        info["step1"] = est_off.to_dict()
        offset = est_off.offset
        curve = {"lag_s": est_off.curve_lag, "corr": est_off.curve_corr}
    else:
        info["step1"] = {
            "used": False,
            "status": "disabled",
            "reason": "disabled",
            "offset": c["offset"],
            "estimated": None,
            "std": None,
        }
        offset = c["offset"]
    i_ref, i_est, assoc = associate(ref, est, c, offset)
    info.update(assoc)
    # ov_eval warns on these (a bad length ratio, a coarse reference): mode ov_eval prints what it prints
    info["matched_length_m"] = {
        "ref": ref.select(i_ref).length(),
        "est": est.select(i_est).length(),
    }
    return (i_ref, i_est), info, curve


def offset_step(ref: Trajectory, est: Trajectory, cfg: dict) -> sync.OffsetEstimate:
    """Step 1 under the ``sync`` settings."""
    c = cfg["sync"]
    return sync.estimate_offset(
        ref,
        est,
        window=c["window"],
        resample_dt=c["resample_dt"],
        min_motion=c["min_motion"],
        min_corr=c["min_corr"],
        min_peak_ratio=c["min_peak_ratio"],
        max_std=c["max_offset_std"],
        speed_interval=c["speed_interval"],
        fallback=c["offset"],
    )


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


def associate(ref: Trajectory, est: Trajectory, c: dict, offset: float):
    """Matched indices under the ``sync`` settings ``c`` and a time offset; too few pairs is an error."""
    i_ref, i_est = sync.associate(
        ref, est, policy=c["policy"], max_diff=c["max_diff"], offset=offset
    )
    max_diff = sync.POLICIES[c["policy"]] if c["max_diff"] is None else c["max_diff"]
    if len(i_ref) < c["min_pairs"]:
        lo, hi = max(ref.t[0], est.t[0] + offset), min(ref.t[-1], est.t[-1] + offset)
        why = (
            f"the stamps do not overlap: reference {ref.t[0]:.3f}..{ref.t[-1]:.3f} s,"
            f" estimate {est.t[0] + offset:.3f}..{est.t[-1] + offset:.3f} s"
            if lo >= hi
            else f"they overlap for {hi - lo:.3f} s"
        )
        raise EpaError(
            f"only {len(i_ref)} poses matched within {max_diff} s (offset {offset:.6f} s);"
            f" {c['min_pairs']} needed; {why} (check the time unit, sync.offset or the files)"
        )
    info = {
        "offset_s": offset,
        "max_diff_s": max_diff,
        "n_matched": int(len(i_ref)),
        "n_ref": len(ref),
        "n_est": len(est),
    }
    return i_ref, i_est, info


def evaluation_plan(cfg: dict, step1: dict, extrinsic: calibration.Extrinsic | None = None) -> dict:
    """How a case is evaluated: the one place that decides the ov_eval fallback.

    An untrusted Step 1 or Step 2 means the case is evaluated the ov_eval way: the configured
    ``sync.offset`` (default 0) instead of an estimated one, no extrinsic, SE3 alignment on all
    poses (see :func:`alignment_of`); it is marked ``eval_source: ov_eval``. ``mode: ov_eval`` is
    that evaluation by choice, with the configured alignment."""
    fallback = {
        "eval_source": "ov_eval",
        "fallback": True,
        "offset_s": cfg["sync"]["offset"],
        "apply_extrinsic": False,
    }
    if cfg["mode"] == "ov_eval":
        return {**fallback, "fallback": False, "reason": "ov_eval mode"}
    if cfg["sync"]["estimate_offset"] and not step1.get("used", False):
        return {**fallback, "reason": f"Step 1 not trusted: {step1.get('reason')}"}
    if extrinsic is not None and not extrinsic.trusted:
        return {**fallback, "reason": f"Step 2 not trusted: {extrinsic.reason}"}
    applied = extrinsic is not None
    return {
        "eval_source": "epa",
        "fallback": False,
        "offset_s": step1.get("offset", cfg["sync"]["offset"]),
        "apply_extrinsic": applied,
        "reason": "Steps 1 and 2 applied" if applied else "Step 2 disabled",
    }


def alignment_of(plan: dict, cfg: dict) -> tuple[str, int]:
    """Step 3 method and first_n under an evaluation plan: the fallback aligns SE3 on all poses."""
    return ("se3", -1) if plan["fallback"] else (cfg["align"]["method"], cfg["align"]["first_n"])


def calibrate_stage(ref: Trajectory, est: Trajectory, cfg: dict, sync_info: dict, cropped=None):
    """Step 2 and the evaluation plan on the matched (ref, est). ``cropped()`` gives the unmatched
    trajectories, needed only when the plan drops an estimated offset (Step 2 not trusted) and the
    poses are re-associated; the new indices are then returned, else None."""
    c = cfg["calibrate"]
    step1_record = sync_info.get("step1", {})
    plan = evaluation_plan(cfg, step1_record)
    info: dict = {
        "mode": cfg["mode"],
        "extrinsic": None,
        "step2_status": "disabled" if cfg["mode"] == "ov_eval" or not c["enabled"] else "not run",
    }
    ext = None
    if plan["eval_source"] == "epa" and c["enabled"]:
        # Step 2 compares each estimate pose with the reference at its very instant: a matched
        # reference pose may be up to max_diff away, which biases the lever arm (1 cm at 8 m/s and a
        # 50 Hz reference). Step 1's uncertainty is carried into Step 2's (a configured offset is exact).
        ref_at = cropped()[0].at(est.t + sync_info["offset_s"]) if cropped is not None else ref
        ext = extrinsic_step(
            ref_at, est, cfg, (step1_record.get("std") or 0.0) if step1_record.get("used") else 0.0
        )
        info["extrinsic"] = ext.to_dict()
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
    return ref, (ext.apply(est) if plan["apply_extrinsic"] else est), info, pairs


def align_stage(ref: Trajectory, est: Trajectory, cfg: dict, calib_info: dict):
    plan = calib_info["plan"]
    method, first_n = alignment_of(plan, cfg)
    fit = alignment.fit(ref, est, method=method, first_n=first_n)
    return fit.apply(est), {
        "method": method,
        "first_n": first_n,
        "fallback_se3": plan["fallback"],
        **fit.to_dict(),
    }


# A matched reference shorter than this has no distance metrics (RPE per metre, drift rate,
# distance success rate would all be 0/0).
MIN_PATH_M = 0.01


def metrics_stage(ref: Trajectory, est: Trajectory, cfg: dict):
    c = cfg["metrics"]
    length = ref.length()
    if length < MIN_PATH_M:
        raise EpaError(
            f"the reference does not move ({length:.3g} m over the matched poses): distance RPE,"
            " drift rate and success rate are undefined"
        )
    summary, tables = accuracy.evaluate(
        ref,
        est,
        segments=c["segments"],
        segment_tol=c["segment_tol"],
        time_delta=c["time_delta"],
        time_tol=c["time_tol"],
        rpe=c["rpe"],
    )
    summary["est_length_m"] = est.length()  # the aligned estimate's matched path (EA-Drift's L)
    # an empty segment length is shown as empty, never as a number; say why once, here
    summary["notes"] = [
        f"no {key} m segment fits in the {length:.3f} m matched path: its RPE and drift rate are empty"
        for key, rpe in summary["rpe_distance"].items()
        if rpe["trans_m"]["n"] == 0
    ]
    if c["kitti"]:
        from epa.metrics import kitti

        summary["kitti"], tables["kitti_segments"] = kitti.odometry(ref, est)
        if not summary["kitti"]["n_segments"]:
            summary["notes"].append(
                f"no 100 m KITTI segment fits in the {length:.3f} m matched path: the KITTI"
                " metric is empty"
            )
    for note in summary["notes"]:
        log.warning("%s", note)
    return summary, tables


def drift_stage(tables: dict, cfg: dict):
    from epa.metrics import drift

    ape, seg, tp = tables["ape"], tables["rpe_segments"], tables["rpe_time"]
    det = drift.detect(
        ape["t"],
        ape["dist_m"],
        ape["trans_m"],
        ape["rot_deg"],
        tp["i"].astype(int),
        tp["j"].astype(int),
        tp["trans_m"],
        cfg["drift"],
    )
    valid, seg_valid, time_valid = drift.valid_metrics(
        det, ape["trans_m"], ape["rot_deg"], seg, tp, cfg["metrics"]["segments"]
    )
    fs = det["fail_segments"]
    curve = drift.success_curve(
        ape["t"],
        ape["dist_m"],
        ape["trans_m"],
        tp["i"].astype(int),
        tp["j"].astype(int),
        tp["trans_m"],
        det["thresholds"],
    )
    summary = {
        "thresholds": det["thresholds"],
        "success_rate_distance_pct": det["success_rate_distance_pct"],
        "success_auc_pct": curve.pop("auc_pct"),
        "success_curve": curve,
        "success_rate_time_pct": det["success_rate_time_pct"],
        "global_failed": det["global_failed"],
        "ape_p5_m": det["ape_p5_m"],
        "knee": det["knee"],
        "n_fail_segments": int(len(fs["index_start"])),
        "first_fail_t": float(fs["t_start"][0] - ape["t"][0]) if len(fs["t_start"]) else None,
        # a fail segment that reaches the last pose: the run never recovered from there
        "diverged_at_s": (
            float(fs["t_start"][-1] - ape["t"][0])
            if len(fs["t_start"]) and fs["index_end"][-1] == len(ape["t"]) - 1
            else None
        ),
        "drift_valid": valid,
    }
    if det["global_failed"]:
        summary["status"] = (
            f"globally failed: 5th percentile APE {det['ape_p5_m']:.3g} m >"
            f" {cfg['drift']['global_fail_p5_m']} m"
        )
    artifacts = {
        "fail_segments": fs,
        "pose_valid": {"t": ape["t"], "valid": ~det["invalid"]},
        # row k: whether pair k of 06_metrics/rpe_segments.csv (rpe_time.csv) is drift-valid
        "rpe_segments_valid": {"valid": seg_valid},
        "rpe_time_valid": {"valid": time_valid},
    }
    return summary, artifacts


def efficiency_stage(t_est, ape: dict, est_length_m: float, timing, dataset: str, cfg: dict):
    """Runtime statistics and EA-Drift of one case (see :mod:`epa.metrics.efficiency`)."""
    c = cfg["efficiency"]
    rate = c["datasets"].get(dataset, c["sensor_rate_hz"])
    note = None
    if rate is None:  # not configured: the timing file's own frame rate
        dt = np.diff(np.sort(timing[0]))
        rate = float(1.0 / np.median(dt[dt > 0])) if (dt > 0).any() else None
        if rate is None:
            raise EpaError("set efficiency.sensor_rate_hz (the timing file's stamps give no rate)")
        note = f"sensor rate {rate:.3f} Hz from the timing file's stamps (efficiency.sensor_rate_hz not set)"
        log.warning("%s", note)
    summary, table = efficiency.evaluate(
        np.asarray(t_est),
        np.asarray(ape["t"]),
        np.asarray(ape["trans_m"]),
        est_length_m,
        timing,
        rate,
        c["max_diff"],
    )
    if note:
        summary["notes"] = [note]
    if summary.get("n_without_timing"):
        log.warning(
            "%d of %d poses have no timing entry within %s s: left out of EA-Drift",
            summary["n_without_timing"],
            summary["n_poses"],
            c["max_diff"],
        )
    return summary, table


def case_record(
    load_info: dict, sync_info: dict, calib_info: dict, align_info: dict, summary: dict
) -> dict:
    """metrics.json: the metrics plus what loading and Steps 1-3 did, so one file tells the whole case."""
    ext = calib_info.get("extrinsic") or {}
    applied = bool(calib_info.get("plan", {}).get("apply_extrinsic"))
    offset = calib_info.get("reassociated", sync_info)["offset_s"]
    return {
        "n_matched": summary["n_matched"],
        "eval_source": calib_info.get("eval_source", "epa"),
        "time_offset_s": offset,
        "extrinsic_rot_deg": ext.get("rotation_deg") if applied else None,
        "extrinsic_trans_m": ext.get("translation_norm_m") if applied else None,
        "alignment": align_info,
        **{k: v for k, v in summary.items() if k != "n_matched"},
        # the estimate's path as invoked stays in load.json: metrics.json is the same from `epa eval` and the grid
        "load": {k: v for k, v in load_info.items() if k != "est_path"},
        "sync": sync_info,
        "calibrate": calib_info,
    }
