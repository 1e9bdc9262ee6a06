"""Step 2: the sensor-to-body extrinsic (hand-eye calibration) from matched relative motions.

Model: the reference gives body poses T_WB(t), the estimate sensor poses T_VC(t) in its own world V,
and X = T_BC is fixed. For motion pairs (i, j): A = T_WB,i^-1 T_WB,j, B = T_VC,i^-1 T_VC,j, and
A X = X B. Rotation: rotvec(R_A) = R_X rotvec(R_B) (Kabsch over all pairs, with residual
rejection). Translation: (R_A - I) t_X - s R_X t_B = -t_A, linear in t_X and the optional scale s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, cast

import numpy as np

from epa.core import geometry
from epa.core.records import ExtrinsicRecord
from epa.core.stamps import closest_pairs
from epa.core.trajectory import Trajectory


class Step2Status(StrEnum):
    """What Step 2 concluded; anything but trusted means the extrinsic was not applied. The values are
    the strings calibrate.json and summary.csv hold."""

    TRUSTED = "trusted"
    DISABLED = "disabled"
    NOT_RUN = "not run"
    TOO_LITTLE_MOTION = "too little motion"
    UNOBSERVABLE = "unobservable"
    LARGE_RESIDUAL = "large residual"
    UNCERTAIN = "uncertain"


@dataclass
class Extrinsic:
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    trusted: bool = False
    reason: str = ""
    status: str = "trusted"  # a Step2Status
    info: dict = field(default_factory=dict)

    def apply(self, est: Trajectory) -> Trajectory:
        """Sensor poses (scaled) -> body poses: T_VB = T_VC X^-1, covariance carried along.

        With the local orientation error (R_true = R Exp(d)): d_body = R_x d_sensor, and
        p_b = s p_c - R_b t_x moves the position error by s dp + R_b [t_x]x d_body. Only the
        orientation and position blocks are known (no cross-covariance), so the lever arm adds
        R_b [t_x]x Cov_rot [t_x]x^T R_b^T to the position block."""
        n = len(est)
        # (N, 3, 3) @ (3, 3) as one (3N, 3) BLAS product: each row of R_C times R^T
        r_b = (est.r.reshape(-1, 3) @ self.R.T).reshape(n, 3, 3)
        p_b = self.scale * est.p - (r_b.reshape(-1, 3) @ self.t).reshape(n, 3)
        # printed rotation blocks (KITTI) take the same right factor: what the devkit's raw matrices would
        extra = {} if est.r_printed is None else {"r_printed": est.r_printed @ self.R.T}
        if est.cov_rot is not None and est.cov_pos is not None:
            cov_rot = self.R @ est.cov_rot @ self.R.T
            lever = (r_b.reshape(-1, 3) @ geometry.skew(self.t)).reshape(n, 3, 3)
            cov_pos = self.scale**2 * est.cov_pos + lever @ cov_rot @ lever.transpose(0, 2, 1)
            extra.update(cov_rot=cov_rot, cov_pos=cov_pos)
        return Trajectory.from_rp(est.t, r_b, p_b, **extra)

    def to_sensor_rp(self, r_b: np.ndarray, p_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The inverse of :meth:`apply` on rotations and positions: body poses -> sensor poses."""
        return r_b @ self.R, (p_b + np.einsum("nab,b->na", r_b, self.t)) / self.scale

    @staticmethod
    def from_dict(d: dict) -> Extrinsic:
        """The transform of a ``to_dict`` record (what calibrate.json holds)."""
        return Extrinsic(
            R=np.asarray(d["rotation"], float),
            t=np.asarray(d["translation_m"], float),
            scale=float(d["scale"]),
            trusted=bool(d["trusted"]),
            reason=d["reason"],
            status=d.get("status", "trusted" if d["trusted"] else "untrusted"),
        )

    def to_dict(self) -> ExtrinsicRecord:
        record = {
            "trusted": self.trusted,
            "status": self.status,
            "reason": self.reason,
            "rotation": self.R.tolist(),
            "quaternion_xyzw": geometry.rot_to_quat(self.R).tolist(),
            "rotation_deg": float(np.degrees(geometry.rotation_angle(self.R))),
            "translation_m": self.t.tolist(),
            "translation_norm_m": float(np.linalg.norm(self.t)),
            "scale": float(self.scale),
            **self.info,
        }
        # info's keys are the solve's, gathered as far as it got: ExtrinsicRecord's NotRequired ones
        return cast(ExtrinsicRecord, record)


