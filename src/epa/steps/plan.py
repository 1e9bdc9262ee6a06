"""The evaluation plan: which of Steps 1-2's results a case is evaluated with, and Step 3's method.
The one place that decides the ov_eval fallback."""

from __future__ import annotations

from epa.core.records import PlanRecord
from epa.steps.calibrate import Extrinsic


def evaluation_plan(cfg: dict, step1: dict, extrinsic: Extrinsic | None = None) -> PlanRecord:
    """How a case is evaluated: the one place that decides the ov_eval fallback.

    An untrusted Step 1 or Step 2 means the case is evaluated the ov_eval way: the configured
    ``sync.offset`` (default 0) instead of an estimated one, no extrinsic (nor Step 2's scale), and
    the alignment the settings ask for (see :func:`alignment_of`: a fallback never changes it); it
    is marked ``eval_source: ov_eval``, with ``dropped`` naming what was left out. ``mode: ov_eval`` is
    that evaluation by choice, with the configured alignment; ``mode: rpg`` is rpg_trajectory_evaluation's
    (``eval_source: rpg``: rpg's association, the configured alignment in rpg's arithmetic)."""

    def fallback(reason: str, eval_source: str = "ov_eval", by_choice: bool = False) -> PlanRecord:
        plan: PlanRecord = {
            "eval_source": eval_source,
            "fallback": not by_choice,
            "offset_s": cfg["sync"]["offset"],
            "apply_extrinsic": False,
            "reason": reason,
        }
        if not by_choice:
            plan["dropped"] = dropped(cfg, step1)
        return plan

    if cfg["mode"] == "ov_eval":
        return fallback("ov_eval mode", by_choice=True)
    if cfg["mode"] == "rpg":
        return fallback("rpg mode", "rpg", by_choice=True)
    if cfg["sync"]["estimate_offset"] and not step1.get("used", False):
        return fallback(f"Step 1 not trusted: {step1.get('reason')}")
    if extrinsic is not None and not extrinsic.trusted:
        return fallback(f"Step 2 not trusted: {extrinsic.reason}")
    applied = extrinsic is not None
    return {
        "eval_source": "epa",
        "fallback": False,
        "offset_s": step1.get("offset", cfg["sync"]["offset"]),
        "apply_extrinsic": applied,
        "reason": "Steps 1 and 2 applied" if applied else "Step 2 disabled",
    }


def dropped(cfg: dict, step1: dict) -> list[str]:
    """What a fallback leaves out of the evaluation the settings ask for."""
    out = []
    if cfg["sync"]["estimate_offset"]:
        used = step1.get("used", False)
        out.append(
            f"Step 1's time offset ({'estimated, not used' if used else 'not trusted'}; the"
            f" configured sync.offset {cfg['sync']['offset']:g} s instead)"
        )
    if cfg["calibrate"]["enabled"]:
        out.append(
            "Step 2's extrinsic"
            + (" and scale (Step 3's Sim3 fits the scale)" if cfg["calibrate"]["scale"] else "")
        )
    return out


def alignment_of(plan: PlanRecord, cfg: dict) -> tuple[str, int]:
    """Step 3 method and first_n under an evaluation plan: the configured ones, also in a fallback
    (a requested Sim3 stays Sim3, posyaw stays posyaw)."""
    return cfg["align"]["method"], cfg["align"]["first_n"]
