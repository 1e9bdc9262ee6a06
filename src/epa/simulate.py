"""Deterministic example grid: 3 algorithms x 3 sequences x 2 runs with known truth.

Motion is analytic (so the estimate can be sampled at any shifted time exactly). Estimates carry
VIO-like drift (yaw and position random walks growing with distance), white noise, and, per
algorithm, a known time offset and sensor-to-body extrinsic; one run diverges at a known time.
Everything known is written to ``manifest.json`` beside the data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from epa.artifacts import files
from epa.core import geometry
from epa.core.trajectory import Trajectory

TRUTH_RATE = 50.0
EST_RATE = 20.0

SEQUENCES = {
    # name: (duration s, roll/pitch amplitude deg)
    "drone_figure8": (150.0, 12.0),
    "urban_drive": (150.0, 3.0),
    "handheld_office": (120.0, 20.0),
}
# camera z forward, x right (120 deg about (1,-1,1))
T_BC_ROT = geometry.so3_exp(np.array([1.2092, -1.2092, 1.2092]))
T_BC_TRANS = np.array([0.10, -0.05, 0.02])
ALGORITHMS = {
    # name: (frame, offsets per run (s), drift scale, file format); openvins = TUM + covariance
    "vio_body": ("body", (0.0, 0.0), 1.0, "openvins"),
    "vio_camera": ("camera", (0.05, -0.03), 1.0, "euroc"),
    "vo_drifty": ("body", (0.0, 0.0), 4.0, "tum"),
}
# algorithm, dataset, run, divergence time (s)
DIVERGING = ("vo_drifty", "urban_drive", "run2", 60.0)
# per-frame processing time (ms): median and log-normal spread; vio_camera is often over its 50 ms period
TIMING = {"vio_body": (22.0, 0.25), "vio_camera": (42.0, 0.3)}
NOISE_ROT_DEG, NOISE_POS_M = 0.1, 0.005


def _position(name: str, t: np.ndarray) -> np.ndarray:
    if name == "drone_figure8":
        w = 2 * np.pi / 60.0
        return np.stack(
            [40 * np.sin(w * t), 20 * np.sin(2 * w * t), 5 + 2 * np.sin(0.3 * w * t)], axis=-1
        )
    if name == "urban_drive":
        th = 2 * np.pi * t / 100.0
        return np.stack(
            [
                80 * np.cos(th) + 15 * np.cos(3 * th),
                50 * np.sin(th) - 10 * np.sin(3 * th),
                0.5 * np.sin(2 * th),
            ],
            axis=-1,
        )
    w = 2 * np.pi / 40.0
    return np.stack(
        [
            15 * np.sin(w * t) + 3 * np.sin(5 * w * t),
            10 * np.sin(1.3 * w * t),
            1.5 + 0.3 * np.sin(3 * w * t),
        ],
        axis=-1,
    )


def truth_pose(name: str, t: np.ndarray):
    """Body rotation and position at any times: heading along the velocity, roll/pitch wobble."""
    _, amp = SEQUENCES[name]
    p = _position(name, t)
    v = (_position(name, t + 1e-4) - _position(name, t - 1e-4)) / 2e-4
    yaw = np.arctan2(v[:, 1], v[:, 0])
    a = np.radians(amp)
    roll = a * np.sin(2 * np.pi * t / 7.3) + 0.3 * a * np.sin(2 * np.pi * t / 1.9)
    pitch = a * np.sin(2 * np.pi * t / 5.1 + 1.0) + 0.3 * a * np.sin(2 * np.pi * t / 2.3)
    yaw = yaw + 0.15 * np.sin(2 * np.pi * t / 3.1)
    cz, sz, cy, sy, cx, sx = (
        np.cos(yaw),
        np.sin(yaw),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(roll),
        np.sin(roll),
    )
    r = np.empty((len(t), 3, 3))
    r[:, 0] = np.stack([cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx], -1)
    r[:, 1] = np.stack([sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx], -1)
    r[:, 2] = np.stack([-sy, cy * sx, cy * cx], -1)
    return r, p


def _estimate(
    seq: str,
    alg: str,
    run_index: int,
    t0: float,
    rng: np.random.Generator,
    diverge_at: float | None,
):
    frame, offsets, drift, _ = ALGORITHMS[alg]
    duration, _ = SEQUENCES[seq]
    offset = offsets[run_index]
    t_est = np.arange(0.5, duration - 0.5, 1.0 / EST_RATE)  # estimate clock, relative
    t_true = t_est + offset  # the moment each estimate pose describes (t_ref = t_est + offset)
    r, p = truth_pose(seq, t_true)
    step = np.linalg.norm(np.diff(p, axis=0, prepend=p[:1]), axis=1)
    yaw_drift = np.cumsum(rng.normal(0, drift * 2e-4, len(t_est)) * np.sqrt(step + 1e-3))
    pos_drift = np.cumsum(
        rng.normal(0, drift * 4e-3, (len(t_est), 3)) * np.sqrt(step + 1e-3)[:, None], axis=0
    )
    pos_drift[:, 2] *= 0.3
    if diverge_at is not None:
        late = np.clip(t_true - diverge_at, 0, None)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        pos_drift += 1.5 * late[:, None] ** 2 * direction
        yaw_drift += 0.02 * late**2
    rz = geometry.so3_exp(
        np.stack([np.zeros_like(yaw_drift), np.zeros_like(yaw_drift), yaw_drift], -1)
    )
    noise_r = geometry.so3_exp(rng.normal(0, np.radians(NOISE_ROT_DEG), (len(t_est), 3)))
    r_est = rz @ r @ noise_r
    p_est = np.einsum("nab,nb->na", rz, p) + pos_drift + rng.normal(0, NOISE_POS_M, (len(t_est), 3))
    # the covariance an honest estimator would report: the random walks' variance so far plus the
    # white noise (orientation: local error; the yaw walk is about the world z axis)
    var_yaw = np.cumsum((drift * 2e-4) ** 2 * (step + 1e-3))
    var_pos = np.cumsum((drift * 4e-3) ** 2 * (step + 1e-3))[:, None] * np.array([1.0, 1.0, 0.09])
    z_local = r_est[:, 2, :]  # world z in body axes: R^T e_z
    cov_rot = var_yaw[:, None, None] * np.einsum("na,nb->nab", z_local, z_local) + np.radians(
        NOISE_ROT_DEG
    ) ** 2 * np.eye(3)
    cov_pos = np.einsum("na,ab->nab", var_pos, np.eye(3)) + NOISE_POS_M**2 * np.eye(3)
    if frame == "camera":
        p_est = p_est + np.einsum("nab,b->na", r_est, T_BC_TRANS)
        r_est = r_est @ T_BC_ROT
    # the estimator's own world: gravity-aligned, arbitrary yaw and origin
    world = geometry.rot_z(rng.uniform(-np.pi, np.pi))
    origin = rng.normal(0, 5, 3)
    r_est = world @ r_est
    p_est = p_est @ world.T + origin
    # x/y equal: yaw-invariant
    cov = {} if frame == "camera" else {"cov_rot": cov_rot, "cov_pos": cov_pos}
    return Trajectory.from_rp(t0 + t_est, r_est, p_est, **cov), offset


def _write(path: Path, traj: Trajectory, fmt: str) -> None:
    if fmt == "openvins":
        files.write_trajectory(path, traj, "openvins")
        return
    if fmt == "euroc":
        ns = np.round(traj.t * 1e9).astype(np.int64)
        q = traj.q
        body = "\n".join(
            f"{a},{x:.6f},{y:.6f},{z:.6f},{qw:.8f},{qx:.8f},{qy:.8f},{qz:.8f}"
            for a, (x, y, z), (qx, qy, qz, qw) in zip(ns, traj.p, q)
        )
        files.write_text(
            path,
            "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],"
            "q_RS_z []\n" + body + "\n",
        )
        return
    data = np.column_stack([traj.t, traj.p, traj.q])
    text = (
        "# timestamp tx ty tz qx qy qz qw\n"
        + "\n".join(
            " ".join(f"{v:.6f}" if k < 4 else f"{v:.8f}" for k, v in enumerate(row)) for row in data
        )
        + "\n"
    )
    files.write_text(path, text)


def simulate(out_dir, seed: int = 7) -> dict:
    """Write truth/ and algorithms/ under out_dir; return the manifest of what is known."""
    out = Path(out_dir)
    manifest: dict = {
        "seed": seed,
        "truth_rate_hz": TRUTH_RATE,
        "estimate_rate_hz": EST_RATE,
        "extrinsic_T_BC": {"rotation": T_BC_ROT.tolist(), "translation": T_BC_TRANS.tolist()},
        "cases": {},
    }
    t0 = 1_700_000_000.0
    for k, (seq, (duration, _)) in enumerate(SEQUENCES.items()):
        t = np.arange(0.0, duration, 1.0 / TRUTH_RATE)
        r, p = truth_pose(seq, t)
        _write(out / "truth" / f"{seq}.txt", Trajectory.from_rp(t0 + t, r, p), "tum")
        for a, alg in enumerate(ALGORITHMS):
            frame, _, _, fmt = ALGORITHMS[alg]
            for run_index in range(2):
                run = f"run{run_index + 1}"
                rng = np.random.default_rng([seed, k, a, run_index])
                diverge = DIVERGING[3] if (alg, seq, run) == DIVERGING[:3] else None
                est, offset = _estimate(seq, alg, run_index, t0, rng, diverge)
                ext = ".csv" if fmt == "euroc" else ".txt"
                _write(out / "algorithms" / alg / seq / f"{run}{ext}", est, fmt)
                if alg in TIMING:  # <run>_timing.txt: <timestamp> <milliseconds>, the naming rule
                    median, spread = TIMING[alg]
                    ms = median * np.exp(rng.normal(0, spread, len(est)))
                    files.write_text(
                        out / "algorithms" / alg / seq / f"{run}_timing.txt",
                        "".join(f"{t:.6f} {m:.3f}\n" for t, m in zip(est.t, ms)),
                    )
                manifest["cases"][f"{alg}/{seq}/{run}"] = {
                    "frame": frame,
                    "time_offset_s": offset,
                    "diverges_at_s": diverge,
                    "format": fmt,
                }
    files.write_json(out / "manifest.json", manifest)
    return manifest


def observe(
    ref: Trajectory,
    rng: np.random.Generator,
    *,
    offset: float = 0.0,
    rotation: np.ndarray | None = None,
    translation=(0.0, 0.0, 0.0),
    scale: float = 1.0,
    rate: float = 20.0,
    noise_rot_deg: float = 0.0,
    noise_pos_m: float = 0.0,
    walk_rot_deg: float = 0.0,
    walk_pos_m: float = 0.0,
    margin: float = 0.0,
) -> Trajectory:
    """A simulated estimate of a sensor rigidly mounted on the reference body, from the reference's
    own motion: poses at ``rate`` on the estimate's clock (t_ref = t_est + offset), sensor frame
    X = (rotation, translation), positions divided by ``scale``, white noise (orientation on the
    right, deg; position, m) and random walks (per sqrt(s)), in an arbitrary world of its own."""
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    t_est = np.arange(
        ref.t[0] + margin + max(0.0, -offset), ref.t[-1] - margin - max(0.0, offset), 1.0 / rate
    )
    body = ref.at(t_est + offset)
    p_b, r_b = body.p, body.r
    n, step = len(t_est), np.sqrt(1.0 / rate)
    walk_r = np.cumsum(rng.normal(0, np.radians(walk_rot_deg) * step, (n, 3)), axis=0)
    walk_p = np.cumsum(rng.normal(0, walk_pos_m * step, (n, 3)), axis=0)
    r_b = (
        geometry.so3_exp(walk_r)
        @ r_b
        @ geometry.so3_exp(rng.normal(0, np.radians(noise_rot_deg), (n, 3)))
    )
    p_b = p_b + walk_p + rng.normal(0, noise_pos_m, (n, 3))
    r_c, p_c = r_b @ rot, p_b + np.einsum("nab,b->na", r_b, np.asarray(translation, float))
    world = geometry.so3_exp(rng.normal(0, 1.0, 3))
    return Trajectory.from_rp(t_est, world @ r_c, (p_c @ world.T + rng.normal(0, 5, 3)) / scale)
