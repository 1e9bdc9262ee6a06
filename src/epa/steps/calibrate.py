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

from epa.core import geometry, ranks
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


APPLY_BLOCK = 16384  # poses per block in Extrinsic.apply's covariances


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
        # R_b = R_c R^T as the quaternion product q_c conj(q_x) (no matrices, no BLAS product on
        # (3N, 3) rows), normalised with w >= 0 as rot_to_quat gives it
        qx = geometry.rot_to_quat(self.R)
        q_c = geometry.component_rows(est.q)
        q = geometry.mul_rows(q_c, (-qx[0], -qx[1], -qx[2], qx[3]))
        norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        q /= np.where(q[3] < 0, -norm, norm)
        # R_b t = R_c (R^T t)
        p_b = self.scale * est.p - geometry.rotate_rows(q_c, self.R.T @ self.t).T
        # printed rotation blocks (KITTI) take the same right factor: what the devkit's raw matrices would
        extra = {} if est.r_printed is None else {"r_printed": est.r_printed @ self.R.T}
        if est.cov_rot is not None and est.cov_pos is not None:
            extra.update(self._covariances(est.cov_rot, est.cov_pos, q))
        return Trajectory(est.t, p_b, np.ascontiguousarray(q.T), **extra)

    def _covariances(self, cov_rot_c: np.ndarray, cov_pos_c: np.ndarray, q: np.ndarray) -> dict:
        """apply's covariances, ``q`` the body orientations' rows; in blocks of poses, the 3x3
        products written out on component rows (numpy's stacked matmul calls BLAS once per 3x3
        matrix: 4x slower), their temporaries in cache."""
        cov_rot, cov_pos = np.empty_like(cov_rot_c), np.empty_like(cov_pos_c)
        skew_t, s2 = geometry.skew(self.t), self.scale**2
        for start in range(0, len(cov_rot_c), APPLY_BLOCK):
            at = slice(start, start + APPLY_BLOCK)
            cr = geometry.matmul_rows(
                geometry.matmul_rows(self.R, geometry.matrix_rows(cov_rot_c[at])), self.R.T
            )
            lever = geometry.matmul_rows(geometry.rot_rows(q[:, at]), skew_t)  # R_b [t_x]x
            lever_t = [[lever[b][a] for b in range(3)] for a in range(3)]
            pos = geometry.matmul_rows(geometry.matmul_rows(lever, cr), lever_t)
            c_pos = cov_pos_c[at]
            for a, b in np.ndindex(3, 3):
                cov_rot[at, a, b] = cr[a][b]
                cov_pos[at, a, b] = s2 * c_pos[:, a, b] + pos[a][b]
        return {"cov_rot": cov_rot, "cov_pos": cov_pos}

    def to_sensor_rows(self, q_b: np.ndarray, p_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The inverse of :meth:`apply` on orientations ((4, N) quaternion rows) and positions
        (N, 3): body poses -> sensor poses, r_b R_X and (p_b + r_b t_X) / scale."""
        lever = geometry.rotate_rows(q_b, self.t).T
        return geometry.mul_rows(q_b, geometry.rot_to_quat(self.R)), (p_b + lever) / self.scale

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


def interpolator(ref: Trajectory):
    """``ref.at`` for several sets of stamps (the same poses, the same bits), the slerp's setup made
    once; the poses are held as component rows, which the solve reads without copies."""
    if len(ref) < 2:  # no interval to set up: Trajectory.at gives the one pose at every stamp
        return ref.at
    at = geometry.interpolator(
        ref.t, geometry.component_rows(ref.p), geometry.component_rows(ref.q)
    )

    def poses(stamps: np.ndarray) -> Trajectory:
        stamps = np.asarray(stamps, float)
        p, q = at(stamps)
        return Trajectory(stamps, p.T, q.T)

    return poses


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
        ends, at = [], interpolator(ref)  # the two share each interval's slerp setup
        for sign in (1.0, -1.0):  # only their solutions are used: no covariances
            shifted = at(ref.t + sign * offset_std)
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
    ``motions`` keeps the motion pairs and the estimate's motions from one call to the next: the
    same relative times give the same pairs, and the same pairs the same motions, so each is
    computed once. Every per-pair quantity is held as component rows ((3, K) and (3, 3, K)), and
    the sums over pairs are einsum's, not BLAS products (whose threads spin and would be counted)."""
    motions = {} if motions is None else motions
    i, j = _motion_pairs(ref.t - ref.t[0], pair_step, motions)
    info: dict = {"pairs": int(len(i)), "pair_step_s": pair_step}
    if len(i) < min_pairs:
        return _too_little(f"only {len(i)} motion pairs ({min_pairs} needed)", info)
    at = (geometry.run_slice(i), geometry.run_slice(j))  # runs of poses: views, not gathers
    qa, ta = geometry.relative_motion_rows(
        geometry.component_rows(ref.q), geometry.component_rows(ref.p), *at
    )
    kept = motions.get("estimate")
    # both ends compared: re-found pairs of a shifted reference can keep i and change a j at a tie
    if kept is not None and all(a is b or np.array_equal(a, b) for a, b in zip(kept[0], (i, j))):
        qb, tb, beta = kept[1]
    else:
        qb, tb = geometry.relative_motion_rows(
            geometry.component_rows(est.q), geometry.component_rows(est.p), *at
        )
        beta = geometry.log_rows(qb)
        motions["estimate"] = ((i, j), (qb, tb, beta))
    alpha = geometry.log_rows(qa)
    angle = np.degrees(np.sqrt(alpha[0] * alpha[0] + alpha[1] * alpha[1] + alpha[2] * alpha[2]))
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
    block = (
        None if solution_only else np.floor((ref.t[i] - ref.t[0]) / (2.0 * pair_step)).astype(int)
    )
    r_x, cov_rot, null_rot = _solve_rotation(
        alpha, beta, use, block, min_pairs, outlier_iterations, max_condition, info, solution_only
    )
    x, cov_x, null_x = _solve_translation(
        qa, ta, tb, r_x, cov_rot, block, scale, max_condition, info, solution_only
    )
    s = float(x[3]) if scale else 1.0
    return Extrinsic(R=r_x, t=x[:3], scale=s, info=info), cov_rot, null_rot, cov_x, null_x


def _motion_pairs(d: np.ndarray, pair_step: float, motions: dict):
    """The motion pairs of relative times ``d``, those of the previous call when ``d`` is the same
    (a reference moved by a constant rounds its relative times differently: then they are found
    again)."""
    kept = motions.get("times")
    if kept is not None and np.array_equal(kept[0], d):
        return kept[1]
    pairs = closest_pairs(d, pair_step, 0.25 * pair_step, strict=False, skip=1)
    motions["times"] = (d, pairs)
    return pairs


def _too_little(reason: str, info: dict):
    ext = Extrinsic(trusted=False, reason=reason, status=Step2Status.TOO_LITTLE_MOTION, info=info)
    return ext, None, None, None, None


def _solve_rotation(
    alpha, beta, use, block, min_pairs, outlier_iterations, max_condition, info, solution_only=False
):
    """R_X from the rotation vectors of the motion pairs ((3, K) rows, alpha = R_X beta) by Kabsch,
    rejecting pairs beyond 3 median residuals; its covariance and unobservable directions (None,
    None with ``solution_only``)."""
    keep = use.copy()
    h = _sums(_cols(beta, keep), _cols(alpha, keep))  # sum beta alpha^T
    for _ in range(outlier_iterations + 1):
        r_x, sv = _kabsch(h)
        resid = _rotation_residuals(r_x, alpha, beta)
        limit = max(3.0 * _median(resid[keep]), 0.1)
        new_keep = use & (resid <= limit)
        if new_keep.sum() < min_pairs or np.array_equal(new_keep, keep):
            break
        # the next round's cross-covariance: only the pairs that left or came back change it
        out, back = keep & ~new_keep, new_keep & ~keep
        h = (
            h
            - _sums(_cols(beta, out), _cols(alpha, out))
            + _sums(_cols(beta, back), _cols(alpha, back))
        )
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
    # residual alpha - Exp(d) R beta ~ r + [c]x d with c = R beta, perturbing R on the left (body
    # axes): J = [c]x, so J^T J = |c|^2 I - c c^T and the gradient J^T r = r x c
    c = _rotated(r_x, _cols(beta, keep))
    r = _cols(alpha, keep) - c
    cc = _sums(c, c)
    grad = np.array(
        (r[1] * c[2] - r[2] * c[1], r[2] * c[0] - r[0] * c[2], r[0] * c[1] - r[1] * c[0])
    )
    cov_rot, null_rot, _ = _sandwich(
        np.trace(cc) * np.eye(3) - cc, grad, block[keep], max_condition
    )
    return r_x, cov_rot, null_rot


def _rotation_residuals(r_x: np.ndarray, alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """|alpha - R_X beta| of every pair, in degrees (in blocks of pairs: temporaries in cache)."""
    resid = np.empty(alpha.shape[1])
    for part in geometry.row_blocks(len(resid)):
        r = alpha[:, part] - _rotated(r_x, beta[:, part])
        resid[part] = np.degrees(np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]))
    return resid


