"""``epa selftest REF``: how well Steps 1-2 recover a known offset, extrinsic and scale on the motion of
the user's own reference, before they are trusted on a new dataset.

Estimates are simulated from the reference itself (:func:`epa.simulate.observe`): a random offset
within half the search window, a random sensor rotation and a lever arm of about 10 cm, optionally a
scale, at three noise levels. Steps 1-2 run with the configuration's settings, exactly as in a case.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from epa import simulate
from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.workflow.stages import calibrate, sync

# name: white orientation noise (deg), white position noise (m), random walks (deg, m per sqrt(s))
NOISE_LEVELS = {
    "low": (0.05, 0.002, 0.005, 0.001),
    "medium": (0.2, 0.005, 0.02, 0.005),
    "high": (0.5, 0.01, 0.05, 0.01),
}


def trial(ref: Trajectory, cfg: dict, rng: np.random.Generator, level: str, rate: float) -> dict:
    """One simulated estimate; what Steps 1-2 found against the truth."""
    rot_noise, pos_noise, rot_walk, pos_walk = NOISE_LEVELS[level]
    scale = float(rng.uniform(0.5, 4.0)) if cfg["calibrate"]["scale"] else 1.0
    truth: dict[str, Any] = {
        "offset": float(rng.uniform(-0.5, 0.5) * cfg["sync"]["window"]),
        "rotation": geometry.so3_exp(rng.normal(0, 1.0, 3)),
        "translation": rng.normal(0, 0.06, 3),
        "scale": scale,
    }
    est = simulate.observe(
        ref,
        rng,
        **truth,
        rate=rate,
        noise_rot_deg=rot_noise,
        noise_pos_m=pos_noise,
        walk_rot_deg=rot_walk,
        walk_pos_m=pos_walk,
        margin=0.5,
    )
    need = cfg["sync"]["min_pairs"]
    if len(est) < need:  # the simulated estimate leaves out the reference's ends (offset, margin)
        raise EpaError(
            f"too short for a selftest: {ref.t[-1] - ref.t[0]:.3f} s of reference ({len(ref)} poses)"
            f" give {len(est)} simulated poses at {rate:g} Hz, {need} needed (sync.min_pairs)"
        )
    found = sync.offset_step(ref, est, cfg)
    out: dict[str, Any] = {
        "level": level,
        "step1_status": found.status,
        "offset_true_s": truth["offset"],
        "offset_error_s": (found.estimated - truth["offset"])
        if found.estimated is not None
        else None,
        "offset_std_s": found.std,
    }
    # Step 2 on the offset Step 1 found (or, when it was not trusted, the true one: Step 2 alone)
    offset = found.offset if found.used else truth["offset"]
    try:
        _, i_est, _ = sync.associate(ref, est, cfg["sync"], offset)
    except EpaError as exc:
        return {**out, "step2_status": "too little motion", "step2_reason": exc.message}
    matched = est.select(i_est)
    ext = calibrate.extrinsic_step(
        ref.at(matched.t + offset), matched, cfg, (found.std or 0.0) if found.used else 0.0
    )
    out.update(step2_status=ext.status, step2_reason=ext.reason)
    if "rotation_std_deg" in ext.info:
        out.update(
            rotation_error_deg=float(
                np.degrees(geometry.rotation_angle(ext.R @ truth["rotation"].T))
            ),
            rotation_std_deg=ext.info["rotation_std_deg"],
            translation_error_m=float(np.linalg.norm(ext.t - truth["translation"])),
            translation_std_m=ext.info["translation_std_m"],
            scale_error=float(ext.scale - scale) if cfg["calibrate"]["scale"] else None,
            unobservable=ext.reason if ext.status == "unobservable" else None,
        )
    return out


def run(
    ref: Trajectory, cfg: dict, *, trials: int = 5, rate: float = 20.0, seed: int = 0
) -> list[dict]:
    rng = np.random.default_rng(seed)
    return [trial(ref, cfg, rng, level, rate) for level in NOISE_LEVELS for _ in range(trials)]


def _fmt(values, factor: float, spec: str) -> str:
    v = np.array([x for x in values if x is not None and np.isfinite(x)], float) * factor
    return f"{np.median(v):{spec}} / {np.max(v):{spec}}" if v.size else "-"


def _worst(std_lists) -> list:
    return [None if not s or any(v is None for v in s) else max(s) for s in std_lists]


def report(results: list[dict], ref_name: str, rate: float) -> str:
    """The self-test's table: per noise level, what was trusted and how far from the truth."""
    lines = [
        f"epa selftest: Steps 1-2 on simulated {rate:g} Hz estimates of the motion in {ref_name}",
        "(median / max over the trials; errors against the known truth: the offset's, the rotation's angle, the",
        " lever arm's length; std as reported: the offset's, the largest per-axis one of rotation and lever arm)",
        "",
    ]
    head = (
        f"{'noise':8} {'Step 1 trusted':>14} {'offset err ms':>14} {'std ms':>13} {'in 3 std':>9}  "
        f"{'Step 2 trusted':>14} {'rot err deg':>13} {'std deg':>13} {'trans err mm':>13} {'std mm':>13}"
    )
    lines += [head, "-" * len(head)]
    for level in NOISE_LEVELS:
        rows = [r for r in results if r["level"] == level]
        s1 = [r for r in rows if r["step1_status"] == "trusted"]
        inside = [abs(r["offset_error_s"]) <= 3 * r["offset_std_s"] for r in s1]
        s2 = [r for r in rows if r["step2_status"] == "trusted"]
        lines.append(
            f"{level:8} {len(s1):>6} of {len(rows):<5} {_fmt([abs(r['offset_error_s']) for r in s1], 1e3, '.2f'):>14}"
            f" {_fmt([r['offset_std_s'] for r in s1], 1e3, '.2f'):>13} {sum(inside):>4} of {len(s1):<2}  "
            f"{len(s2):>6} of {len(rows):<5} {_fmt([r.get('rotation_error_deg') for r in s2], 1, '.3f'):>13}"
            f" {_fmt(_worst([r.get('rotation_std_deg') for r in s2]), 1, '.3f'):>13}"
            f" {_fmt([r.get('translation_error_m') for r in s2], 1e3, '.1f'):>13}"
            f" {_fmt(_worst([r.get('translation_std_m') for r in s2]), 1e3, '.1f'):>13}"
        )
    lines.append("")
    not_trusted: dict[tuple[int, str], str | None] = {}  # (step, status): an example reason
    for r in results:
        if r["step1_status"] != "trusted":
            not_trusted.setdefault((1, r["step1_status"]), None)
        if r["step2_status"] != "trusted":
            not_trusted.setdefault((2, r["step2_status"]), r.get("step2_reason"))
    if not_trusted:
        lines.append("not trusted in some trials:")
        lines += [
            f"  Step {step} {status}" + (f" (e.g. {why})" if why else "")
            for (step, status), why in not_trusted.items()
        ]
    unobservable = {r["unobservable"] for r in results if r.get("unobservable")}
    if unobservable:
        lines.append(
            "this motion leaves part of the extrinsic unobservable: "
            + "; ".join(sorted(unobservable))
        )
    trusted = [r for r in results if r["step2_status"] == "trusted"]
    lines.append(
        "verdict: "
        + (
            "Steps 1-2 recover offset and extrinsic on this motion; the errors above are what"
            " to expect"
            if len(trusted) == len(results)
            else f"Steps 1-2 are trusted in {len(trusted)} of {len(results)} trials on this motion;"
            " read the statuses before relying on them"
        )
    )
    return "\n".join(lines) + "\n"
