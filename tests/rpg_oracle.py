"""Test oracle: a line-by-line transcription of uzh-rpg/rpg_trajectory_evaluation @ 8c8ceec (MIT; its
transformations.py is C. Gohlke's, BSD) as ``analyze_trajectory_single.py --no_plot`` runs it, kept to the
functions that produce the statistics, for comparison with epa.rpg under the current numpy.

Changes from rpg, none of which changes a number: ``np.linalg.linalg.svd`` -> ``np.linalg.svd`` (numpy 2);
``associate``'s candidate list and ``compute_comparison_indices_length``'s inner loop are computed one row
at a time with numpy (the same comparisons, the same order, the same first-minimum rule) because rpg's pure
Python double loops take minutes on 200 Hz groundtruth; prints, caches, plots and file writing are left out.
"""

import math
import os

import numpy as np
import yaml

_EPS = np.finfo(float).eps * 4.0
kRelMetrics = [
    "rel_trans",
    "rel_trans_perc",
    "rel_yaw",
    "rel_rot",
    "rel_gravity",
    "rel_rot_deg_per_m",
]
kRelMetricLables = ["trans", "trans_perc", "yaw", "rot", "gravity", "rot_deg_per_m"]
kNsToEstFnMapping = {
    "traj_est": "stamped_traj_estimate",
    "pose_graph": "stamped_pose_graph_estimate",
    "ba_estimate": "stamped_ba_estimate",
}


# --- transformations.py ---
def unit_vector(data):
    data = np.array(data, dtype=np.float64, copy=True)
    data /= math.sqrt(np.dot(data, data))
    return data


def rotation_matrix(angle, direction):
    sina = math.sin(angle)
    cosa = math.cos(angle)
    direction = unit_vector(direction[:3])
    R = np.array(((cosa, 0.0, 0.0), (0.0, cosa, 0.0), (0.0, 0.0, cosa)), dtype=np.float64)
    R += np.outer(direction, direction) * (1.0 - cosa)
    direction *= sina
    R += np.array(
        (
            (0.0, -direction[2], direction[1]),
            (direction[2], 0.0, -direction[0]),
            (-direction[1], direction[0], 0.0),
        ),
        dtype=np.float64,
    )
    M = np.identity(4)
    M[:3, :3] = R
    return M


def logmap_so3(R):
    R11, R12, R13 = R[0, 0], R[0, 1], R[0, 2]
    R21, R22, R23 = R[1, 0], R[1, 1], R[1, 2]
    R31, R32, R33 = R[2, 0], R[2, 1], R[2, 2]
    tr = np.trace(R)
    if np.abs(tr + 1.0) < 1e-10:
        if np.abs(R33 + 1.0) > 1e-10:
            omega = (np.pi / np.sqrt(2.0 + 2.0 * R33)) * np.array([R13, R23, 1.0 + R33])
        elif np.abs(R22 + 1.0) > 1e-10:
            omega = (np.pi / np.sqrt(2.0 + 2.0 * R22)) * np.array([R12, 1.0 + R22, R32])
        else:
            omega = (np.pi / np.sqrt(2.0 + 2.0 * R11)) * np.array([1.0 + R11, R21, R31])
    else:
        tr_3 = tr - 3.0
        if tr_3 < -1e-7:
            theta = np.arccos((tr - 1.0) / 2.0)
            magnitude = theta / (2.0 * np.sin(theta))
        else:
            magnitude = 0.5 - tr_3 * tr_3 / 12.0
        omega = magnitude * np.array([R32 - R23, R13 - R31, R21 - R12])
    return omega


_NEXT_AXIS = [1, 2, 0, 1]
_AXES2TUPLE = {"rzyx": (0, 0, 0, 1)}


