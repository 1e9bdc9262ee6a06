"""The trajectory value type: parallel arrays, never lists of 4x4 matrices."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from epa.core import geometry


def position_only(ref: Trajectory, est: Trajectory) -> str | None:
    """Which side has no orientation, as a clause ("the estimate is position-only"); None when both
    are full poses. Either side's lack makes every rotation error of the pair null."""
    sides = [
        name for name, traj in (("the reference", ref), ("the estimate", est)) if traj.position_only
    ]
    if not sides:
        return None
    return " and ".join(sides) + (" are" if len(sides) == 2 else " is") + " position-only"


def _every_index(idx, n: int) -> bool:
    """Whether ``idx`` is the integer array 0, 1, ..., n - 1."""
    if not isinstance(idx, np.ndarray) or idx.ndim != 1 or len(idx) != n:
        return False
    return bool(idx.dtype.kind in "iu" and geometry.consecutive(idx) and idx[0] == 0)


def _c_ordered(x: np.ndarray) -> np.ndarray:
    """``x`` itself where it is C-ordered already, else a C-ordered copy: the same values in the
    same layout either way, and a million poses' t and p (64 MB a pair) are not held twice."""
    return np.ascontiguousarray(x)


@dataclass(frozen=True)
class Trajectory:
    t: np.ndarray  # (N,) seconds
    p: np.ndarray  # (N, 3) metres
    q: np.ndarray  # (N, 4) unit quaternions (x, y, z, w); all NaN for a position-only source
    # Optional per-pose marginal covariances kept for consistency metrics:
    # orientation (N, 3, 3) rad^2 and position (N, 3, 3) m^2.
    cov_rot: np.ndarray | None = field(default=None, repr=False)
    cov_pos: np.ndarray | None = field(default=None, repr=False)
    # The full 6x6 pose covariance as ROS gives it (x y z, rotation about x y z), when the source is ROS.
    cov_ros: np.ndarray | None = field(default=None, repr=False)
    # Rotation blocks (N, 3, 3) exactly as a KITTI file prints them (orthonormal only to ~1e-7), kept
    # for the two tools that compute on them: evo's commands and the KITTI devkit metric. Every other
    # number is computed on ``q`` (their nearest rotations).
    r_printed: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def position_only(self) -> bool:
        """Whether the source gave positions only (``t x y z``): its orientations are NaN, never a
        rotation invented from positions, and they stay NaN through every stage's artifacts."""
        return len(self.q) > 0 and bool(np.isnan(self.q[0]).all())

    @property
    def r(self) -> np.ndarray:
        """Rotation matrices (N, 3, 3) of ``q``: orthonormal, also for a KITTI file's poses."""
        return geometry.quat_to_rot(self.q)

    @property
    def r_as_printed(self) -> np.ndarray:
        """The rotation blocks as the file printed them (``r_printed``), else ``r``: what evo and the
        KITTI devkit compute on."""
        return self.r if self.r_printed is None else self.r_printed

    def select(self, idx) -> Trajectory:
        if (
            isinstance(idx, np.ndarray)
            and idx.dtype == bool
            and len(idx) == len(self)
            and idx.all()
        ):
            return (
                self  # a mask that keeps every pose (a crop without limits): no copy, same arrays
            )
        # 0, 1, ..., n - 1 (every pose matched): the arrays themselves where C-ordered, else plain
        # copies (2x cheaper than gathers); C-ordered either way, as a gather gives them (the later
        # stages' bits depend on the layout, so never a strided view). No stage writes into a
        # trajectory's arrays, so sharing them is safe, as a crop without limits shares them.
        take = _c_ordered if _every_index(idx, len(self)) else (lambda x: x[idx])
        return replace(
            self,
            t=take(self.t),
            p=take(self.p),
            q=take(self.q),
            cov_rot=None if self.cov_rot is None else take(self.cov_rot),
            cov_pos=None if self.cov_pos is None else take(self.cov_pos),
            cov_ros=None if self.cov_ros is None else take(self.cov_ros),
            r_printed=None if self.r_printed is None else take(self.r_printed),
        )

    def without_covariance(self) -> Trajectory:
        """The same poses (the same arrays) without their covariances."""
        if self.cov_rot is None and self.cov_pos is None and self.cov_ros is None:
            return self
        return replace(self, cov_rot=None, cov_pos=None, cov_ros=None)

    def at(self, stamps: np.ndarray) -> Trajectory:
        """The poses at ``stamps``: linear positions, slerp orientations (clamped at the ends)."""
        p, q = geometry.interpolate(self.t, self.p, self.q, stamps)
        return Trajectory(np.asarray(stamps, float), p, q)

    def shifted(self, dt: float) -> Trajectory:
        return replace(self, t=self.t + dt)

    def length(self) -> float:
        return float(geometry.path_distances(self.p)[-1]) if len(self) else 0.0

    @staticmethod
    def positions(t, p) -> Trajectory:
        """A position-only trajectory: its orientations unknown (NaN)."""
        t = np.asarray(t, float)
        return Trajectory(t, np.asarray(p, float), np.full((len(t), 4), np.nan))

    @staticmethod
    def from_rp(t, r, p, **extra) -> Trajectory:
        """From rotation matrices ``r`` (``extra``: the other fields, printed rotation blocks included)."""
        return Trajectory(
            np.asarray(t, float), np.asarray(p, float), geometry.rot_to_quat(r), **extra
        )