# the Levi-Civita symbol: (m x v)_b = sum eps[b, c, d] m_c v_d
_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0


def _solve_translation(
    qa, ta, tb, r_x, cov_rot, block, scale, max_condition, info, solution_only=False
):
    """t_X (and the scale) from every pair, the rotation now known: (R_A - I) t_X = R_X t_B - t_A
    (with scale: s R_X t_B). Its covariance carries the rotation's uncertainty (None, None with
    ``solution_only``). The equations (:func:`_equations`) are made block by block of pairs, in
    cache, in each pass that reads them: never the (3, n, K) rows of every pair."""
    rtb = _rotated(r_x, tb)  # R_X t_B
    x, keep_t, h, tinfo = _robust_lstsq(qa, ta, rtb, scale, max_condition)
    info.update(tinfo)
    if solution_only:
        return x, None, None
    s = float(x[3]) if scale else 1.0
    n = len(x)
    grad = np.empty((n, int(keep_t.sum())))  # J^T r of every kept pair
    t = np.zeros((3, n, 3))
    done = 0
    for part in geometry.row_blocks(len(keep_t)):
        sel = keep_t[part]
        rtb_kept = _cols(rtb[:, part], sel)
        m, b = _equations(_cols(qa[:, part], sel), _cols(ta[:, part], sel), rtb_kept, scale)
        grad[:, done : done + m.shape[2]] = np.einsum("cak,ck->ak", m, _residual_rows(m, x, b))
        done += m.shape[2]
        # the rotation's own uncertainty moves R_X t_B: d(residual)/d(rotation) = [v]x, v = s R_X
        # t_B; sum m^T [v]x has rows sum m[:, a] x v, from the sums of m[c, a] v_d
        t += np.einsum("cak,dk->cad", m, s * rtb_kept)
    cov_x, null_x, h_pinv = _sandwich(h, grad, block[keep_t], max_condition)
    gain = h_pinv @ np.einsum("bcd,cad->ab", _EPS, t)
    return x, cov_x + gain @ cov_rot @ gain.T, null_x


