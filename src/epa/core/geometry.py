"""Vectorised rotation and pose helpers. Quaternions are (x, y, z, w), as in TUM files."""

from __future__ import annotations

import numpy as np


def norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis, as np.linalg.norm(v, axis=-1) computes them (the squares
    summed first to last: the same bits), 3-4x faster: numpy reduces a short last axis slowly."""
    v = np.asarray(v, dtype=float)
    total = v[..., 0] * v[..., 0]
    for k in range(1, v.shape[-1]):
        total = total + v[..., k] * v[..., k]
    return np.sqrt(total)


def dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products over the last axis, summed first to last as np.sum(a * b, axis=-1) does."""
    total = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        total = total + a[..., k] * b[..., k]
    return total


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (3), the same products and differences as np.cross, without its
    axis moves and copies."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def component_rows(a: np.ndarray) -> np.ndarray:
    """The columns of an (N, k) array as k contiguous rows: elementwise arithmetic on them runs 2-3x
    faster than on strided columns, with the same operations and so the same bits."""
    return np.ascontiguousarray(np.asarray(a, dtype=float).T)


def _mul_rows(a, b) -> tuple:
    """The Hamilton product of quaternions given as component rows (x, y, z, w): quat_mul's
    arithmetic, for callers that keep their quaternions as rows."""
    (ax, ay, az, aw), (bx, by, bz, bw) = a, b
    return (
        aw * bx + bw * ax + (ay * bz - az * by),
        aw * by + bw * ay + (az * bx - ax * bz),
        aw * bz + bw * az + (ax * by - ay * bx),
        aw * bw - (ax * bx + ay * by + az * bz),
    )


def _rotate_rows(q, v) -> tuple:
    """R(q) v on component rows (x, y, z, w) and (x, y, z): quat_rotate's arithmetic."""
    (ux, uy, uz, w), (vx, vy, vz) = q, v
    cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx  # u x v
    return (
        vx + 2 * (w * cx + (uy * cz - uz * cy)),
        vy + 2 * (w * cy + (uz * cx - ux * cz)),
        vz + 2 * (w * cz + (ux * cy - uy * cx)),
    )


def normalize_quat(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q / norms(q)[..., None]


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) -> (..., 3, 3) rotation matrices."""
    x, y, z, w = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    r = np.empty(np.shape(x) + (3, 3))
    for (a, b), entry in zip(_MATRIX_ENTRIES, _rot_entries(x, y, z, w)):
        r[..., a, b] = entry
    return r


_MATRIX_ENTRIES = [(a, b) for a in range(3) for b in range(3)]


def _rot_entries(x, y, z, w) -> tuple:
    """The nine entries of R(q), row by row, of quaternions given as component rows."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1 - 2 * (yy + zz),
        2 * (xy - wz),
        2 * (xz + wy),
        2 * (xy + wz),
        1 - 2 * (xx + zz),
        2 * (yz - wx),
        2 * (xz - wy),
        2 * (yz + wx),
        1 - 2 * (xx + yy),
    )


ROT_TO_QUAT_BLOCK = 65536  # matrices per block in rot_to_quat