def euler_from_matrix(matrix, axes="sxyz"):
    firstaxis, parity, repetition, frame = _AXES2TUPLE[axes.lower()]
    i = firstaxis
    j = _NEXT_AXIS[i + parity]
    k = _NEXT_AXIS[i - parity + 1]
    M = np.asarray(matrix, dtype=np.float64)[:3, :3]
    if repetition:
        raise NotImplementedError
    cy = math.sqrt(M[i, i] * M[i, i] + M[j, i] * M[j, i])
    if cy > _EPS:
        ax = math.atan2(M[k, j], M[k, k])
        ay = math.atan2(-M[k, i], cy)
        az = math.atan2(M[j, i], M[i, i])
    else:
        ax = math.atan2(-M[j, k], M[j, j])
        ay = math.atan2(-M[k, i], cy)
        az = 0.0
    if parity:
        ax, ay, az = -ax, -ay, -az
    if frame:
        ax, az = az, ax
    return ax, ay, az


def quaternion_matrix(quaternion):
    q = np.array(quaternion[:4], dtype=np.float64, copy=True)
    nq = np.dot(q, q)
    if nq < _EPS:
        return np.identity(4)
    q *= math.sqrt(2.0 / nq)
    q = np.outer(q, q)
    return np.array(
        (
            (1.0 - q[1, 1] - q[2, 2], q[0, 1] - q[2, 3], q[0, 2] + q[1, 3], 0.0),
            (q[0, 1] + q[2, 3], 1.0 - q[0, 0] - q[2, 2], q[1, 2] - q[0, 3], 0.0),
            (q[0, 2] - q[1, 3], q[1, 2] + q[0, 3], 1.0 - q[0, 0] - q[1, 1], 0.0),
            (0.0, 0.0, 0.0, 1.0),
        ),
        dtype=np.float64,
    )


matrix_from_quaternion = quaternion_matrix


def quaternion_from_matrix(matrix):
    q = np.empty((4,), dtype=np.float64)
    M = np.asarray(matrix, dtype=np.float64)[:4, :4]
    t = np.trace(M)
    if t > M[3, 3]:
        q[3] = t
        q[2] = M[1, 0] - M[0, 1]
        q[1] = M[0, 2] - M[2, 0]
        q[0] = M[2, 1] - M[1, 2]
    else:
        i, j, k = 0, 1, 2
        if M[1, 1] > M[0, 0]:
            i, j, k = 1, 2, 0
        if M[2, 2] > M[i, i]:
            i, j, k = 2, 0, 1
        t = M[i, i] - (M[j, j] + M[k, k]) + M[3, 3]
        q[i] = t
        q[j] = M[i, j] + M[j, i]
        q[k] = M[k, i] + M[i, k]
        q[3] = M[k, j] - M[j, k]
    q *= 0.5 / math.sqrt(t * M[3, 3])
    return q


# --- associate_timestamps.py ---
def associate(first_stamps, second_stamps, offset, max_difference):
    second = np.array(second_stamps, dtype=float)
    potential_matches = []
    for idx_a, a in enumerate(first_stamps):  # per row: abs(a - (b + offset)) < max_difference
        diff = np.abs(a - (second + offset))
        for idx_b in np.nonzero(diff < max_difference)[0]:
            potential_matches.append((float(diff[idx_b]), idx_a, int(idx_b)))
    potential_matches.sort()
    matches = []
    first_free = set(range(len(first_stamps)))
    second_free = set(range(len(second_stamps)))
    for _diff, idx_a, idx_b in potential_matches:
        if idx_a in first_free and idx_b in second_free:
            first_free.remove(idx_a)
            second_free.remove(idx_b)
            matches.append((int(idx_a), int(idx_b)))
    matches.sort()
    return matches


# --- trajectory_loading.py ---
def load_estimate_and_associate(
    fn_gt, fn_es, max_diff=0.02, start_t_sec=-float("inf"), end_t_sec=float("inf")
):
    data_es = np.loadtxt(fn_es)
    data_gt = np.loadtxt(fn_gt)
    matches = associate(data_es[:, 0].tolist(), data_gt[:, 0].tolist(), 0.0, max_diff)
    dict_matches = dict(matches)
    p_es, p_gt, q_es, q_gt = [], [], [], []
    for es_id, es in enumerate(data_es):
        if es_id in dict_matches:
            gt = data_gt[dict_matches[es_id]]
            if gt[0] < start_t_sec or gt[0] > end_t_sec:
                continue
            p_es.append(es[1:4])
            p_gt.append(gt[1:4])
            q_es.append(es[4:8])
            q_gt.append(gt[4:8])
    return matches, np.array(p_es), np.array(q_es), np.array(p_gt), np.array(q_gt)