def _kabsch(h: np.ndarray):
    """R minimising sum |alpha - R beta|^2 from the cross-covariance h = sum beta alpha^T, and h's
    singular values."""
    u, s, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T, s


def solve(
    ref: Trajectory,
    est: Trajectory,
    *,
    pair_step: float = 1.0,
    min_rotation_deg: float = 2.0,
    scale: bool = False,
    max_rot_residual_deg: float = 2.0,
    max_trans_residual_m: float = 0.2,
    max_condition: float = 100.0,
    min_pairs: int = 20,
    outlier_iterations: int = 3,
    max_rot_std_deg: float = 1.0,
    max_trans_std_m: float = 0.05,
    max_scale_std: float = 0.02,
    offset_std: float = 0.0,
) -> Extrinsic:
    """Hand-eye calibration over all pose pairs ``pair_step`` seconds apart (on matched poses),
    with the standard deviation of every parameter (:func:`_sandwich`) and the directions the
    motion leaves unobservable. Trusted only when everything is observed, the residuals are small
    and the deviations within ``max_*_std``.

    ``offset_std`` (s), Step 1's uncertainty, is carried into those deviations: a wrong offset
    pairs each estimate pose with a slightly different reference pose and bends the solution. The
    solve is repeated on the reference moved by +-offset_std and half the difference is added."""
    fit: dict[str, Any] = dict(
        pair_step=pair_step,
        min_rotation_deg=min_rotation_deg,
        scale=scale,
        max_condition=max_condition,
        min_pairs=min_pairs,
        outlier_iterations=outlier_iterations,
    )
    motions: dict = {}  # the estimate's motion pairs, shared by the three solves when their pairs are
    ext, cov_rot, null_rot, cov_x, null_x = _fit(ref, est, **fit, motions=motions)
    if cov_rot is None:
        return ext
    if offset_std > 0:
        ends = []
        for sign in (1.0, -1.0):  # only their solutions are used: no covariances
            shifted = ref.at(ref.t + sign * offset_std)
            ends.append(_fit(shifted, est, **fit, motions=motions, solution_only=True)[0])
        d_rot = geometry.so3_log(ends[0].R @ ends[1].R.T) / 2
        d_x = (np.r_[ends[0].t, ends[0].scale] - np.r_[ends[1].t, ends[1].scale])[: len(cov_x)] / 2
        cov_rot, cov_x = cov_rot + np.outer(d_rot, d_rot), cov_x + np.outer(d_x, d_x)
        ext.info["offset_std_s"] = float(offset_std)
    ext.info.update(_uncertainty(cov_rot, null_rot, cov_x, null_x, scale))
    return _verdict(
        ext,
        scale,
        max_rot_residual_deg,
        max_trans_residual_m,
        max_rot_std_deg,
        max_trans_std_m,
        max_scale_std,
    )


def _fit(
    ref: Trajectory,
    est: Trajectory,
    *,
    pair_step,
    min_rotation_deg,
    scale,
    max_condition,
    min_pairs,
    outlier_iterations,
    motions: dict | None = None,
    solution_only: bool = False,
):
    """The solve, and the covariances and unobservable directions of rotation and translation (all
    None when too little motion left nothing to solve, or not asked for: ``solution_only``).
    ``motions`` keeps the estimate's motion pairs from one call to the next: the same pairs give the
    same motions, so they are computed once."""
    i, j = closest_pairs(ref.t - ref.t[0], pair_step, 0.25 * pair_step, strict=False, skip=1)
    info: dict = {"pairs": int(len(i)), "pair_step_s": pair_step}
    if len(i) < min_pairs:
        return _too_little(f"only {len(i)} motion pairs ({min_pairs} needed)", info)
    qa, ta = geometry.relative_motions(ref.q, ref.p, i, j)
    kept = None if motions is None else motions.get("pairs")
    if (
        motions is not None
        and kept is not None
        and np.array_equal(kept[0], i)
        and np.array_equal(kept[1], j)
    ):
        qb, tb, beta = motions["estimate"]
    else:
        qb, tb = geometry.relative_motions(est.q, est.p, i, j)
        beta = geometry.quat_log(qb)
        if motions is not None:
            motions.update(pairs=(i, j), estimate=(qb, tb, beta))
    alpha = geometry.quat_log(qa)
    angle = np.degrees(geometry.norms(alpha))
    use = angle >= min_rotation_deg
    info["rotation_pairs"] = int(use.sum())
    info["excitation_rms_deg"] = float(np.sqrt(np.mean(angle[use] ** 2))) if use.any() else 0.0
    if use.sum() < min_pairs:
        return _too_little(
            f"too little rotation: {int(use.sum())} pairs rotate more than"
            f" {min_rotation_deg} deg ({min_pairs} needed)",
            info,
        )
    # Pairs overlap in time, so the residuals are grouped in blocks (see _sandwich).
    block = np.floor((ref.t[i] - ref.t[0]) / (2.0 * pair_step)).astype(int)
    r_x, cov_rot, null_rot = _solve_rotation(
        alpha, beta, use, block, min_pairs, outlier_iterations, max_condition, info, solution_only
    )
    # the translation equations need (R_A - I) as matrices
    x, cov_x, null_x = _solve_translation(
        geometry.quat_to_rot(qa),
        ta,
        tb,
        r_x,
        cov_rot,
        block,
        scale,
        max_condition,
        info,
        solution_only,
    )
    s = float(x[3]) if scale else 1.0
    return Extrinsic(R=r_x, t=x[:3], scale=s, info=info), cov_rot, null_rot, cov_x, null_x