def rot_to_quat(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions (x, y, z, w), w >= 0.

    Shepperd's method: pick the largest of the four squared components so no division is
    ever by a small number (accurate for tiny and for 180-degree rotations alike).
    """
    r = np.asarray(r, dtype=float)
    if r.ndim == 3 and len(r) > ROT_TO_QUAT_BLOCK:  # in blocks: a few MB of temporaries, not 200
        q = np.empty((len(r), 4))
        for start in range(0, len(r), ROT_TO_QUAT_BLOCK):
            q[start : start + ROT_TO_QUAT_BLOCK] = rot_to_quat(r[start : start + ROT_TO_QUAT_BLOCK])
        return q
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    trace = m00 + m11 + m22
    pick = np.argmax(np.stack([trace, m00, m11, m22], axis=-1), axis=-1)
    q = np.empty(r.shape[:-2] + (4,))
    # each matrix by its own candidate only: the same formulas per element, a quarter of the work
    for k in range(4):
        sel = pick == k
        if not sel.any():
            continue
        m = r[sel]
        m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
        a, b = (m[:, 2, 1], m[:, 1, 2]), (m[:, 0, 2], m[:, 2, 0])
        c = (m[:, 1, 0], m[:, 0, 1])
        if k == 0:  # w largest
            s = np.sqrt(np.maximum(1 + (m00 + m11 + m22), 1e-300)) * 2
            cand = ((a[0] - a[1]) / s, (b[0] - b[1]) / s, (c[0] - c[1]) / s, 0.25 * s)
        elif k == 1:
            s = np.sqrt(np.maximum(1 + m00 - m11 - m22, 1e-300)) * 2
            cand = (0.25 * s, (c[1] + c[0]) / s, (b[0] + b[1]) / s, (a[0] - a[1]) / s)
        elif k == 2:
            s = np.sqrt(np.maximum(1 - m00 + m11 - m22, 1e-300)) * 2
            cand = ((c[1] + c[0]) / s, 0.25 * s, (a[1] + a[0]) / s, (b[0] - b[1]) / s)
        else:
            s = np.sqrt(np.maximum(1 - m00 - m11 + m22, 1e-300)) * 2
            cand = ((b[0] + b[1]) / s, (a[1] + a[0]) / s, 0.25 * s, (c[0] - c[1]) / s)
        q[sel] = np.stack(cand, axis=-1)
    q = normalize_quat(q)
    return np.where(q[..., 3:4] < 0, -q, q)


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """The rotation nearest (Frobenius) to each (..., 3, 3) matrix near SO(3): U V^T of its SVD."""
    u, _, vt = np.linalg.svd(m)
    return u @ vt


def rotation_angle(r: np.ndarray) -> np.ndarray:
    """Angle (rad) of rotation matrices, computed via the quaternion (accurate near 0 and pi)."""
    return quat_angle(rot_to_quat(r))


def so3_log(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3)."""
    return quat_log(rot_to_quat(r))


def quat_log(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of unit quaternions (x, y, z, w)."""
    if q.ndim == 2:  # on contiguous components: the same arithmetic, about 2x faster
        return np.stack(quat_log_rows(q), axis=-1)
    q = np.where(q[..., 3:4] < 0, -q, q)  # same rotation, angle in [0, pi]
    v = q[..., :3]
    n = norms(v)
    angle = 2 * np.arctan2(n, q[..., 3])
    # angle/sin(angle/2) -> 2 as angle -> 0
    scale = np.where(n > 1e-12, angle / np.where(n > 1e-12, n, 1.0), 2.0)
    return v * scale[..., None]


def quat_log_rows(q: np.ndarray) -> tuple:
    """quat_log of (N, 4) quaternions as its three component rows (the same arithmetic, on
    contiguous components)."""
    return _log_components(*component_rows(q))


def _log_components(x, y, z, w) -> tuple:
    """quat_log of quaternions given as component rows: the rotation vector's three rows."""
    flip = w < 0  # same rotation, angle in [0, pi]
    x, y, z, w = (np.where(flip, -c, c) for c in (x, y, z, w))
    n = np.sqrt(x * x + y * y + z * z)
    angle = 2 * np.arctan2(n, w)
    # angle/sin(angle/2) -> 2 as angle -> 0
    scale = np.where(n > 1e-12, angle / np.where(n > 1e-12, n, 1.0), 2.0)
    return x * scale, y * scale, z * scale


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (..., 3) (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    theta = norms(w)
    half = 0.5 * theta
    # sin(half)/theta -> 1/2 as theta -> 0
    k = np.where(theta > 1e-12, np.sin(half) / np.where(theta > 1e-12, theta, 1.0), 0.5)
    q = np.concatenate([w * k[..., None], np.cos(half)[..., None]], axis=-1)
    return quat_to_rot(q)


def skew(v: np.ndarray) -> np.ndarray:
    """[v]x, the matrix with [v]x w = v x w, for vectors (..., 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def local_covariance(r: np.ndarray, cov_global: np.ndarray) -> np.ndarray:
    """Orientation covariance of the global error (R_true = Exp(d) R, ROS's) as the local one
    (R_true = R Exp(d), epica's and OpenVINS's): d_local = R^T d_global, so C_local = R^T C R."""
    return np.einsum("nba,nbc,ncd->nad", r, cov_global, r)


def rot_z(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions (x, y, z, w): R(a) R(b)."""
    if a.ndim == 2 and a.shape == b.shape:  # one product per row: on contiguous components
        return np.stack(_mul_rows(component_rows(a), component_rows(b)), axis=-1)
    av, aw = a[..., :3], a[..., 3:]
    bv, bw = b[..., :3], b[..., 3:]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., :3] = aw * bv + bw * av + cross(av, bv)
    out[..., 3] = aw[..., 0] * bw[..., 0] - dots(av, bv)
    return out


def relative_angles(q: np.ndarray, step: int) -> np.ndarray:
    """Rotation angle (rad) of q_i^-1 q_{i+step} for every i: quat_angle of relative_motions'
    rotation, the same values as ``rows_angle(*_mul_rows(conjugate, later))`` on each component row
    once (3x cheaper than the (N, 4) arrays' conjugate, product and angle; Step 1's angular speed).

    The conjugate's negations are folded into the signs (IEEE rounding is symmetric, so
    w0 x1 + w1 (-x0) + ((-y0) z1 - (-z0) y1) is exactly (w0 x1 - w1 x0) - (y0 z1 - z0 y1)), and every
    step writes into a few buffers: the same bits without the negated copies and temporaries."""
    rows = component_rows(q)
    (x0, y0, z0, w0), (x1, y1, z1, w1) = rows[:, :-step], rows[:, step:]
    scratch, inner = np.empty(len(x0)), np.empty(len(x0))

    def part(a, b, c, d, out=None) -> np.ndarray:  # a b - c d
        out = np.multiply(a, b, out=out)
        return np.subtract(out, np.multiply(c, d, out=scratch), out=out)

    def component(a0, a1, b0, b1, c0, c1) -> np.ndarray:  # (w0 a1 - w1 a0) - (b0 c1 - c0 b1)
        out = part(w0, a1, w1, a0)
        return np.subtract(out, part(b0, c1, c0, b1, inner), out=out)

    rx = component(x0, x1, y0, y1, z0, z1)
    ry = component(y0, y1, z0, z1, x0, x1)
    rz = component(z0, z1, x0, x1, y0, y1)
    # w0 w1 - ((-x0) x1 + (-y0) y1 + (-z0) z1) = w0 w1 + ((x0 x1 + y0 y1) + z0 z1)
    dot = np.multiply(x0, x1, out=inner)
    dot += np.multiply(y0, y1, out=scratch)
    dot += np.multiply(z0, z1, out=scratch)
    rw = np.multiply(w0, w1)
    rw += dot
    # rows_angle's 2 atan2(sqrt(x x + y y + z z), |w|), in place
    sq = np.multiply(rx, rx, out=rx)
    sq += np.multiply(ry, ry, out=ry)
    sq += np.multiply(rz, rz, out=rz)
    angle = np.arctan2(np.sqrt(sq, out=sq), np.abs(rw, out=rw), out=sq)
    angle *= 2
    return angle


def quat_conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def quat_angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) of unit quaternions; atan2 keeps small angles accurate."""
    return rows_angle(q[..., 0], q[..., 1], q[..., 2], q[..., 3])


def rows_angle(x, y, z, w) -> np.ndarray:
    """quat_angle of quaternions given as their component rows (the same arithmetic)."""
    return 2 * np.arctan2(np.sqrt(x * x + y * y + z * z), np.abs(w))


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v for (..., 4) unit quaternions and (..., 3) vectors."""
    if q.ndim == 2 and v.ndim == 2 and len(q) == len(v):  # on contiguous components
        return np.stack(_rotate_rows(component_rows(q), component_rows(v)), axis=-1)
    u, w = q[..., :3], q[..., 3:]
    uv = cross(u, v)
    return v + 2 * (w * uv + cross(u, uv))


def slerp(q0: np.ndarray, q1: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Spherical interpolation from q0 to q1 at fractions f (shortest path), row by row."""
    q0, q1 = normalize_quat(q0), normalize_quat(q1)
    f = np.asarray(f, float)[..., None]
    dot = dots(q0, q1)[..., None]
    q1 = np.where(dot < 0, -q1, q1)
    angle = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    small = angle < 1e-12  # the same rotation: either end
    w0, w1 = _slerp_weights(f, angle, small, np.sin(np.where(small, 1.0, angle)))
    return w0 * q0 + w1 * q1


def _slerp_weights(f, angle, small, sine) -> tuple:
    """slerp's weights of its two ends at fractions f, from the ends' angle and its sine."""
    w0 = np.where(small, 1.0 - f, np.sin((1.0 - f) * angle) / sine)
    w1 = np.where(small, f, np.sin(f * angle) / sine)
    return w0, w1


def _bracket(t: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each stamp of ``at``: the index k of the pose after it (k - 1 before it, clamped to the
    first and last interval) and its fraction of the interval, in [0, 1]."""
    k = np.clip(np.searchsorted(t, at, side="left"), 1, len(t) - 1)
    return k, _fraction(t[k - 1], t[k], at)


def _fraction(t0: np.ndarray, t1: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The fraction of each stamp of ``at`` in its interval (t0, t1], in [0, 1]."""
    dt = t1 - t0
    return np.clip(np.where(dt > 0, (at - t0) / np.where(dt > 0, dt, 1.0), 0.0), 0.0, 1.0)


def _intervals(t: np.ndarray, at: np.ndarray):
    """:func:`_bracket` as (k - 1, k, fraction), the ends slices when the stamps fall one per
    interval in order (stamps at the poses' own rate mostly do: checked against the interval's
    ends, with one search instead of one per stamp), else index arrays."""
    n, k0 = len(at), int(np.searchsorted(t, at[0], side="left"))
    lo, hi = slice(k0 - 1, k0 - 1 + n), slice(k0, k0 + n)
    if k0 >= 1 and k0 + n <= len(t) and (t[lo] < at).all() and (at <= t[hi]).all():
        return lo, hi, _fraction(t[lo], t[hi], at)
    k, f = _bracket(t, at)
    return run_slice(k - 1), run_slice(k), f


def interpolate(
    t: np.ndarray, p: np.ndarray, q: np.ndarray, at: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Poses at stamps ``at``: positions linear, orientations slerp between the neighbouring poses;
    clamped to the first and last pose outside the stamps (as evo's interpolate)."""
    k, f = _bracket(t, at)
    return p[k - 1] + f[:, None] * (p[k] - p[k - 1]), slerp(q[k - 1], q[k], f)


def relative_motions(q: np.ndarray, p: np.ndarray, i, j):
    """Relative motions T_i^-1 T_j for index arrays i, j, as (quaternions (M, 4), translations (M, 3))."""
    qi_inv = quat_conj(q[i])
    return quat_mul(qi_inv, q[j]), quat_rotate(qi_inv, p[j] - p[i])


def pose_discrepancy(q_ref: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """d_k = q_ref,k * conj(q_est,k), i.e. D_k = Q_k P_k^T: computed once per pose, it turns every
    relative error into one quaternion product per pair (see relative_errors)."""
    return quat_mul(q_ref, quat_conj(q_est))


PAIR_BLOCK = 8192  # pairs per block in pair_errors: temporaries in cache (10 % faster than 16384)


def pair_rows(d: np.ndarray | None, p_ref: np.ndarray, p_est: np.ndarray, *, q=None) -> np.ndarray:
    """What :func:`relative_errors` reads of each pose, as ten contiguous rows (D's x y z w, the
    reference's and the estimate's positions): a set of pairs gathers each side with one ``take``
    (0.3 ms for 100,000 pairs; rows of an (N, 4) array gathered and transposed take 6 ms). Made
    once, it serves every set of pairs of the same poses. ``d`` None: D of ``q`` = (reference,
    estimate quaternions), pose_discrepancy's arithmetic written straight into the rows."""
    rows = np.empty((10, len(p_ref)))
    if d is None:
        for part in row_blocks(len(p_ref)):  # in blocks: the temporaries in cache
            ref, est = component_rows(q[0][part]), component_rows(q[1][part])
            est[:3] *= -1  # conj(q_est)
            for k, row in enumerate(_mul_rows(ref, est)):
                rows[k, part] = row
    else:
        rows[:4] = np.asarray(d).T
    rows[4:7], rows[7:] = np.asarray(p_ref).T, np.asarray(p_est).T
    return rows


def relative_errors(d: np.ndarray, p_ref: np.ndarray, p_est: np.ndarray, i, j):
    """Per-pair relative pose error E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j), as in evo and ov_eval.

    With D = Q P^T (``pose_discrepancy``): angle(E) = angle(D_i D_j^T) and
    |t(E)| = |D_i (p_j - p_i) - (q_j - q_i)|, exact rewrites that gather one quaternion per pair.
    Returns (rotation angle in degrees, translation norm in metres) for each pair.
    """
    return pair_errors(pair_rows(d, p_ref, p_est), i, j)


def pair_errors(rows: np.ndarray, i, j) -> tuple[np.ndarray, np.ndarray]:
    """:func:`relative_errors` of the pairs (i, j) of the poses whose :func:`pair_rows` are
    ``rows`` (made once for several sets of pairs): quat_mul, quat_angle, quat_rotate and norms'
    arithmetic, each pair on its own, so the same bits whatever the rows or blocks."""
    i, j = np.asarray(i, dtype=np.intp), np.asarray(j, dtype=np.intp)
    # checked once: the gathers clip (np.take with an out and mode="raise" copies first)
    if len(i) and (min(i.min(), j.min()) < 0 or max(i.max(), j.max()) >= rows.shape[1]):
        raise IndexError(f"pair index out of range for {rows.shape[1]} poses")
    angle, trans = np.empty(len(i)), np.empty(len(i))
    # in blocks, every temporary in reused scratch rows: a few hundred kB, in cache
    size = min(len(i), PAIR_BLOCK)
    scratch, gathered = np.empty((8, size)), np.empty((2, 10, size))
    for s in range(0, len(i), PAIR_BLOCK):
        block = slice(s, s + PAIR_BLOCK)
        a, b = (_gather(rows, k[block], out) for k, out in zip((i, j), gathered))
        t = scratch[:, : a.shape[1]]
        _angle_block(a, b, t, angle[block])
        _trans_block(a, b, t, trans[block])
    return angle, trans


def _angle_block(a: np.ndarray, b: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:
    """pair_errors' angle (deg) of D_i D_j^T, D_i and D_j the first four of ``a`` and ``b``:
    _mul_rows of (D_i, conj D_j) and rows_angle, with conj's negations taken out of the sums
    (exactly: -p + q is q - p), into ``out``; ``t``: scratch rows."""
    mul = np.multiply
    ax, ay, az, aw = a[:4]
    cx, cy, cz, cw = b[:4]
    x, y, z, w, u = t[:5]
    mul(cw, ax, out=x), np.subtract(x, mul(aw, cx, out=u), out=x)
    mul(az, cy, out=u), np.subtract(u, mul(ay, cz, out=w), out=u), np.add(x, u, out=x)
    mul(cw, ay, out=y), np.subtract(y, mul(aw, cy, out=u), out=y)
    mul(ax, cz, out=u), np.subtract(u, mul(az, cx, out=w), out=u), np.add(y, u, out=y)
    mul(cw, az, out=z), np.subtract(z, mul(aw, cz, out=u), out=z)
    mul(ay, cx, out=u), np.subtract(u, mul(ax, cy, out=w), out=u), np.add(z, u, out=z)
    # w = aw cw - (ax (-cx) + ay (-cy) + az (-cz)): its sum's sign taken out
    mul(ax, cx, out=w), np.add(w, mul(ay, cy, out=u), out=w), np.add(w, mul(az, cz, out=u), out=w)
    np.add(w, mul(aw, cw, out=u), out=w)
    mul(x, x, out=x), np.add(x, mul(y, y, out=u), out=x), np.add(x, mul(z, z, out=u), out=x)
    np.arctan2(np.sqrt(x, out=x), np.abs(w, out=w), out=out)
    # np.degrees is x * (180 / pi), one rounding: the same bits, 7x faster than its loop
    np.multiply(np.multiply(out, 2, out=out), 180 / np.pi, out=out)


def _trans_block(a: np.ndarray, b: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:
    """pair_errors' translation error |D_i (p_j - p_i) - (q_j - q_i)| (``a``, ``b``: pair_rows'
    ten rows of i and j): _rotate_rows' and norms' arithmetic, into ``out``; ``t``: scratch rows."""
    mul, sub = np.multiply, np.subtract
    ux, uy, uz, w = a[:4]
    vx, vy, vz, cx, cy, cz, u, e = t
    sub(b[7], a[7], out=vx), sub(b[8], a[8], out=vy), sub(b[9], a[9], out=vz)
    mul(uy, vz, out=cx), sub(cx, mul(uz, vy, out=u), out=cx)  # c = u x v
    mul(uz, vx, out=cy), sub(cy, mul(ux, vz, out=u), out=cy)
    mul(ux, vy, out=cz), sub(cz, mul(uy, vx, out=u), out=cz)
    # each component: v + 2 (w c + (u x c)) - (q_j - q_i), written over v (no longer read)
    for k, (v, c, p, q, cp, cq) in enumerate(
        ((vx, cx, uy, uz, cz, cy), (vy, cy, uz, ux, cx, cz), (vz, cz, ux, uy, cy, cx))
    ):
        mul(p, cp, out=e), sub(e, mul(q, cq, out=u), out=e), np.add(e, mul(w, c, out=u), out=e)
        np.add(v, mul(e, 2, out=e), out=v), sub(v, sub(b[4 + k], a[4 + k], out=u), out=v)
    mul(vx, vx, out=out), np.add(out, mul(vy, vy, out=u), out=out)
    np.sqrt(np.add(out, mul(vz, vz, out=u), out=out), out=out)


def _gather(rows: np.ndarray, k: np.ndarray, out: np.ndarray) -> np.ndarray:
    """rows[:, k], into ``out`` (10 rows, at least len(k) columns); a view where k is a run of
    consecutive indices (a pair set's starts mostly are: every pose but the last few), half the
    gathering of a set of pairs."""
    if consecutive(k) and 0 <= k[0] and k[-1] < rows.shape[1]:
        return rows[:, k[0] : k[-1] + 1]
    return np.take(rows, k, axis=1, out=out[:, : len(k)], mode="clip")  # in range: pair_errors


def consecutive(k: np.ndarray) -> bool:
    """Whether the integers ``k`` are k[0], k[0] + 1, ..., k[-1] (not empty)."""
    return bool(len(k) and k[-1] - k[0] == len(k) - 1 and (np.diff(k) == 1).all())


def path_distances(p: np.ndarray) -> np.ndarray:
    """Cumulative path length at every pose, starting at 0: the steps' norms summed first to last,
    as np.cumsum sums them. In blocks of poses, each block's sum carried on from the distance
    before it (one sum after the other, so the same bits), its temporaries in cache: at a million
    poses the whole (N - 1, 3) difference and its norms took 40 MB of fresh pages."""
    out = np.empty(len(p))
    if len(p) == 0:
        return out
    out[0] = 0.0
    for part in row_blocks(len(p) - 1):
        a, b = part.start, part.stop
        out[a + 1 : b + 1] = norms(p[a + 1 : b + 1] - p[a:b])
        np.cumsum(out[a : b + 1], out=out[a : b + 1])  # from out[a], the distance so far
    return out


ROW_BLOCK = (
    32768  # columns per block in the *_rows functions: temporaries in cache, not fresh pages
)


def row_blocks(n: int):
    """Slices of ``ROW_BLOCK`` columns covering n (for arithmetic on component rows in blocks)."""
    return (slice(s, min(s + ROW_BLOCK, n)) for s in range(0, n, ROW_BLOCK))


def _part(idx, part: slice):
    """The part of an index array or slice (of step 1) that the columns ``part`` of its result take."""
    if isinstance(idx, slice):
        return slice(idx.start + part.start, idx.start + part.stop)
    return idx[part]


def relative_motion_rows(
    q_rows: np.ndarray, p_rows: np.ndarray, i, j
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`relative_motions` on component rows ((4, N) quaternions, (3, N) positions), returned
    as rows, (4, M) and (3, M): its arithmetic, without the (M, 4) arrays' copies, in blocks of
    pairs. ``i``, ``j``: index arrays or slices (of step 1, with a start)."""
    m = len(i) if not isinstance(i, slice) else i.stop - i.start
    q, t = np.empty((4, m)), np.empty((3, m))
    for part in row_blocks(m):
        a, b = run_slice(_part(i, part)), run_slice(_part(j, part))
        inv = conj_rows(_take(q_rows, a))
        q[:, part] = _mul_rows(inv, _take(q_rows, b))
        t[:, part] = _rotate_rows(inv, _take(p_rows, b) - _take(p_rows, a))
    return q, t


def log_rows(q_rows: np.ndarray) -> np.ndarray:
    """quat_log of (4, N) quaternion rows, as (3, N) rows (:func:`quat_log_rows`' arithmetic)."""
    out = np.empty((3, q_rows.shape[1]))
    for part in row_blocks(q_rows.shape[1]):
        out[:, part] = _log_components(*q_rows[:, part])
    return out


def rot_rows(q_rows: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """quat_to_rot of (4, N) quaternion rows, as (3, 3, N) rows (the same formulas), written into
    ``out`` when given."""
    r = np.empty((3, 3, q_rows.shape[1])) if out is None else out
    for part in row_blocks(q_rows.shape[1]):
        for (a, b), entry in zip(_MATRIX_ENTRIES, _rot_entries(*q_rows[:, part])):
            r[a, b, part] = entry
    return r


def conj_rows(q_rows) -> tuple:
    """The conjugate (the inverse of a unit quaternion) of component rows: quat_conj's arithmetic."""
    x, y, z, w = q_rows
    return (-x, -y, -z, w)


def mul_rows(a_rows, b_rows) -> np.ndarray:
    """The Hamilton product of component rows ((4, N) or four scalars each), as (4, N) rows:
    quat_mul's arithmetic."""
    return np.array(_mul_rows(a_rows, b_rows))


def rotate_rows(q_rows, v_rows) -> np.ndarray:
    """R(q) v on component rows ((4, N) quaternions, (3, N) or three scalars), as (3, N) rows:
    quat_rotate's arithmetic."""
    return np.array(_rotate_rows(q_rows, v_rows))


def interpolator(t: np.ndarray, p_rows: np.ndarray, q_rows: np.ndarray):
    """:func:`interpolate` of the same poses at several sets of stamps, on component rows ((3, N)
    positions, (4, N) quaternions): the slerp's setup of each interval (its normalised ends, their
    angle and its sine) is made once, and each call ``at(stamps)`` returns (3, M) and (4, M) rows.
    The same arithmetic as interpolate, element by element: the same bits."""
    x, y, z, w = q_rows
    q = q_rows / np.sqrt(x * x + y * y + z * z + w * w)
    q0, q1 = q[:, :-1], q[:, 1:]
    dot = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3]
    q1 = np.where(dot < 0, -q1, q1)
    angle = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    small = angle < 1e-12  # the same rotation: either end
    sine = np.sin(np.where(small, 1.0, angle))

    def at(stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p_at, q_at = np.empty((3, len(stamps))), np.empty((4, len(stamps)))
        for part in row_blocks(len(stamps)):
            lo, hi, f = _intervals(t, stamps[part])
            w0, w1 = _slerp_weights(f, _take(angle, lo), _take(small, lo), _take(sine, lo))
            p0 = _take(p_rows, lo)
            p_at[:, part] = p0 + f * (_take(p_rows, hi) - p0)
            q_at[:, part] = w0 * _take(q0, lo) + w1 * _take(q1, lo)
        return p_at, q_at

    return at


def run_slice(k):
    """Indices as a slice where they are a run of consecutive ones (a block of pairs mostly is:
    pairs a fixed number of poses apart; stamps at the poses' own rate fall in one interval after
    the other), else as they are: a slice reads a view where indices would gather."""
    if isinstance(k, slice) or not consecutive(k) or k[0] < 0:  # a negative run is not its slice
        return k
    return slice(int(k[0]), int(k[-1]) + 1)


def _take(rows: np.ndarray, k) -> np.ndarray:
    """rows[..., k] of a slice (a view) or indices (np.take: 3-5x faster than fancy indexing over
    the last axis of (n, N) rows)."""
    return rows[..., k] if isinstance(k, slice) else np.take(rows, k, axis=-1)


def matrix_rows(m: np.ndarray) -> np.ndarray:
    """(B, 3, 3) matrices as (3, 3, B) component rows."""
    return np.ascontiguousarray(m.transpose(1, 2, 0))


def matmul_rows(a, b) -> list:
    """a b of 3x3 matrices given as component rows (entries indexed [i][k]: rows of B matrices, or
    the scalars of one matrix), as a 3x3 list of rows: the products written out, 3-4x faster than
    numpy's stacked matmul, which calls BLAS once per 3x3 matrix."""
    return [
        [a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)]
        for i in range(3)
    ]


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of (3, N) component rows, as (3, N) rows."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    np.subtract(a[1] * b[2], a[2] * b[1], out=out[0])
    np.subtract(a[2] * b[0], a[0] * b[2], out=out[1])
    np.subtract(a[0] * b[1], a[1] * b[0], out=out[2])
    return out
