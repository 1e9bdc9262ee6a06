"""Step 1: the time offset by cross-correlating angular speed (linear speed for a position-only
estimate), then association (03_sync/)."""

from __future__ import annotations

import logging
import math

from epa.artifacts.case import Both, CaseData, Indices, Record
from epa.artifacts.stage import Stage, Value
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory, position_only
from epa.steps import sync

log = logging.getLogger(__name__)

NAME = "sync"


def compute(ref: Trajectory, est: Trajectory, cfg: dict):
    """Step 1 (when ``sync.estimate_offset``), then association. Returns the matched indices
    (i_ref, i_est), the matched poses (ref, est), the record and the correlation curve."""
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
        # what Step 1 could not measure (too few poses, no motion) is None; status and reason say why
        info["step1"] = {
            k: None if isinstance(v, float) and math.isnan(v) else v
            for k, v in est_off.to_dict().items()
        }
        if which := position_only(ref, est):
            info["step1"] = linear_record(info["step1"], which)
        offset = est_off.offset
        curve = {"lag_s": est_off.curve_lag, "corr": est_off.curve_corr}
    else:
        info["step1"] = {
            "used": False,
            "status": sync.Step1Status.DISABLED,
            "reason": "disabled",
            "offset": c["offset"],
            "estimated": None,
            "std": None,
        }
        offset = c["offset"]
    i_ref, i_est, assoc = associate(ref, est, c, offset)
    info.update(assoc)
    matched = ref.select(i_ref), est.select(i_est)
    # ov_eval warns on these (a bad length ratio, a coarse reference): mode ov_eval prints what it prints
    info["matched_length_m"] = {"ref": matched[0].length(), "est": matched[1].length()}
    return (i_ref, i_est), matched, info, curve


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
        speed=sync.linear_speed if position_only(ref, est) else sync.angular_speed,
    )


def linear_record(step1: dict, which: str) -> dict:
    """Step 1's record where a side is position-only (``which``): its signal is the linear speed,
    in m/s."""
    rename = {"ref_motion_rad_s": "ref_motion_m_s", "est_motion_rad_s": "est_motion_m_s"}
    return {
        "signal": f"linear speed ({which}: no angular speed)",
        **{rename.get(k, k): v for k, v in step1.items()},
    }


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


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    folder = data.folder
    ref, est = data.cropped
    (i_ref, i_est), data.sync_matched, info, curve = compute(ref, est, cfg)
    data.sync_pairs, data.sync_record = (i_ref, i_est), info
    folder.write_record(NAME, "sync.json", info)
    if write_arrays:
        folder.write_pairs(NAME, i_ref, i_est, ref.t, est.t)
        folder.write_table(NAME, "xcorr.csv", curve or {"lag_s": [], "corr": []})


def matched_by(name: str, pairs: str) -> Value:
    """The value ``name``: (ref, est) of the cropped trajectories at the indices of the value
    ``pairs`` (a stage's ``pairs.csv``)."""

    def read(data: CaseData) -> Both:
        ref, est = data.cropped
        i_ref, i_est = getattr(data, pairs)
        return ref.select(i_ref), est.select(i_est)

    return Value(name, Both, read, needs=("cropped", pairs))


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("mode", "sync"),
    records=("sync.json",),
    arrays=("pairs.csv", "xcorr.csv"),
    reads=("cropped",),
    values=(
        Value("sync_record", Record, lambda s: s.f.record(NAME, "sync.json")),
        Value("sync_pairs", Indices, lambda s: s.f.pairs(NAME)),
        matched_by("sync_matched", "sync_pairs"),
    ),
)