def _too_little(reason: str, info: dict):
    ext = Extrinsic(trusted=False, reason=reason, status=Step2Status.TOO_LITTLE_MOTION, info=info)
    return ext, None, None, None, None


def _solve_rotation(
    alpha, beta, use, block, min_pairs, outlier_iterations, max_condition, info, solution_only=False
):
    """R_X from the rotation vectors of the motion pairs (alpha = R_X beta) by Kabsch, rejecting
    pairs beyond 3 median residuals; its covariance and unobservable directions (None, None with
    ``solution_only``)."""
    keep = use.copy()
    h = beta[keep].T @ alpha[keep]
    for _ in range(outlier_iterations + 1):
        r_x, sv = _kabsch(h)
        resid = np.degrees(geometry.norms(alpha - beta @ r_x.T))
        limit = max(3.0 * np.median(resid[keep]), 0.1)
        new_keep = use & (resid <= limit)
        if new_keep.sum() < min_pairs or np.array_equal(new_keep, keep):
            break
        # the next round's cross-covariance: only the pairs that left or came back change it
        out, back = keep & ~new_keep, new_keep & ~keep
        h = h - beta[out].T @ alpha[out] + beta[back].T @ alpha[back]
        keep = new_keep
    rot_rms = float(np.sqrt(np.mean(resid[keep] ** 2)))
    info.update(
        rotation_inliers=int(keep.sum()),
        rotation_residual_rms_deg=rot_rms,
        rotation_singular_values=sv.tolist(),
        rotation_condition=float(sv[0] / sv[1]) if sv[1] > 0 else float("inf"),
    )
    if solution_only:
        return r_x, None, None
    # residual alpha - Exp(d) R beta ~ r + [R beta]x d, perturbing R on the left (body axes)
    jac_r = geometry.skew(beta[keep] @ r_x.T)
    cov_rot, null_rot, _ = _sandwich(
        jac_r, alpha[keep] - beta[keep] @ r_x.T, block[keep], max_condition
    )
    return r_x, cov_rot, null_rot


def _solve_translation(
    ra, ta, tb, r_x, cov_rot, block, scale, max_condition, info, solution_only=False
):
    """t_X (and the scale) from every pair, the rotation now known: (R_A - I) t_X = R_X t_B - t_A
    (with scale: s R_X t_B). Its covariance carries the rotation's uncertainty (None, None with
    ``solution_only``)."""
    m = ra - np.eye(3)  # (K, 3, 3)
    rtb = tb @ r_x.T  # R_X t_B
    if scale:
        m = np.concatenate([m, -rtb[:, :, None]], axis=2)
        b = -ta
    else:
        b = rtb - ta
    x, keep_t, tinfo = _robust_lstsq(m, b, max_condition)
    info.update(tinfo)
    if solution_only:
        return x, None, None
    s = float(x[3]) if scale else 1.0
    m_kept = m[keep_t]
    cov_x, null_x, h_pinv = _sandwich(
        m_kept, (_rows(m_kept) @ x).reshape(-1, 3) - b[keep_t], block[keep_t], max_condition
    )
    # the rotation's own uncertainty moves R_X t_B: d(residual)/d(rotation) = s [R_X t_B]x
    lever = geometry.skew(s * rtb[keep_t])
    gain = h_pinv @ (_rows(m_kept).T @ _rows(lever))
    return x, cov_x + gain @ cov_rot @ gain.T, null_x