def load_raw_groundtruth(fn_gt, start_t_sec=-float("inf"), end_t_sec=float("inf")):
    data_gt = np.loadtxt(fn_gt)
    p_gt = []
    for d in data_gt:
        if d[0] < start_t_sec or d[0] > end_t_sec:
            continue
        p_gt.append(d[1:4])
    return np.array(p_gt)


# --- align_trajectory.py ---
def get_best_yaw(C):
    A = C[0, 1] - C[1, 0]
    B = C[0, 0] + C[1, 1]
    return np.pi / 2 - np.arctan2(B, A)


def rot_z(theta):
    return rotation_matrix(theta, [0, 0, 1])[0:3, 0:3]


def align_umeyama(model, data, known_scale=False, yaw_only=False):
    mu_M = model.mean(0)
    mu_D = data.mean(0)
    model_zerocentered = model - mu_M
    data_zerocentered = data - mu_D
    n = np.shape(model)[0]
    C = 1.0 / n * np.dot(model_zerocentered.transpose(), data_zerocentered)
    sigma2 = 1.0 / n * np.multiply(data_zerocentered, data_zerocentered).sum()
    U_svd, D_svd, V_svd = np.linalg.svd(C)
    D_svd = np.diag(D_svd)
    V_svd = np.transpose(V_svd)
    S = np.eye(3)
    if np.linalg.det(U_svd) * np.linalg.det(V_svd) < 0:
        S[2, 2] = -1
    if yaw_only:
        rot_C = np.dot(data_zerocentered.transpose(), model_zerocentered)
        R = rot_z(get_best_yaw(rot_C))
    else:
        R = np.dot(U_svd, np.dot(S, np.transpose(V_svd)))
    s = 1 if known_scale else 1.0 / sigma2 * np.trace(np.dot(D_svd, S))
    t = mu_M - s * np.dot(R, mu_D)
    return s, R, t


# --- align_utils.py ---
def _getIndices(n_aligned, total_n):
    if n_aligned == -1:
        return np.arange(0, total_n)
    assert 1 <= n_aligned <= total_n
    return np.arange(0, n_aligned)


def alignPositionYawSingle(p_es, p_gt, q_es, q_gt):
    g_rot = quaternion_matrix(q_gt[0, :])[0:3, 0:3]
    est_rot = quaternion_matrix(q_es[0, :])[0:3, 0:3]
    C_R = np.dot(est_rot, g_rot.transpose())
    R = rot_z(get_best_yaw(C_R))
    return R, p_gt[0, :] - np.dot(R, p_es[0, :])


def alignSE3Single(p_es, p_gt, q_es, q_gt):
    g_rot = quaternion_matrix(q_gt[0, :])[0:3, 0:3]
    est_rot = quaternion_matrix(q_es[0, :])[0:3, 0:3]
    R = np.dot(g_rot, np.transpose(est_rot))
    return R, p_gt[0, :] - np.dot(R, p_es[0, :])


def alignTrajectory(p_es, p_gt, q_es, q_gt, method, n_aligned=-1):
    s = 1
    if method == "sim3":
        assert n_aligned >= 2 or n_aligned == -1
        idxs = _getIndices(n_aligned, p_es.shape[0])
        s, R, t = align_umeyama(p_gt[idxs, 0:3], p_es[idxs, 0:3])
    elif method in ("se3", "posyaw"):
        if n_aligned == 1:
            single = alignSE3Single if method == "se3" else alignPositionYawSingle
            R, t = single(p_es, p_gt, q_es, q_gt)
        else:
            idxs = _getIndices(n_aligned, p_es.shape[0])
            _, R, t = align_umeyama(
                p_gt[idxs, 0:3], p_es[idxs, 0:3], known_scale=True, yaw_only=method == "posyaw"
            )
            t = np.array(t).reshape((3,))
    elif method == "none":
        R = np.identity(3)
        t = np.zeros((3,))
    else:
        raise AssertionError("unknown alignment method")
    return s, R, t


