"""Step 3: world-frame alignment of matched positions (Umeyama se3 / sim3, posyaw, none)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.records import SimilarityRecord
from epa.core.trajectory import Trajectory


class Method(StrEnum):
    """Step 3's fit: rigid, rigid with scale, position and yaw (4-DoF), or none."""

    SE3 = "se3"
    SIM3 = "sim3"
    POSYAW = "posyaw"
    NONE = "none"


METHODS = tuple(Method)


APPLY_BLOCK = 16384  # poses per block in Similarity.apply's rotations


@dataclass(frozen=True)
class Similarity:
    """x -> s R x + t."""

    R: np.ndarray
    t: np.ndarray
    s: float = 1.0

    def apply(self, traj: Trajectory, *, matrices: bool = False) -> Trajectory:
        """The trajectory in the target world frame. The local orientation error is unchanged by a
        world rotation; the position covariance turns with it and scales by s^2. Printed rotation
        blocks (KITTI) turn as evo and the devkit would turn a raw matrix: R times the printed one
        (its nearest rotation is R times theirs, so ``q`` turns as ever).

        The orientations turn by the quaternion product q_R q (3-4x cheaper than R's product with
        each matrix and Shepperd's method back: the same rotations up to rounding), the positions
        column by column; ``matrices``: by those matrices and BLAS's product, whose bits evo's
        commands and mode ov_eval print."""
        # in blocks of poses, the (N, 3, 3) temporaries in cache: R r's quaternions by the same
        # arithmetic as on all at once (each pose's own; 1.5x faster at 1M poses), the position
        # covariance's s^2 R C R^T with its products written out on component rows
        q = self._turned(traj.q) if not matrices else np.empty((len(traj), 4))
        cov_c = traj.cov_pos if traj.cov_rot is not None else None
        cov_pos = None if cov_c is None else np.empty_like(cov_c)
        s2_r = self.s**2 * self.R
        for start in range(0, len(traj) if matrices or cov_c is not None else 0, APPLY_BLOCK):
            at = slice(start, start + APPLY_BLOCK)
            if matrices:
                q[at] = geometry.rot_to_quat(self.R @ geometry.quat_to_rot(traj.q[at]))
            if cov_c is not None and cov_pos is not None:
                c = geometry.matmul_rows(s2_r, geometry.matrix_rows(cov_c[at]))
                turned = geometry.matmul_rows(c, self.R.T)
                for i, j in np.ndindex(3, 3):
                    cov_pos[at, i, j] = turned[i][j]
        p = self.s * traj.p @ self.R.T + self.t if matrices else self._moved(traj.p)
        extra = {} if traj.r_printed is None else {"r_printed": self.R @ traj.r_printed}
        if cov_pos is not None:
            extra.update(cov_rot=traj.cov_rot, cov_pos=cov_pos)
        return Trajectory(np.asarray(traj.t, float), np.asarray(p, float), q, **extra)

    def _moved(self, p: np.ndarray) -> np.ndarray:
        """s R p + t of (N, 3) positions, column by column: BLAS's product of (N, 3) rows starts
        threads whose spinning is counted (10-100x the 20 ms of CPU these take at 1M poses on a
        busy machine)."""
        p, sr = np.asarray(p, float), self.s * self.R
        out = np.empty(p.shape)
        for a in range(3):
            column = np.multiply(p[:, 0], sr[a, 0], out=out[:, a])
            column += sr[a, 1] * p[:, 1]
            column += sr[a, 2] * p[:, 2]
            column += self.t[a]
        return out

    def _turned(self, q: np.ndarray) -> np.ndarray:
        """q_R q of (N, 4) unit quaternions, normalised with w >= 0 as rot_to_quat gives them."""
        q_r = geometry.rot_to_quat(self.R)
        out = geometry.mul_rows(q_r, geometry.component_rows(q))
        norm = np.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3])
        out /= np.where(out[3] < 0, -norm, norm)
        return np.ascontiguousarray(out.T)

    def apply_rows(self, q_rows: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Orientations ((4, N) quaternion rows) and positions (N, 3) in the target world frame."""
        q = geometry.mul_rows(geometry.rot_to_quat(self.R), q_rows)
        return q, self.s * p @ self.R.T + self.t

    def inverse(self) -> Similarity:
        return Similarity(self.R.T, -self.R.T @ self.t / self.s, 1.0 / self.s)

    def to_dict(self) -> SimilarityRecord:
        return {
            "rotation": self.R.tolist(),
            "translation": self.t.tolist(),
            "scale": float(self.s),
            "quaternion_xyzw": geometry.rot_to_quat(self.R).tolist(),
            "yaw_deg": float(np.degrees(np.arctan2(self.R[1, 0], self.R[0, 0]))),
        }

    @staticmethod
    def from_dict(d: dict) -> Similarity:
        return Similarity(
            np.asarray(d["rotation"], float), np.asarray(d["translation"], float), float(d["scale"])
        )


IDENTITY = Similarity(np.eye(3), np.zeros(3), 1.0)


def umeyama(src: np.ndarray, dst: np.ndarray, *, with_scale: bool = False) -> Similarity:
    """Least-squares s, R, t with dst ≈ s·R·src + t (Umeyama 1991)."""
    return _umeyama(_centred(src), _centred(dst), with_scale=with_scale)


def _centred(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mean of the points and the points less it."""
    mu = pts.mean(axis=0)
    return mu, pts - mu


def _umeyama(
    src: tuple[np.ndarray, np.ndarray],
    dst: tuple[np.ndarray, np.ndarray],
    *,
    with_scale: bool,
    refuse_line: str | None = None,
) -> Similarity:
    """:func:`umeyama` of the centred points (:func:`_centred`). ``refuse_line``: the fit's name
    (``100 poses used by align se3``), to refuse points on one line (the second singular value of
    the cross-covariance below COLLINEAR times the first: the rotation about the line is
    arbitrary) from the singular values the fit computes anyway."""
    (mu_s, xs), (mu_d, xd) = src, dst
    cov = xd.T @ xs / len(xs)
    u, d, vt = np.linalg.svd(cov)
    if refuse_line is not None and d[1] <= COLLINEAR * d[0]:
        raise EpaError(
            f"the {refuse_line} lie on one straight line: the rotation about"
            " it is undetermined (use align.method: posyaw, or more poses via align.first_n)"
        )
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    r = u @ sign @ vt
    s = float(np.trace(np.diag(d) @ sign) / (np.sum(xs * xs) / len(xs))) if with_scale else 1.0
    return Similarity(r, mu_d - s * r @ mu_s, s)


def sim3_fit_rmse(src_rows: np.ndarray, dst_rows: np.ndarray) -> tuple[float, float]:
    """The scale of the Sim3 fit (Umeyama) of ``src`` onto ``dst`` and the position RMSE after it,
    on positions as component rows, in blocks: the temporaries stay in cache and no (N, 3) copy is
    made (a 1M-pose case's check is two passes over its rows). The residual is summed directly, not
    from the moments (whose difference loses 1e-8 of a centimetre RMSE on 100 m of path).

    Parameters
    ----------
    src_rows, dst_rows : ndarray, shape (3, N)
        Matched positions, x, y and z rows (:func:`epa.core.geometry.pair_rows` holds them).

    Returns
    -------
    scale, rmse : float
    """
    n = src_rows.shape[1]
    mu_s, mu_d = src_rows.mean(axis=1), dst_rows.mean(axis=1)
    cov, var_s = np.zeros((3, 3)), 0.0
    for part in geometry.row_blocks(n):
        xs, xd = src_rows[:, part] - mu_s[:, None], dst_rows[:, part] - mu_d[:, None]
        cov += xd @ xs.T
        var_s += float(np.einsum("ij,ij->", xs, xs))
    u, d, vt = np.linalg.svd(cov / n)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    scale = float(np.trace(np.diag(d) @ sign) / (var_s / n))
    sr = scale * (u @ sign @ vt)
    t = mu_d - sr @ mu_s
    squares = 0.0
    for part in geometry.row_blocks(n):
        r = dst_rows[:, part] - (sr @ src_rows[:, part] + t[:, None])
        squares += float(np.einsum("ij,ij->", r, r))
    return scale, float(np.sqrt(squares / n))


def posyaw(src: np.ndarray, dst: np.ndarray) -> Similarity:
    """Rotation about gravity (z) and translation only: the 4 DoF a VIO cannot observe."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    xs, xd = src - mu_s, dst - mu_d
    num = np.sum(xs[:, 0] * xd[:, 1] - xs[:, 1] * xd[:, 0])
    den = np.sum(xs[:, 0] * xd[:, 0] + xs[:, 1] * xd[:, 1])
    r = geometry.rot_z(np.arctan2(num, den))
    return Similarity(r, mu_d - r @ mu_s, 1.0)


def fit(ref: Trajectory, est: Trajectory, *, method: str = "se3", first_n: int = -1) -> Similarity:
    """The transform that maps the estimate onto the reference, from the first N matched poses (all if -1)."""
    if method not in METHODS:
        raise EpaError(f"unknown align method {method!r}; choose one of {', '.join(METHODS)}")
    if method == "none":
        return IDENTITY
    n = len(ref) if first_n is None or first_n < 0 else min(first_n, len(ref))
    need = 2 if method == "posyaw" else 3
    if n < need:
        what = (
            f"align.first_n is {first_n} ({len(ref)} poses matched)"
            if n < len(ref)
            else f"only {n} poses matched"
        )
        raise EpaError(f"align {method} needs at least {need} poses: {what}")
    src, dst = est.p[:n], ref.p[:n]
    # an alignment that the data do not determine would give an arbitrary rotation (and rotation
    # error) presented as a result: refuse it, naming what is degenerate
    if method == "posyaw":  # it rotates about z only: the horizontal spread
        _check_spread(_centred(dst[:, :2])[1], _centred(src[:, :2])[1], method, n)
        return posyaw(src, dst)
    centred = _centred(src), _centred(dst)  # shared by the checks and the fit
    _check_spread(centred[1][1], centred[0][1], method, n)
    return _umeyama(
        *centred, with_scale=method == "sim3", refuse_line=f"{n} poses used by align {method}"
    )


# Below this spread (m) the points are one point; below this ratio of the cross-covariance's second
# to first singular value they are one line, and the rotation about that line is arbitrary.
STILL_M = 1e-6
COLLINEAR = 1e-10


def _check_spread(xd: np.ndarray, xs: np.ndarray, method: str, n: int) -> None:
    """Refuse a side whose centred points (reference ``xd``, estimate ``xs``) do not move (their
    spread below STILL_M)."""
    for name, x in (("reference", xd), ("estimate", xs)):
        spread = float(np.sqrt(np.mean(geometry.dots(x, x))))
        if spread < STILL_M:
            plane = " horizontally" if method == "posyaw" else ""
            raise EpaError(
                f"the {name} does not move{plane} over the {n} poses used by align {method}"
                f" (spread {spread:.3g} m): the alignment is undetermined"
            )
