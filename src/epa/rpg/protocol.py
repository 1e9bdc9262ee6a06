"""The arithmetic of uzh-rpg's rpg_trajectory_evaluation (``analyze_trajectory_single.py``), quirks included,
in one namespace: the association and alignment live in :mod:`epa.steps.rpg`, the errors and statistics in
:mod:`epa.metrics.rpg` (below the workflow, so ``mode: rpg`` runs the same functions as ``epa rpg``).

Every function names the rpg function it reproduces. Quaternions are ``(qx, qy, qz, qw)`` as in rpg's files
and its ``transformations.py``. Nothing here reads or writes files (that is :mod:`epa.rpg.command`).

The quirks kept on purpose (each is rpg's behaviour, not an oversight here):

* association (``associate_timestamps.associate``): every (estimate, groundtruth) pair closer than 0.02 s
  (strictly) is a candidate; candidates are taken greedily by (time difference, estimate index,
  groundtruth index), each pose at most once. The offset is added to the groundtruth stamp
  (``abs(a - (b + offset))``); rpg always passes 0.
* ``posyaw`` / ``se3`` with ``align_num_frames == 1`` align on the first matched pose only: ``se3`` takes
  ``R_gt0 R_es0^T``, ``posyaw`` the best yaw of ``R_es0 R_gt0^T``; the translation maps the first position.
  Otherwise Umeyama on the first n matched positions (-1: all); ``posyaw`` keeps only a yaw, chosen from
  the cross-covariance ``data^T model`` (no 1/n), scale 1. ``sim3`` needs n >= 2 or -1.
* the yaw rotation is built as rpg's ``rotation_matrix(theta, [0, 0, 1])``: its (2, 2) entry is
  ``cos + (1 - cos)``, not exactly 1.
* the absolute ``scale`` error is ``|(|p_es_aligned| / |p_gt|) - 1| * 100`` per pose: ``np.diff(p, 0)`` in
  rpg is the positions themselves, so it is a ratio of distances from the origin, not of motions.
* the absolute rotation error uses rpg's ``logmap_so3``, whose small-angle branch (trace > 3 - 1e-7) uses
  ``0.5 - (tr - 3)^2 / 12``.
* relative-error distances are 10..50 % of the length of the whole (time-window filtered) raw groundtruth,
  truncated (not rounded) to two decimals; the pairs use the accumulated length of the *matched*
  groundtruth positions.
* pair selection (``compute_comparison_indices_length``): for each start index, the first index at or
  after it whose accumulated distance is closest to start + d, if closer than 0.2 d (strictly); starts
  without such an end are skipped, yet the k-th kept pair then starts at index k (rpg enumerates the list
  of end indices), not at the start index that found it. Fewer than 2 pairs: no samples.
* relative errors use the *unaligned* estimate; only the Sim3 scale (1 for the other alignments) multiplies
  the estimate's relative translation. The error ``inv(T_gt1_gt2) * T_es1_es2`` is conjugated by the
  estimate's end orientation; yaw and gravity (pitch/roll norm) are its 'rzyx' Euler angles in degrees,
  ``rot`` its angle (arccos of the clipped trace), ``trans_perc = |t| / d * 100``,
  ``rot_deg_per_m = rot / d``.
* statistics (``results_writer.compute_statistics``): population std, and integer zeros with
  ``num_samples: 0`` for an empty vector.

The operations are rpg's, in rpg's order (the same squared norms, matrix products, inverses and
conversions, vectorised only where numpy gives the same bits), so the statistics equal rpg's bit for bit
under the same numpy: the arccos of a small rotation angle amplifies a last-bit difference ~1e6 times.
"""

from epa.metrics.rpg import (
    BOXPLOT_PERCENTAGES,
    REL_LABELS,
    REL_METRICS,
    STAT_KEYS,
    absolute_errors,
    boxplot_distances,
    comparison_indices,
    distance_from_start,
    errors,
    euler_rzyx,
    multi_trial_statistics,
    path_length,
    relative_errors,
    rotation_angle_deg,
    statistics,
    truncate,
)
from epa.steps.rpg import (
    ALIGN_TYPES,
    EPS,
    MAX_DIFF,
    align,
    apply_alignment,
    associate,
    best_yaw,
    quaternion_from_matrix,
    quaternion_matrix,
    rot_z,
    umeyama,
)

__all__ = [
    "ALIGN_TYPES",
    "BOXPLOT_PERCENTAGES",
    "EPS",
    "MAX_DIFF",
    "REL_LABELS",
    "REL_METRICS",
    "STAT_KEYS",
    "absolute_errors",
    "align",
    "apply_alignment",
    "associate",
    "best_yaw",
    "boxplot_distances",
    "comparison_indices",
    "distance_from_start",
    "errors",
    "euler_rzyx",
    "multi_trial_statistics",
    "path_length",
    "quaternion_from_matrix",
    "quaternion_matrix",
    "relative_errors",
    "rot_z",
    "rotation_angle_deg",
    "statistics",
    "truncate",
    "umeyama",
]