def _equations(qa, ta, rtb, scale: bool):
    """The translation equations m x = b of pairs given as rows (q_A (4, B), t_A and R_X t_B
    (3, B)): m[c, a] as (3, n, B) rows (R_A - I, and with scale the column -R_X t_B) and b (3, B)
    (R_X t_B - t_A, with scale -t_A)."""
    m = np.empty((3, 4 if scale else 3, qa.shape[1]))
    geometry.rot_rows(qa, out=m[:, :3])
    for k in range(3):
        m[k, k] -= 1.0  # R_A - I
    if scale:
        m[:, 3] = -rtb
        return m, -ta
    return m, rtb - ta


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
        if any(np.isnan(known)):  # NaN compares false: never read as within the limit
            uncertain.append(f"{name} std undefined (motion pairs in one time block)")
        elif not all(np.isfinite(known)):
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


def _sandwich(h: np.ndarray, grad: np.ndarray, block: np.ndarray, max_condition: float):
    """Covariance of a least-squares solution, H^+ S H^+ with H = sum J^T J (given), from residuals
    that are correlated in time: S sums the outer products of the gradient J^T r (``grad``, (n, K)
    rows) over time blocks and of each block with the next (overlapping motion pairs correlate only
    across neighbouring blocks), scaled by G/(G-1) for G blocks. No noise level is assumed: it comes
    from the residuals, so with a single block it is undefined (all NaN). Returns the covariance,
    the unobservable directions and H^+."""
    h_pinv, null, _ = _pinv(h, max_condition)
    per_block, ids = _block_sums(grad, block)
    g = len(ids)
    if g < 2:
        return np.full(h.shape, np.nan), null, h_pinv
    s = _sums(per_block, per_block)
    adjacent = np.flatnonzero(np.diff(ids) == 1)
    cross = _sums(per_block[:, adjacent], per_block[:, adjacent + 1])
    s = s + cross + cross.T
    eig, v = np.linalg.eigh(s)
    s = (v * np.clip(eig, 0, None)) @ v.T  # the cross terms can leave it slightly indefinite
    cov = h_pinv @ s @ h_pinv * (g / (g - 1))
    return cov, null, h_pinv


