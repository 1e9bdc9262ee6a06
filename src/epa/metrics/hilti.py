"""The Hilti SLAM Challenge's score of a sequence, 2022 and 2023 (docs/protocols.md, section Hilti).

As the 2022 evaluation (``evaluation-2022/evaluation.py`` and ``batch_evaluation.py`` of
Hilti-Research/hilti-slam-challenge-2022) computes it:

1. every estimate pose is moved to the measured point: ``T_i · [I | lever]`` (2022: the pole tip
   ``(0.059, -0.00855, 0.1964)`` m in the IMU frame; the script skips it for a reference named
   ``*_imu.txt``, here ``lever_arm_m: [0, 0, 0]``);
2. each control point takes the estimate pose nearest in time within 2 s (evo's association);
3. an SE3 fit (Umeyama, no scale) of those estimate positions onto the control points;
4. each control point's error ``|c_k - (R e_k + t)|`` earns points by threshold
   (2022: 10/6/3/1 below 1/3/6/10 cm; 2023: 20/10/6/5/3/1 below 0.5/1/3/6/10/40 cm; none above);
5. the sequence score is the sum over **all** control points of the reference normalised to 100
   (a point missing from the estimate earns nothing).

A reference of more than 100 poses is a dense trajectory, which the challenge does not score
(``control_every_s`` draws sparse control points from one).
"""

from __future__ import annotations

import numpy as np

from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics.spec import Table, protocol
from epa.steps import align, sync

KEY = "hilti"
# year: ([thresholds (m), strictly below], [points]); above the last: 0 points
BINS = {
    2022: ((0.01, 0.03, 0.06, 0.10), (10, 6, 3, 1)),
    2023: ((0.005, 0.01, 0.03, 0.06, 0.10, 0.40), (20, 10, 6, 5, 3, 1)),
}
POLE_TIP_2022_M = (0.059, -0.00855, 0.1964)  # T_imu_ref of the 2022 script (IMU to pole tip)
DENSE = 100  # more reference poses than this: a dense trajectory (the script's test)


def control_points(reference: Trajectory, every_s: float | None) -> Trajectory:
    """The control points: the reference itself (None), or its first pose at or after each
    ``t_0 + k · every_s``."""
    if every_s is None:
        return reference
    wanted = reference.t[0] + every_s * np.arange(
        int((reference.t[-1] - reference.t[0]) // every_s) + 1
    )
    idx = np.unique(np.searchsorted(reference.t, wanted, side="left"))
    return reference.select(idx[idx < len(reference)])


def lever(year: int, lever_arm_m) -> np.ndarray:
    """The point measured, in the estimate's body frame (m): the setting, else the year's."""
    if lever_arm_m is not None:
        return np.asarray(lever_arm_m, float)
    return np.asarray(POLE_TIP_2022_M if year == 2022 else (0.0, 0.0, 0.0))


def points(errors_m: np.ndarray, year: int) -> tuple[np.ndarray, list[int]]:
    """Points of each error, and how many errors fall in each bin (the last: above every threshold)."""
    thresholds, award = BINS[year]
    bin_of = np.searchsorted(np.asarray(thresholds), errors_m, side="right")  # e < th: that bin
    per_error = np.append(np.asarray(award), 0)[bin_of]
    return per_error, np.bincount(bin_of, minlength=len(thresholds) + 1).tolist()


def score(total_points: int, n_control: int, year: int) -> float:
    """The sum normalised to 100: ``total / (n / (100 / best))`` (2022: ``/ (n / 10)``, the script's)."""
    best = BINS[year][1][0]
    return total_points / (n_control / (100 / best))


def evaluate(
    control: Trajectory, estimate: Trajectory, *, year: int, lever_m: np.ndarray, max_diff_s: float
) -> dict:
    """One sequence's record (see the module's docstring)."""
    tips = estimate.p + np.einsum("nab,b->na", estimate.r, lever_m)
    i_ref, i_est = sync.associate_evo(control.t, estimate.t, max_diff_s)
    if len(i_ref) < 3:
        raise EpaError(
            f"metrics.{KEY}: {len(i_ref)} of the {len(control)} control points have an estimate"
            f" pose within {max_diff_s:g} s; the SE3 fit needs at least 3"
        )
    fit = align.umeyama(tips[i_est], control.p[i_ref])
    err = np.linalg.norm(control.p[i_ref] - (tips[i_est] @ fit.R.T + fit.t), axis=1)
    per_error, counts = points(err, year)
    return {
        "year": year,
        "lever_arm_m": lever_m.tolist(),
        "n_control_points": len(control),
        "n_matched": int(len(i_ref)),
        "rmse_m": float(np.sqrt(np.mean(err**2))),
        "mean_m": float(np.mean(err)),
        "median_m": float(np.median(err)),
        "std_m": float(np.std(err)),
        "min_m": float(np.min(err)),
        "max_m": float(np.max(err)),
        "thresholds_m": list(BINS[year][0]),
        "per_bin": counts,
        "points": int(per_error.sum()),
        "score": score(int(per_error.sum()), len(control), year),
    }


def compute(
    ref: Trajectory, est: Trajectory, cfg: dict, *, reference: Trajectory, estimate: Trajectory
) -> tuple[dict, dict, list[str]]:
    """The Hilti record of a case (its settings: ``metrics.hilti``).

    Parameters
    ----------
    ref, est : Trajectory
        epica's matched poses (not used: the challenge associates and aligns on its own).
    reference : Trajectory
        The whole cropped reference: the control points, or the trajectory they are drawn from.
    estimate : Trajectory
        The whole cropped estimate, as given (IMU frame).

    Returns
    -------
    (record, arrays, notes)
    """
    settings = cfg["metrics"][KEY]
    control = control_points(reference, settings["control_every_s"])
    year = settings["year"]
    if len(control) > DENSE:
        why = (
            f"{len(control)} control points (more than {DENSE}: a dense trajectory, which the"
            f" challenge does not score; set metrics.{KEY}.control_every_s)"
        )
        return (
            {"year": year, "n_control_points": len(control), "score": None, "reason": why},
            {},
            [f"{KEY}: no score: {why}"],
        )
    record = evaluate(
        control,
        estimate,
        year=year,
        lever_m=lever(year, settings["lever_arm_m"]),
        max_diff_s=settings["max_diff_s"],
    )
    return record, {}, []


def summary(record: dict) -> dict:
    """Empty unless metrics.hilti is on."""
    return {"hilti_score": record.get("score"), "hilti_rmse_m": record.get("rmse_m")}


METRIC = protocol(
    KEY,  # metrics.hilti: off by default; `epa eval --protocol hilti`
    summary=summary,
    compute=compute,
    inputs=("reference", "estimate"),
    summary_columns=("hilti_score", "hilti_rmse_m"),
    tables=(
        Table(
            KEY,
            "HILTI SLAM CHALLENGE SCORE (0-100 PER SEQUENCE)",
            pair=False,
            per_run=lambda r: (r["score"],),
            has=lambda r: r.get("score") is not None,
        ),
    ),
)