# --- trajectory_utils.py ---
def get_rigid_body_trafo(quat, trans):
    T = quaternion_matrix(quat)
    T[0:3, 3] = trans
    return T


def get_distance_from_start(gt_translation):
    distances = np.diff(gt_translation[:, 0:3], axis=0)
    distances = np.sqrt(np.sum(np.multiply(distances, distances), 1))
    distances = np.cumsum(distances)
    return np.concatenate(([0], distances))


def compute_comparison_indices_length(distances, dist, max_dist_diff):
    max_idx = len(distances)
    comparisons = []
    for idx, d in enumerate(distances):
        # rpg: for i in range(idx, max_idx): keep i if np.abs(distances[i] - (d + dist)) < error (strict)
        err = np.abs(distances[idx:max_idx] - (d + dist))
        i = int(np.argmin(err))  # the first minimum, as the strict comparison keeps it
        if err[i] < max_dist_diff:
            comparisons.append(idx + i)
    return comparisons


def compute_angle(transform):
    return np.arccos(min(1, max(-1, (np.trace(transform[0:3, 0:3]) - 1) / 2))) * 180.0 / np.pi


# --- compute_trajectory_errors.py ---
def compute_relative_error(
    p_es, q_es, p_gt, q_gt, T_cm, dist, max_dist_diff, accum_distances=(), scale=1.0
):
    if len(accum_distances) == 0:
        accum_distances = get_distance_from_start(p_gt)
    comparisons = compute_comparison_indices_length(accum_distances, dist, max_dist_diff)
    if len(comparisons) < 2:
        return [np.array([]) for _ in range(7)]
    T_mc = np.linalg.inv(T_cm)
    errors = []
    for idx, c in enumerate(comparisons):
        if c != -1:
            T_c1 = get_rigid_body_trafo(q_es[idx, :], p_es[idx, :])
            T_c2 = get_rigid_body_trafo(q_es[c, :], p_es[c, :])
            T_c1_c2 = np.dot(np.linalg.inv(T_c1), T_c2)
            T_c1_c2[:3, 3] *= scale
            T_m1 = get_rigid_body_trafo(q_gt[idx, :], p_gt[idx, :])
            T_m2 = get_rigid_body_trafo(q_gt[c, :], p_gt[c, :])
            T_m1_m2 = np.dot(np.linalg.inv(T_m1), T_m2)
            T_m1_m2_in_c1 = np.dot(T_cm, np.dot(T_m1_m2, T_mc))
            T_error_in_c2 = np.dot(np.linalg.inv(T_m1_m2_in_c1), T_c1_c2)
            T_c2_rot = np.eye(4)
            T_c2_rot[0:3, 0:3] = T_c2[0:3, 0:3]
            errors.append(np.dot(T_c2_rot, np.dot(T_error_in_c2, np.linalg.inv(T_c2_rot))))
    error_trans_norm, error_trans_perc, error_yaw, error_gravity, e_rot, e_rot_deg_per_m = (
        [],
        [],
        [],
        [],
        [],
        [],
    )
    for e in errors:
        tn = np.linalg.norm(e[0:3, 3])
        error_trans_norm.append(tn)
        error_trans_perc.append(tn / dist * 100)
        ypr_angles = euler_from_matrix(e, "rzyx")
        e_rot.append(compute_angle(e))
        error_yaw.append(abs(ypr_angles[0]) * 180.0 / np.pi)
        error_gravity.append(np.sqrt(ypr_angles[1] ** 2 + ypr_angles[2] ** 2) * 180.0 / np.pi)
        e_rot_deg_per_m.append(e_rot[-1] / dist)
    return (
        errors,
        np.array(error_trans_norm),
        np.array(error_trans_perc),
        np.array(error_yaw),
        np.array(error_gravity),
        np.array(e_rot),
        np.array(e_rot_deg_per_m),
    )