def _verdict(
    ext: Extrinsic,
    scale: bool,
    max_rot_residual_deg,
    max_trans_residual_m,
    max_rot_std_deg,
    max_trans_std_m,
    max_scale_std,
) -> Extrinsic:
    """Status, trust and reason of a solved extrinsic: unobservable, large residual, uncertain or trusted."""
    info, s, rot_rms = ext.info, ext.scale, ext.info["rotation_residual_rms_deg"]
    unobservable, residual, uncertain = [], [], []
    relative_scale_std = (
        [info["scale_std"] / abs(s)] if scale and s and info["scale_std"] is not None else []
    )
    if info["rotation_unobservable_axes"]:
        unobservable.append("rotation about " + _axes(info["rotation_unobservable_axes"]))
    if info["translation_unobservable_directions"]:
        unobservable.append(
            "translation along " + _axes(info["translation_unobservable_directions"])
        )
    if scale and (not np.isfinite(s) or s <= 0 or info["scale_unobservable"]):
        unobservable.append("scale")
    if rot_rms > max_rot_residual_deg:
        residual.append(f"rotation residual {rot_rms:.3g} deg > {max_rot_residual_deg}")
    if info["translation_residual_rms_m"] > max_trans_residual_m:
        residual.append(
            f"translation residual {info['translation_residual_rms_m']:.3g} m > {max_trans_residual_m}"
        )
    for name, std, limit, unit in (
        ("rotation", info["rotation_std_deg"], max_rot_std_deg, " deg"),
        ("translation", info["translation_std_m"], max_trans_std_m, " m"),
        ("relative scale", relative_scale_std, max_scale_std, ""),
    ):
        known = [v for v in std if v is not None]
        if not all(np.isfinite(known)):  # NaN compares false: never read as within the limit
            uncertain.append(f"{name} std not finite")
        elif (worst := max(known, default=0.0)) > limit:
            uncertain.append(f"{name} std {worst:.3g}{unit} > {limit}")
    problems = (
        (["unobservable: " + ", ".join(unobservable)] if unobservable else [])
        + residual
        + uncertain
    )
    if unobservable:
        ext.status = Step2Status.UNOBSERVABLE
    elif residual:
        ext.status = Step2Status.LARGE_RESIDUAL
    elif uncertain:
        ext.status = Step2Status.UNCERTAIN
    else:
        ext.status = Step2Status.TRUSTED
    ext.trusted = not problems
    ext.reason = "; ".join(problems) if problems else "solved"
    return ext


def _axes(dirs) -> str:
    return " and ".join("[" + ", ".join(f"{v:.2f}" for v in d) + "]" for d in dirs)


def _pinv(h: np.ndarray, max_condition: float):
    """Pseudo-inverse of a normal matrix H = A^T A over the directions observed (singular value of A
    at least 1/max_condition of the largest), the unit directions left out, and A's singular values
    (largest first). Columns are scaled by unit group, not one by one: the three of a rotation or a
    translation share one scale (else a column the motion barely excites would be blown up to look
    observed), a fourth (scale) its own. H is n x n (n = 3 or 4): no tall SVD over all rows."""
    d = np.diag(h)
    col = np.full(len(d), np.sqrt(np.mean(d[:3])))
    if len(d) > 3:
        col[3:] = np.sqrt(d[3:])
    col[col == 0] = 1.0
    eig, v = np.linalg.eigh(h / np.outer(col, col))
    eig, v = eig[::-1], v[:, ::-1]
    sv = np.sqrt(np.clip(eig, 0, None))
    observed = sv >= sv[0] / max_condition
    pinv = (v[:, observed] / eig[observed]) @ v[:, observed].T / np.outer(col, col)
    null = (v[:, ~observed] / col[:, None]).T
    return pinv, (null / np.linalg.norm(null, axis=1, keepdims=True) if len(null) else null), sv


