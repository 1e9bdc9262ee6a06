"""Step 2: the sensor-to-body extrinsic (hand-eye calibration) from matched relative motions.

Model: the reference gives body poses T_WB(t), the estimate sensor poses T_VC(t) in its own world V,
and X = T_BC is fixed. For motion pairs (i, j): A = T_WB,i^-1 T_WB,j, B = T_VC,i^-1 T_VC,j, and
A X = X B. Rotation: rotvec(R_A) = R_X rotvec(R_B) (Kabsch over all pairs, with residual
rejection). Translation: (R_A - I) t_X - s R_X t_B = -t_A, linear in t_X and the optional scale s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from epa import geometry
from epa.metrics.accuracy import closest_pairs
from epa.trajectory import Trajectory


@dataclass
class Extrinsic:
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    trusted: bool = False
    reason: str = ""
    info: dict = field(default_factory=dict)

    def apply(self, est: Trajectory) -> Trajectory:
        """Sensor poses (scaled) -> body poses: T_VB = T_VC X^-1, covariance carried along.

        With the local orientation error (R_true = R Exp(d)): d_body = R_x d_sensor, and
        p_b = s p_c - R_b t_x moves the position error by s dp + R_b [t_x]x d_body. Only the
        orientation and position blocks are known (no cross-covariance), so the lever arm adds
        R_b [t_x]x Cov_rot [t_x]x^T R_b^T to the position block."""
        r_b = est.r @ self.R.T
        p_b = self.scale * est.p - np.einsum("nab,b->na", r_b, self.t)
        cov = {}
        if est.cov_rot is not None and est.cov_pos is not None:
            cov_rot = self.R @ est.cov_rot @ self.R.T
            lever = np.einsum("nab,bc->nac", r_b, geometry.skew(self.t))
            cov_pos = self.scale ** 2 * est.cov_pos + lever @ cov_rot @ lever.transpose(0, 2, 1)
            cov = {"cov_rot": cov_rot, "cov_pos": cov_pos}
        return Trajectory.from_rp(est.t, r_b, p_b, **cov)

    def to_sensor_rp(self, r_b: np.ndarray, p_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The inverse of :meth:`apply` on rotations and positions: body poses -> sensor poses."""
        return r_b @ self.R, (p_b + np.einsum("nab,b->na", r_b, self.t)) / self.scale

    @staticmethod
    def from_dict(d: dict) -> "Extrinsic":
        """The transform of a ``to_dict`` record (what calibrate.json holds)."""
        return Extrinsic(R=np.asarray(d["rotation"], float), t=np.asarray(d["translation_m"], float),
                         scale=float(d["scale"]), trusted=bool(d["trusted"]), reason=d["reason"])

    def translation_unobservable(self) -> bool:
        return bool(self.info.get("translation_unobservable_directions"))

    def to_dict(self) -> dict:
        return {"trusted": self.trusted, "reason": self.reason,
                "rotation": self.R.tolist(), "quaternion_xyzw": geometry.rot_to_quat(self.R).tolist(),
                "rotation_deg": float(np.degrees(geometry.rotation_angle(self.R))),
                "translation_m": self.t.tolist(), "translation_norm_m": float(np.linalg.norm(self.t)),
                "scale": float(self.scale), **self.info}


def _kabsch(beta: np.ndarray, alpha: np.ndarray):
    """R minimising sum |alpha - R beta|^2, and the singular values of the cross-covariance."""
    h = beta.T @ alpha
    u, s, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T, s