def compute_absolute_error(p_es_aligned, q_es_aligned, p_gt, q_gt):
    e_trans_vec = p_gt - p_es_aligned
    e_trans = np.sqrt(np.sum(e_trans_vec**2, 1))
    e_rot = np.zeros((len(e_trans),))
    for i in range(np.shape(p_es_aligned)[0]):
        R_we = matrix_from_quaternion(q_es_aligned[i, :])
        R_wg = matrix_from_quaternion(q_gt[i, :])
        e_R = np.dot(R_we, np.linalg.inv(R_wg))
        e_rot[i] = np.rad2deg(np.linalg.norm(logmap_so3(e_R[:3, :3])))
    motion_gt = np.diff(p_gt, 0)
    motion_es = np.diff(p_es_aligned, 0)
    dist_gt = np.sqrt(np.sum(np.multiply(motion_gt, motion_gt), 1))
    dist_es = np.sqrt(np.sum(np.multiply(motion_es, motion_es), 1))
    e_scale_perc = np.abs((np.divide(dist_es, dist_gt) - 1.0) * 100)
    return e_trans, e_rot, e_scale_perc


# --- results_writer.py ---
def compute_statistics(data_vec):
    stats = {}
    if len(data_vec) > 0:
        stats["rmse"] = float(np.sqrt(np.dot(data_vec, data_vec) / len(data_vec)))
        stats["mean"] = float(np.mean(data_vec))
        stats["median"] = float(np.median(data_vec))
        stats["std"] = float(np.std(data_vec))
        stats["min"] = float(np.min(data_vec))
        stats["max"] = float(np.max(data_vec))
        stats["num_samples"] = len(data_vec)
    else:
        for k in ("rmse", "mean", "median", "std", "min", "max", "num_samples"):
            stats[k] = 0
    return stats


def truncate(number, decimals=0):
    if decimals == 0:
        return math.trunc(number)
    factor = 10.0**decimals
    return math.trunc(number * factor) / factor


