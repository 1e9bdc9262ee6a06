"""The records that cross stages, typed at their edges: what ``03_sync/sync.json``,
``04_calibrate/calibrate.json``, ``05_align/transform.json`` and ``06_metrics/metrics.json`` hold.

The steps (:mod:`epa.steps`) and :func:`epa.metrics.accuracy.evaluate` return the parts they build
under these types; the stage modules assemble them into the files; later stages and the outputs read
them back. Each declaration lists the keys a run writes, ``NotRequired`` where a path or a setting
leaves one out (``tests/test_records.py`` holds every record of the bundled example and the ``.test``
modes to them). Types are the values in memory; a written non-finite number is ``null`` or text.
No ``from __future__ import annotations`` here: TypedDict sees NotRequired only in evaluated ones."""

from typing import NotRequired, TypedDict


class Statistics(TypedDict):
    """One quantity's statistics (:func:`epa.metrics.accuracy.stats`): None for each statistic of
    an empty sample, whose record says why in a note."""

    n: int
    rmse: float | None
    mean: float | None
    median: float | None
    std: float | None
    min: float | None
    max: float | None


class ErrorStatistics(TypedDict):
    """Translation (m) and rotation (deg) errors of a set of poses or pose pairs."""

    trans_m: Statistics
    rot_deg: Statistics


class TimeRpe(ErrorStatistics):
    """The RPE over ``metrics.time_delta``; its key is :func:`epa.metrics.accuracy.time_rpe_key`."""

    delta_s: float


class EvoRpe(ErrorStatistics):
    """One ``metrics.rpe`` entry in evo's semantics: its settings as given, then its errors."""

    delta: float
    unit: str
    all_pairs: NotRequired[bool]
    rel_tol: NotRequired[float]
    pairs_from: NotRequired[str]


class AccuracyRecord(TypedDict):
    """What :func:`epa.metrics.accuracy.evaluate` computes, in this order, with the time RPE
    (:class:`TimeRpe`) between ``drift_rate_pct`` and ``rpe`` under the key
    ``rpe_time_<time_delta>s``, which a TypedDict cannot name."""

    n_matched: int
    ref_length_m: float
    duration_s: float
    ate: ErrorStatistics
    rpe_distance: dict[str, ErrorStatistics]  # by segment length, as segment_key spells it
    drift_rate_pct: dict[str, float | None]
    rpe: list[EvoRpe]


class Step1Record(TypedDict):
    """Step 1 (:meth:`epa.steps.sync.OffsetEstimate.to_dict`): the offset used and why; the
    correlation's figures only where it ran (not with ``sync.estimate_offset: false``)."""

    offset: float
    estimated: float | None
    used: bool
    reason: str
    status: str  # a Step1Status
    std: float | None
    peak_corr: NotRequired[float | None]
    peak_ratio: NotRequired[float | None]
    beyond_window_corr: NotRequired[float | None]
    ref_motion_rad_s: NotRequired[float | None]
    est_motion_rad_s: NotRequired[float | None]
    dt: NotRequired[float | None]


class Association(TypedDict):
    """An association under the ``sync`` settings (``epa.workflow.stages.sync.associate``)."""

    offset_s: float
    max_diff_s: float
    n_matched: int
    n_ref: int
    n_est: int


class MatchedLength(TypedDict):
    ref: float
    est: float


class SyncRecord(Association):
    """``03_sync/sync.json``."""

    mode: str
    policy: str
    step1: Step1Record
    matched_length_m: MatchedLength


class ExtrinsicRecord(TypedDict):
    """Step 2's extrinsic (:meth:`epa.steps.calibrate.Extrinsic.to_dict`): the solution, then what
    the solve found as far as it got (a solve stopped by too little motion has only ``pairs`` and
    ``pair_step_s``, or also the rotation pairs)."""

    trusted: bool
    status: str  # a Step2Status
    reason: str
    rotation: list[list[float]]
    quaternion_xyzw: list[float]
    rotation_deg: float
    translation_m: list[float]
    translation_norm_m: float
    scale: float
    pairs: int
    pair_step_s: float
    rotation_pairs: NotRequired[int]
    excitation_rms_deg: NotRequired[float]
    rotation_inliers: NotRequired[int]
    rotation_residual_rms_deg: NotRequired[float]
    rotation_singular_values: NotRequired[list[float]]
    rotation_condition: NotRequired[float]
    translation_singular_values: NotRequired[list[float]]
    translation_condition: NotRequired[float]
    translation_unobservable_directions: NotRequired[list[list[float]]]
    scale_unobservable: NotRequired[bool]
    translation_inliers: NotRequired[int]
    translation_residual_rms_m: NotRequired[float]
    offset_std_s: NotRequired[float]
    rotation_std_deg: NotRequired[list[float | None]]
    translation_std_m: NotRequired[list[float | None]]
    scale_std: NotRequired[float | None]
    rotation_unobservable_axes: NotRequired[list[str]]
    rotation_covariance_rad2: NotRequired[list[list[float | None]]]
    translation_covariance: NotRequired[list[list[float | None]]]
    notes: NotRequired[list[str]]  # the stage's: why an uncertainty entry is None


class PlanRecord(TypedDict):
    """How a case is evaluated (:func:`epa.steps.plan.evaluation_plan`)."""

    eval_source: str  # epa, ov_eval or rpg
    fallback: bool
    offset_s: float
    apply_extrinsic: bool
    reason: str
    dropped: NotRequired[list[str]]  # a fallback: what it left out of the configured evaluation


class CalibrateRecord(TypedDict):
    """``04_calibrate/calibrate.json``: Step 2 (None where it did not run) and the plan."""

    mode: str
    extrinsic: ExtrinsicRecord | None
    step2_status: str  # a Step2Status
    reassociated: NotRequired[Association]  # the plan dropped Step 1's offset: associated again
    eval_source: str
    reason: str
    plan: PlanRecord


class SimilarityRecord(TypedDict):
    """A similarity transform (:meth:`epa.steps.align.Similarity.to_dict`)."""

    rotation: list[list[float]]
    translation: list[float]
    scale: float
    quaternion_xyzw: list[float]
    yaw_deg: float


class TransformRecord(SimilarityRecord):
    """``05_align/transform.json``: Step 3's method, then its fit (in rpg's arithmetic in mode rpg)."""

    method: str
    first_n: int
    fallback: bool  # Steps 1-2 dropped (untrusted): the configured alignment all the same


class MetricsRecord(TypedDict):
    """``06_metrics/metrics.json``: what load and Steps 1-3 found, then :class:`AccuracyRecord`'s
    keys in its order (the time RPE under its key), each registered metric's record under its key
    where that metric is on, then the records of load, sync and calibrate."""

    n_matched: int
    eval_source: str
    time_offset_s: float
    extrinsic_rot_deg: float | None
    extrinsic_trans_m: float | None
    alignment: TransformRecord
    ref_length_m: float
    duration_s: float
    ate: ErrorStatistics
    rpe_distance: dict[str, ErrorStatistics]
    drift_rate_pct: dict[str, float | None]
    rpe: list[EvoRpe]
    est_length_m: float
    notes: list[str]
    load: dict
    sync: SyncRecord
    calibrate: CalibrateRecord
