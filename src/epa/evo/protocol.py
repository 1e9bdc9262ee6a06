"""evo's APE and RPE protocol on epica's readers and formulas: what `epa ape` and `epa rpe` run.

The order is evo 1.38.1's (main_ape / main_rpe): cut the reference to [t_start, t_end], associate
(nearest stamp within t_max_diff after adding t_offset to the estimate, or interpolate the denser
trajectory at the sparser one's matched stamps), align (Umeyama SE(3), Sim(3), scale only, or the
first pose), project to a plane, then the pose relation and the statistics block. Steps 1 and 2 run
only when asked for (``step1``: the offset found by Step 1 is added to ``t_offset``).

Every formula is the library's: association (:mod:`epa.steps.sync`), Umeyama (:mod:`epa.steps.align`), pairs
(:func:`epa.metrics.accuracy.evo_pairs`), pose relations (:mod:`epa.metrics.relations`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import accuracy, relations
from epa.steps import align as alignment
from epa.steps import sync

# evo's -u letters -> evo_pairs units
DELTA_UNITS = {"f": "frames", "d": "deg", "r": "rad", "m": "m"}
PLANES = ("xy", "xz", "yz")
SYNC_METHODS = ("nearest_time", "interpolation")


@dataclass(frozen=True)
class EvoOptions:
    relation: str = "trans_part"
    align: bool = False
    correct_scale: bool = False
    n_to_align: int = -1
    align_origin: bool = False
    align_posyaw: bool = False  # not in evo 1.38.1: its pending 4-DoF alignment, as epica's posyaw
    project_to_plane: str | None = None
    t_max_diff: float = 0.01
    t_offset: float = 0.0
    t_start: float | None = None
    t_end: float | None = None
    sync_method: str = "nearest_time"
    step1: bool = False
    # RPE only
    delta: float = 1.0
    delta_unit: str = "f"
    delta_tol: float = 0.1
    all_pairs: bool = False
    pairs_from_reference: bool = False


@dataclass
class EvoResult:
    kind: str  # "ape" | "rpe"
    title: str
    errors: np.ndarray
    stats: dict
    options: dict
    info: dict = field(default_factory=dict)
    # what the errors were computed on, for evo's result zip and figures: the matched reference and
    # estimate, aligned and projected; the RPE's pair ends (evo's delta_ids, one per error); evo's
    # alignment_transformation_sim3 (4x4); whether the poses have stamps (not KITTI's)
    ref: Trajectory | None = field(default=None, repr=False)
    est: Trajectory | None = field(default=None, repr=False)
    ends: np.ndarray | None = field(default=None, repr=False)
    sim3: np.ndarray | None = field(default=None, repr=False)
    timed: bool = True

    @property
    def unit(self) -> str:
        """evo's unit of the errors (its Unit enum's value)."""
        return relations.UNIT[self.options["relation"]] or "unit-less"

    def statistics_block(self) -> str:
        """evo's printout: the title, a blank line, one `name<TAB>value` line per statistic (sorted)."""
        lines = [f"{name:>10}\t{value:.6f}" for name, value in sorted(self.stats.items())]
        return f"{self.title}\n\n" + "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- steps
def cut_reference(ref: Trajectory, t_start: float | None, t_end: float | None) -> Trajectory:
    """The reference within [t_start, t_end] (evo reduces the reference only; 0 counts as not given)."""
    if not (t_start or t_end):
        return ref
    start = ref.t[0] if t_start is None else t_start
    end = ref.t[-1] if t_end is None else t_end
    if start > end:
        raise EpaError(f"--t_start {start} is after --t_end {end}")
    keep = np.flatnonzero((ref.t >= start) & (ref.t <= end))
    if len(keep) == 0:
        raise EpaError(f"no reference pose between --t_start {start} and --t_end {end}")
    return ref.select(keep)


def synchronise(ref: Trajectory, est: Trajectory, o: EvoOptions) -> tuple[Trajectory, Trajectory]:
    """Matched copies, as evo's associate_trajectories: the shorter trajectory keeps its matched poses;
    the longer is either its nearest poses or, with interpolation, resampled at those stamps."""
    if o.sync_method not in SYNC_METHODS:
        raise EpaError(
            f"unknown --sync_method {o.sync_method!r}; choose one of {', '.join(SYNC_METHODS)}"
        )
    i_ref, i_est = sync.associate_evo(ref.t, est.t, o.t_max_diff, o.t_offset)
    if len(i_ref) == 0:
        raise EpaError(
            f"found no matching timestamps between reference and estimate with max. time diff "
            f"{o.t_max_diff} (s) and time offset {o.t_offset} (s)"
        )
    if o.sync_method == "nearest_time":
        return ref.select(i_ref), est.select(i_est)
    # the estimate is denser: resample it at the reference's stamps in its own clock
    if len(est) > len(ref):
        r = ref.select(i_ref)
        return r, est.at(r.t - o.t_offset)
    e = est.select(i_est)
    return ref.at(e.t + o.t_offset), e