def _block_sums(grad: np.ndarray, block: np.ndarray):
    """The sums of ``grad``'s columns over each block id, as (n, G) rows, and the ids (ascending).
    The pairs' blocks come sorted (pairs in time order): runs summed by reduceat."""
    if len(block) == 0:
        return np.zeros((len(grad), 0)), block
    if (np.diff(block) < 0).any():
        order = np.argsort(block, kind="stable")
        grad, block = grad[:, order], block[order]
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1]])
    return np.add.reduceat(grad, starts, axis=1), block[starts]


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


def _cols(rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The pairs (last axis) of ``mask``; no copy when it keeps them all."""
    return rows if mask.all() else np.compress(mask, rows, axis=-1)  # 4x a boolean index


def _sums(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sum_k a[:, k] b[:, k]^T of (p, K) and (q, K) rows: einsum's loops, not a BLAS product (whose
    threads spin on such thin shapes, and whose sums depend on their number)."""
    return np.einsum("ik,jk->ij", a, b)


def _rotated(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """r v for a 3x3 ``r`` and (3, K) rows ``v`` (each row summed in place: no temporaries)."""
    out = np.empty((3, v.shape[1]))
    for a in range(3):
        row = np.multiply(r[a, 0], v[0], out=out[a])
        row += r[a, 1] * v[1]
        row += r[a, 2] * v[2]
    return out


def _median(x: np.ndarray) -> float:
    """np.median's value; NaN where there is one, or no value."""
    if x.size == 0 or np.isnan(x).any():
        return float("nan")
    return ranks.median(x)


def _residual_rows(m: np.ndarray, x: np.ndarray, b: np.ndarray) -> np.ndarray:
    """m x - b of every pair of (3, n, B) and (3, B) rows, as (3, B) rows."""
    e = np.empty_like(b)
    for c in range(3):
        row = m[c, 0] * x[0]
        for a in range(1, len(x)):
            row = row + m[c, a] * x[a]
        e[c] = row - b[c]
    return e


def _translation_residuals(qa, ta, rtb, scale: bool, x: np.ndarray) -> np.ndarray:
    """|m x - b| of every pair, in blocks of pairs: (R_A - I) t_X as R_A t_X by the quaternion
    (half the operations of R_A's nine entries and their products; the same residual up to
    rounding)."""
    resid = np.empty(qa.shape[1])
    for part in geometry.row_blocks(len(resid)):
        e = geometry.rotate_rows(qa[:, part], x[:3])
        e -= x[:3, None]  # (R_A - I) t_X
        if scale:  # - s R_X t_B + t_A
            e -= x[3] * rtb[:, part]
            e += ta[:, part]
        else:  # - (R_X t_B - t_A)
            e -= rtb[:, part] - ta[:, part]
        resid[part] = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    return resid


def _normal_equations(qa, ta, rtb, scale: bool):
    """sum m^T m and sum m^T b of the translation equations (:func:`_equations`) of pairs given as
    rows, from the quaternions q_A = (u, w) without R_A's entries (2-6x faster): R_A = I + 2w [u]x
    + 2 [u]x^2, so (R_A - I)^T (R_A - I) = 4 (|u|^2 I - u u^T) and (R_A - I)^T v = 2 u x (u x v)
    - 2w u x v. In blocks of pairs."""
    n = 4 if scale else 3
    h, g = np.zeros((n, n)), np.zeros(n)
    for part in geometry.row_blocks(qa.shape[1]):
        u, w, rtb_p, ta_p = qa[:3, part], qa[3, part], rtb[:, part], ta[:, part]
        uu = _sums(u, u)
        h[:3, :3] += 4.0 * (np.trace(uu) * np.eye(3) - uu)
        b = -ta_p if scale else rtb_p - ta_p
        g[:3] += _transposed_motion(u, w, b).sum(axis=1)
        if scale:  # the column -R_X t_B
            column = _transposed_motion(u, w, rtb_p).sum(axis=1)
            h[:3, 3] -= column
            h[3, :3] -= column
            h[3, 3] += np.einsum("ck,ck->", rtb_p, rtb_p)
            g[3] -= np.einsum("ck,ck->", rtb_p, b)
    return h, g


def _transposed_motion(u: np.ndarray, w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(R_A - I)^T v of every pair, as 2 u x (u x v) - 2w u x v, on (3, B) rows."""
    c = geometry.cross_rows(u, v)
    return 2.0 * geometry.cross_rows(u, c) - (2.0 * w) * c


def _robust_lstsq(qa, ta, rtb, scale: bool, max_condition: float):
    """Least squares on the translation equations of every pair (:func:`_equations`), with up to
    two rounds of outlier rejection and truncation of directions the motion does not observe
    (reported, and left at zero rather than fitted to noise). Returns the solution, the pairs kept,
    their normal matrix and the record."""
    n, k = 4 if scale else 3, qa.shape[1]
    keep = np.ones(k, bool)
    h, g = _normal_equations(qa, ta, rtb, scale)  # over every pair
    for rejection in range(3):
        pinv, null, sv = _pinv(h, max_condition)
        x = pinv @ g
        resid = _translation_residuals(qa, ta, rtb, scale, x)
        new_keep = resid <= max(3.0 * _median(resid[keep]), 1e-3)
        if rejection == 2 or new_keep.sum() < max(n, k // 2) or np.array_equal(new_keep, keep):
            break
        # the next round's normal equations: only the pairs that left or came back change them
        for sign, changed in ((-1.0, keep & ~new_keep), (1.0, new_keep & ~keep)):
            dh, dg = _normal_equations(
                _cols(qa, changed), _cols(ta, changed), _cols(rtb, changed), scale
            )
            h, g = h + sign * dh, g + sign * dg
        keep = new_keep
    unobs_t = [d[:3].tolist() for d in null if np.linalg.norm(d[:3]) > 0.5]
    scale_unobs = bool(n == 4 and any(abs(d[3]) > 0.5 for d in null))
    return (
        x,
        keep,
        h,
        {
            "translation_singular_values": sv.tolist(),
            "translation_condition": float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
            "translation_unobservable_directions": unobs_t,
            "scale_unobservable": scale_unobs,
            "translation_inliers": int(keep.sum()),
            "translation_residual_rms_m": float(np.sqrt(np.mean(resid[keep] ** 2))),
        },
    )