def _sandwich(jac: np.ndarray, resid: np.ndarray, block: np.ndarray, max_condition: float):
    """Covariance of a least-squares solution, H^+ S H^+ with H = sum J^T J, from residuals that are
    correlated in time: S sums the outer products of the gradient J^T r over time blocks and of
    each block with the next (overlapping motion pairs correlate only across neighbouring blocks),
    scaled by G/(G-1) for G blocks. No noise level is assumed: it comes from the residuals.
    Returns the covariance, the unobservable directions and H^+."""
    rows = _rows(jac)
    h_pinv, null, _ = _pinv(rows.T @ rows, max_condition)
    grad = jac[:, 0] * resid[:, 0:1] + jac[:, 1] * resid[:, 1:2] + jac[:, 2] * resid[:, 2:3]
    ids, inverse = np.unique(block, return_inverse=True)
    per_block = np.zeros((len(ids), jac.shape[2]))
    np.add.at(per_block, inverse, grad)
    s = per_block.T @ per_block
    adjacent = np.flatnonzero(np.diff(ids) == 1)
    cross = per_block[adjacent].T @ per_block[adjacent + 1]
    s = s + cross + cross.T
    eig, v = np.linalg.eigh(s)
    s = (v * np.clip(eig, 0, None)) @ v.T  # the cross terms can leave it slightly indefinite
    g = len(ids)
    cov = h_pinv @ s @ h_pinv * (g / (g - 1) if g > 1 else np.inf)
    return cov, null, h_pinv


def _uncertainty(cov_rot, null_rot, cov_x, null_x, scale: bool) -> dict:
    """Per-axis standard deviations (None along an axis an unobservable direction touches)."""

    def per_axis(cov, null, factor=1.0):
        touched = (np.abs(null) > 0.1).any(axis=0) if len(null) else np.zeros(len(cov), bool)
        return [None if touched[k] else float(factor * np.sqrt(cov[k, k])) for k in range(len(cov))]

    rot = per_axis(cov_rot, null_rot, np.degrees(1.0))
    trans = per_axis(cov_x, null_x)
    return {
        "rotation_std_deg": rot,
        "translation_std_m": trans[:3],
        "scale_std": trans[3] if scale else None,
        "rotation_unobservable_axes": [d.tolist() for d in null_rot],
        "rotation_covariance_rad2": cov_rot.tolist(),
        "translation_covariance": cov_x.tolist(),
    }


def _rows(blocks: np.ndarray) -> np.ndarray:
    """(K, 3, n) blocks of equations as (3K, n) rows, so that sums over them are BLAS products."""
    return np.ascontiguousarray(blocks).reshape(-1, blocks.shape[-1])


def _robust_lstsq(m: np.ndarray, b: np.ndarray, max_condition: float):
    """Least squares on stacked 3-row blocks, with up to two rounds of outlier rejection and
    truncation of directions the motion does not observe (reported, and left at zero rather than
    fitted to noise). Returns the solution, the rows kept and the record."""
    k, _, n = m.shape
    keep = np.ones(k, bool)
    rows = _rows(m)  # every 3-row block an equation: the sums over them are BLAS products
    h, g = rows.T @ rows, rows.T @ b.reshape(-1)  # the normal equations over every pair
    for rejection in range(3):
        pinv, null, sv = _pinv(h, max_condition)
        x = pinv @ g
        resid = geometry.norms((rows @ x).reshape(k, 3) - b)
        new_keep = resid <= max(3.0 * np.median(resid[keep]), 1e-3)
        if rejection == 2 or new_keep.sum() < max(n, k // 2) or np.array_equal(new_keep, keep):
            break
        # the next round's normal equations: only the pairs that left or came back change them
        for sign, changed in ((-1.0, keep & ~new_keep), (1.0, new_keep & ~keep)):
            rows_c = _rows(m[changed])
            h = h + sign * (rows_c.T @ rows_c)
            g = g + sign * (rows_c.T @ b[changed].reshape(-1))
        keep = new_keep
    unobs_t = [d[:3].tolist() for d in null if np.linalg.norm(d[:3]) > 0.5]
    scale_unobs = bool(n == 4 and any(abs(d[3]) > 0.5 for d in null))
    return (
        x,
        keep,
        {
            "translation_singular_values": sv.tolist(),
            "translation_condition": float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
            "translation_unobservable_directions": unobs_t,
            "scale_unobservable": scale_unobs,
            "translation_inliers": int(keep.sum()),
            "translation_residual_rms_m": float(np.sqrt(np.mean(resid[keep] ** 2))),
        },
    )