def _sim3(fit: alignment.Similarity) -> np.ndarray:
    """The fit as evo's lie_algebra.sim3 writes it: [[s R, t], [0, 1]]."""
    m = np.eye(4)
    m[:3, :3] = fit.s * fit.R
    m[:3, 3] = fit.t
    return m


def align(
    ref: Trajectory, est: Trajectory, o: EvoOptions
) -> tuple[Trajectory, alignment.Similarity | None, np.ndarray | None]:
    """The estimate aligned as evo's flags say (-a, -s, -as, --n_to_align, --align_origin), or on
    position and yaw only (``--align_posyaw``: 4 degrees of freedom, for VIO whose roll and pitch
    gravity makes observable; Step 3's ``posyaw``). Also the transformation as evo records it
    (alignment_transformation_sim3): with -s alone, the whole Sim(3) fit, of which only the scale
    is applied."""
    if o.align and o.align_origin:
        raise EpaError("--align and --align_origin can't be used together")
    if o.align_posyaw:
        if o.align or o.align_origin or o.correct_scale:
            raise EpaError("--align_posyaw aligns alone: not with -a, --align_origin or -s")
        fit = alignment.fit(ref, est, method="posyaw", first_n=o.n_to_align)
        return fit.apply(est, matrices=True), fit, _sim3(fit)
    if o.align or o.correct_scale:
        fit = alignment.fit(
            ref, est, method="sim3" if o.correct_scale else "se3", first_n=o.n_to_align
        )
        recorded = _sim3(fit)
        if not o.align:  # -s alone: the scale only
            fit = alignment.Similarity(np.eye(3), np.zeros(3), fit.s)
        return fit.apply(est, matrices=True), fit, recorded
    if o.align_origin:
        r0, p0 = ref.r_as_printed[0], est.r_as_printed[0]
        rot = r0 @ p0.T
        fit = alignment.Similarity(rot, ref.p[0] - rot @ est.p[0], 1.0)
        return fit.apply(est, matrices=True), fit, _sim3(fit)
    return est, None, None


def project(traj: Trajectory, plane: str) -> Trajectory:
    """evo's projection: the out-of-plane coordinate set to 0 and the orientation replaced by its
    rotation about the plane's normal (that axis's static-xyz Euler angle)."""
    normal = {"xy": 2, "xz": 1, "yz": 0}[plane]
    m = traj.r_as_printed
    cy = np.hypot(m[:, 0, 0], m[:, 1, 0])
    regular = cy > 4 * np.finfo(float).eps
    angle = [
        np.where(regular, np.arctan2(m[:, 2, 1], m[:, 2, 2]), np.arctan2(-m[:, 1, 2], m[:, 1, 1])),
        np.arctan2(-m[:, 2, 0], cy),
        np.where(regular, np.arctan2(m[:, 1, 0], m[:, 0, 0]), 0.0),
    ][normal]
    q = np.zeros((len(traj), 4))
    q[:, normal] = np.sin(angle / 2)
    q[:, 3] = np.cos(angle / 2)
    p = traj.p.copy()
    p[:, normal] = 0.0
    return Trajectory(traj.t, p, q)


def _title(head: str, o: EvoOptions) -> str:
    only_scale = o.correct_scale and not o.align
    if o.align:
        head += (
            "\n(with Sim(3) Umeyama alignment)"
            if o.correct_scale
            else "\n(with SE(3) Umeyama alignment)"
        )
    elif only_scale:
        head += "\n(scale corrected)"
    elif not o.align_origin and not o.align_posyaw:
        head += "\n(not aligned)"
    if o.align_posyaw:
        head += "\n(with position and yaw (4-DoF) alignment)"
    if (o.align or o.correct_scale or o.align_posyaw) and o.n_to_align != -1:
        head += f" (aligned poses: {o.n_to_align})"
    if o.align_origin:
        head += "\n(with origin alignment)"
    if o.project_to_plane:
        head += f"\n(projected to {o.project_to_plane} plane)"
    return head