def solve(ref: Trajectory, est: Trajectory, *, pair_step: float = 1.0, min_rotation_deg: float = 2.0,
          scale: bool = False, max_rot_residual_deg: float = 2.0, max_trans_residual_m: float = 0.2,
          max_condition: float = 100.0, min_pairs: int = 20, outlier_iterations: int = 3) -> Extrinsic:
    """Hand-eye calibration over all pose pairs ``pair_step`` seconds apart (on matched poses)."""
    i, j = closest_pairs(ref.t - ref.t[0], pair_step, 0.25 * pair_step, strict=False, skip=1)
    info: dict = {"pairs": int(len(i)), "pair_step_s": pair_step}
    if len(i) < min_pairs:
        return Extrinsic(trusted=False, reason=f"only {len(i)} motion pairs ({min_pairs} needed)", info=info)
    qa, ta = geometry.relative_motions(ref.q, ref.p, i, j)
    qb, tb = geometry.relative_motions(est.q, est.p, i, j)
    alpha, beta = geometry.quat_log(qa), geometry.quat_log(qb)
    ra = geometry.quat_to_rot(qa)  # the translation equations need (R_A - I) as matrices
    angle = np.degrees(np.linalg.norm(alpha, axis=1))
    use = angle >= min_rotation_deg
    info["rotation_pairs"] = int(use.sum())
    info["excitation_rms_deg"] = float(np.sqrt(np.mean(angle[use] ** 2))) if use.any() else 0.0
    if use.sum() < min_pairs:
        return Extrinsic(trusted=False, reason=f"too little rotation: {int(use.sum())} pairs rotate more than"
                         f" {min_rotation_deg} deg ({min_pairs} needed)", info=info)
    keep = use.copy()
    for _ in range(outlier_iterations + 1):
        r_x, sv = _kabsch(beta[keep], alpha[keep])
        resid = np.degrees(np.linalg.norm(alpha - beta @ r_x.T, axis=1))
        limit = max(3.0 * np.median(resid[keep]), 0.1)
        new_keep = use & (resid <= limit)
        if new_keep.sum() < min_pairs or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    rot_rms = float(np.sqrt(np.mean(resid[keep] ** 2)))
    info.update(rotation_inliers=int(keep.sum()), rotation_residual_rms_deg=rot_rms,
                rotation_singular_values=sv.tolist(),
                rotation_condition=float(sv[0] / sv[1]) if sv[1] > 0 else float("inf"))

    # Translation (and scale): every pair, rotation now known.
    eye = np.eye(3)
    m = ra - eye  # (K, 3, 3)
    rtb = tb @ r_x.T  # R_X t_B
    if scale:
        m = np.concatenate([m, -rtb[:, :, None]], axis=2)
        b = -ta
    else:
        b = rtb - ta
    x, tinfo = _robust_lstsq(m, b, max_condition)
    info.update(tinfo)
    t_x = x[:3]
    s = float(x[3]) if scale else 1.0
    ext = Extrinsic(R=r_x, t=t_x, scale=s, info=info)
    problems = []
    if info["rotation_condition"] > max_condition:
        problems.append(f"rotation ill-conditioned (axes barely excited, condition {info['rotation_condition']:.3g})")
    if rot_rms > max_rot_residual_deg:
        problems.append(f"rotation residual {rot_rms:.3g} deg > {max_rot_residual_deg}")
    if info["translation_residual_rms_m"] > max_trans_residual_m:
        problems.append(f"translation residual {info['translation_residual_rms_m']:.3g} m > {max_trans_residual_m}")
    if scale and (not np.isfinite(s) or s <= 0 or info["scale_unobservable"]):
        problems.append("scale not observable")
    ext.trusted = not problems
    ext.reason = "; ".join(problems) if problems else "solved"
    return ext


def _robust_lstsq(m: np.ndarray, b: np.ndarray, max_condition: float):
    """Least squares on stacked 3-row blocks, with one round of outlier rejection and truncation of
    directions the motion does not observe (reported, and left at zero rather than fitted to noise)."""
    k, _, n = m.shape
    keep = np.ones(k, bool)
    for _ in range(2):
        # The normal matrix (n x n, n = 3 or 4) has the stacked system's singular values squared and
        # the same right singular vectors: no tall SVD over all 3K rows is needed.
        ata = np.einsum("kai,kaj->ij", m[keep], m[keep])
        aty = np.einsum("kai,ka->i", m[keep], b[keep])
        col = np.sqrt(np.diag(ata))
        col[col == 0] = 1.0
        eig, v = np.linalg.eigh(ata / np.outer(col, col))
        order = np.argsort(eig)[::-1]
        sv = np.sqrt(np.clip(eig[order], 0, None))
        vt = v[:, order].T
        observable = sv >= sv[0] / max_condition
        coef = (vt[observable] @ (aty / col)) / sv[observable] ** 2
        x = (vt[observable].T @ coef) / col
        resid = np.linalg.norm(np.einsum("kab,b->ka", m, x) - b, axis=1)
        limit = max(3.0 * np.median(resid[keep]), 1e-3)
        new_keep = resid <= limit
        if new_keep.sum() < max(n, k // 2) or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    null_dirs = (vt[~observable] / col)
    null_dirs = null_dirs / np.linalg.norm(null_dirs, axis=1, keepdims=True) if len(null_dirs) else null_dirs
    unobs_t = [d[:3].tolist() for d in null_dirs if np.linalg.norm(d[:3]) > 0.5]
    scale_unobs = bool(n == 4 and any(abs(d[3]) > 0.5 for d in null_dirs))
    return x, {"translation_singular_values": sv.tolist(),
               "translation_condition": float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
               "translation_unobservable_directions": unobs_t, "scale_unobservable": scale_unobs,
               "translation_inliers": int(keep.sum()),
               "translation_residual_rms_m": float(np.sqrt(np.mean(resid[keep] ** 2)))}