# --- trajectory.py (Trajectory), reduced to what the statistics need ---
def trajectory(results_dir, nm_est, preset_boxplot_distances=()):
    """Returns None when rpg's load fails (missing file, no match), else a dict of rpg's results."""
    align_type, align_num_frames = "sim3", -1
    eval_cfg = os.path.join(results_dir, "eval_cfg.yaml")
    if os.path.exists(eval_cfg):
        with open(eval_cfg) as f:
            cfg = yaml.safe_load(f)
        align_type, align_num_frames = cfg["align_type"], cfg["align_num_frames"]
    start, end = -float("inf"), float("inf")
    fn = os.path.join(results_dir, "start_end_time.yaml")
    if os.path.exists(fn):
        with open(fn) as f:
            d = yaml.safe_load(f)
        start = d.get("start_time_sec", start)
        end = d.get("end_time_sec", end)
    fn_gt = os.path.join(results_dir, "stamped_groundtruth.txt")
    fn_es = os.path.join(results_dir, nm_est)
    if not os.path.exists(fn_gt) or not os.path.exists(fn_es):
        return None
    matches, p_es, q_es, p_gt, q_gt = load_estimate_and_associate(fn_gt, fn_es, 0.02, start, end)
    p_gt_raw = load_raw_groundtruth(fn_gt, start, end)
    if p_es.size == 0:
        return None
    traj_length = get_distance_from_start(p_gt_raw)[-1]
    accum_distances = get_distance_from_start(p_gt)
    if len(preset_boxplot_distances) != 0:
        distances = list(preset_boxplot_distances)
    else:
        distances = [truncate(pct * traj_length, 2) for pct in [0.1, 0.2, 0.3, 0.4, 0.5]]
    # align_trajectory
    trans, rot, scale = np.zeros((3,)), np.eye(3), 1.0
    if align_type != "none":
        scale, rot, trans = alignTrajectory(p_es, p_gt, q_es, q_gt, align_type, align_num_frames)
    p_es_aligned = np.zeros(np.shape(p_es))
    q_es_aligned = np.zeros(np.shape(q_es))
    for i in range(np.shape(p_es)[0]):
        p_es_aligned[i, :] = scale * rot.dot(p_es[i, :]) + trans
        q_es_R = rot.dot(quaternion_matrix(q_es[i, :])[0:3, 0:3])
        q_es_T = np.identity(4)
        q_es_T[0:3, 0:3] = q_es_R
        q_es_aligned[i, :] = quaternion_from_matrix(q_es_T)
    e_trans, e_rot, e_scale_perc = compute_absolute_error(p_es_aligned, q_es_aligned, p_gt, q_gt)
    abs_stats = {
        "trans": compute_statistics(e_trans),
        "rot": compute_statistics(e_rot),
        "scale": compute_statistics(e_scale_perc),
    }
    rel_errors = {}
    for subtraj_len in distances:
        if rel_errors and subtraj_len in rel_errors:
            continue
        _, e_tr, e_tr_perc, e_yaw, e_grav, e_r, e_r_m = compute_relative_error(
            p_es,
            q_es,
            p_gt,
            q_gt,
            np.identity(4),
            subtraj_len,
            0.2 * subtraj_len,
            accum_distances,
            scale,
        )
        rel_errors[subtraj_len] = {
            "rel_trans": e_tr,
            "rel_trans_perc": e_tr_perc,
            "rel_yaw": e_yaw,
            "rel_rot": e_r,
            "rel_gravity": e_grav,
            "rel_rot_deg_per_m": e_r_m,
        }
        for et in kRelMetrics:
            rel_errors[subtraj_len][et + "_stats"] = compute_statistics(rel_errors[subtraj_len][et])
    return {
        "matches": matches,
        "align_str": f"{align_type}_{align_num_frames}",
        "scale": scale,
        "abs_stats": abs_stats,
        "rel_errors": rel_errors,
        "distances": distances,
    }


# --- analyze_trajectory_single.analyze_multiple_trials + multiple_traj_errors.MulTrajError ---
def analyze(results_dir, est_type="traj_est", n_trials=1):
    """{'trials': {i: trajectory()}, 'success': [...], 'mt': {...} or None} as rpg computes them."""
    trials, success, preset = {}, [], []
    mt_abs = {"rmse_trans": [], "rmse_rot": [], "rmse_scale": []}
    mt_rel = {}
    for trial_i in range(n_trials):
        suffix = "" if n_trials == 1 else str(trial_i)
        traj = trajectory(results_dir, kNsToEstFnMapping[est_type] + suffix + ".txt", preset)
        if traj is None:
            continue
        if not preset:
            preset = traj["distances"]
        trials[trial_i] = traj
        success.append(trial_i)
        for et, lab in zip(mt_abs, ("trans", "rot", "scale")):
            mt_abs[et].append(traj["abs_stats"][lab]["rmse"])
        if not mt_rel.keys():
            for d in traj["distances"]:
                mt_rel[d] = {et: traj["rel_errors"][d][et] for et in kRelMetrics}
        else:
            for d in traj["distances"]:
                for et in kRelMetrics:
                    mt_rel[d][et] = np.concatenate((mt_rel[d][et], traj["rel_errors"][d][et]))
    mt = None
    if n_trials > 1 and success:
        overall = {}
        rel_stats = {}
        for et in kRelMetrics:
            values = []
            for d in mt_rel:
                rel_stats.setdefault(d, {})[et] = compute_statistics(mt_rel[d][et])
                values.extend(mt_rel[d][et].tolist())
            overall[et] = compute_statistics(values)
        mt = {
            "rmse": mt_abs,
            "abs_stats": {et: compute_statistics(np.array(v)) for et, v in mt_abs.items()},
            "rel_stats": rel_stats,
            "overall": overall,
        }
    return {"trials": trials, "success": success, "mt": mt}