def _relation_head(kind: str, relation: str) -> str:
    unit = relations.UNIT[relation] or "unit-less"
    return f"{kind.upper()} w.r.t. {relations.TITLE[relation]} ({unit})"


def prepare(ref: Trajectory, est: Trajectory, o: EvoOptions, *, timed: bool = True):
    """Reference and estimate matched, aligned and projected; info on what was done; the alignment
    as evo records it (or None)."""
    if o.project_to_plane is not None and o.project_to_plane not in PLANES:
        raise EpaError(
            f"unknown --project_to_plane {o.project_to_plane!r}; choose one of {', '.join(PLANES)}"
        )
    info: dict = {}
    if timed:
        if o.step1:
            found = sync.estimate_offset(ref, est, smooth_fft=False)  # the bits it has printed
            if not found.used:
                raise EpaError(
                    f"Step 1 found no trustworthy time offset ({found.reason}); give --t_offset instead"
                )
            # Step 1's offset is what to add to the estimate's stamps, as evo's --t_offset
            o = EvoOptions(**{**asdict(o), "t_offset": o.t_offset + found.offset})
            info["step1_offset_s"] = found.offset
        ref = cut_reference(ref, o.t_start, o.t_end)
        ref, est = synchronise(ref, est, o)
    elif len(ref) != len(est):
        raise EpaError(
            f"without timestamps the trajectories must have the same number of poses "
            f"(reference {len(ref)}, estimate {len(est)})"
        )
    info["n_matched"] = len(ref)
    est, fit, sim3 = align(ref, est, o)
    if fit is not None:
        info["alignment"] = fit.to_dict()
    if o.project_to_plane:
        ref, est = project(ref, o.project_to_plane), project(est, o.project_to_plane)
    return ref, est, o, info, sim3


def ape(ref: Trajectory, est: Trajectory, o: EvoOptions, *, timed: bool = True) -> EvoResult:
    ref, est, o, info, sim3 = prepare(ref, est, o, timed=timed)
    errors = relations.ape(ref, est, o.relation)
    return EvoResult(
        "ape",
        _title(_relation_head("ape", o.relation), o),
        errors,
        relations.evo_statistics(errors),
        asdict(o),
        info,
        ref=ref,
        est=est,
        sim3=sim3,
        timed=timed,
    )


def rpe(ref: Trajectory, est: Trajectory, o: EvoOptions, *, timed: bool = True) -> EvoResult:
    if o.delta_unit not in DELTA_UNITS:
        raise EpaError(
            f"unknown --delta_unit {o.delta_unit!r}; choose one of {', '.join(DELTA_UNITS)}"
        )
    if not (np.isfinite(o.delta) and o.delta > 0):  # a negative or zero delta relates no poses
        raise EpaError(f"--delta must be positive, not {o.delta:g}")
    if o.delta_unit == "f" and float(o.delta) != int(o.delta):
        raise EpaError(f"--delta must be an integer for delta unit f (frames), not {o.delta}")
    ref, est, o, info, sim3 = prepare(ref, est, o, timed=timed)
    i, j = accuracy.evo_pairs(
        ref if o.pairs_from_reference else est,
        o.delta,
        DELTA_UNITS[o.delta_unit],
        all_pairs=o.all_pairs,
        rel_tol=o.delta_tol,
    )
    if len(i) == 0:
        raise EpaError(
            f"delta = {o.delta} ({o.delta_unit}) produced no pose pairs: try a smaller delta "
            f"or a larger --delta_tol"
        )
    errors = relations.rpe(ref, est, i, j, o.relation)
    ends = j
    if (
        o.relation == "point_distance_error_ratio"
    ):  # the pairs relations.rpe keeps: a moved reference
        ends = j[np.linalg.norm(ref.p[j] - ref.p[i], axis=1) != 0]
    delta = int(o.delta) if o.delta_unit == "f" else o.delta
    head = (
        _relation_head("rpe", o.relation)
        + f"\nfor delta = {delta} ({DELTA_UNITS[o.delta_unit]})"
        + (" using all pairs" if o.all_pairs else " using consecutive pairs")
    )
    return EvoResult(
        "rpe",
        _title(head, o),
        errors,
        relations.evo_statistics(errors),
        asdict(o),
        {**info, "n_pairs": int(len(i))},
        ref=ref,
        est=est,
        ends=np.asarray(ends),
        sim3=sim3,
        timed=timed,
    )
