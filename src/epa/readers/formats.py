"""The per-format trajectory builders: a :class:`~epa.readers.table.Table` of TUM, OpenVINS, EuRoC,
named-CSV or KITTI rows into a :class:`~epa.core.trajectory.Trajectory` in seconds with unit
quaternions, with the checks every format shares (stamp units, positions, quaternions, order). A new
format is one builder registered in ``READERS``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from epa.core import geometry, ranks
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers.checks import MAX_POSITION_M, Unordered, beyond_reach, in_order
from epa.readers.header import named_columns, position_columns
from epa.readers.table import Table, split_fields

FORMATS = ("auto", "tum", "kitti", "euroc", "openvins", "csv", "position")
TIME_UNITS = ("auto", "s", "ns", "sec_nsec")
# A stamp this large cannot be seconds (it would be ~30,000 years); it is nanoseconds.
NS_THRESHOLD = 1e12
# A quaternion printed with 4+ digits is unit to ~1e-4; beyond this it was not meant to be unit.
QUAT_NORM_TOL = 1e-2


_UPPER = (
    (0, 0),
    (0, 1),
    (0, 2),
    (1, 1),
    (1, 2),
    (2, 2),
)  # the entries of an upper triangle, in order


def upper_to_full(u: np.ndarray, columns=None) -> np.ndarray:
    """(N, 6) upper triangles (11 12 13 22 23 33) -> (N, 3, 3) symmetric matrices; with
    ``columns``, the six columns of ``u`` that hold them (gathered once, not copied twice). Each
    column is gathered into a row of a (3, 3, N) array and the mirror entry copied from that row,
    which is what ``u[:, [[0, 1, 2], [1, 3, 4], [2, 4, 5]]]`` gives, strides and all (later sums
    depend on the layout), at 0.7 of its time (a million poses: 93 ms against 130 for both)."""
    out = np.empty((3, 3, len(u)))
    for (r, c), k in zip(_UPPER, range(6) if columns is None else columns):
        out[r, c] = u[:, k]
        out[c, r] = out[r, c]
    return out.transpose(2, 0, 1)


def _finish(
    tab: Table,
    t: np.ndarray,
    p: np.ndarray,
    q_xyzw: np.ndarray,
    *,
    time_unit: str,
    header_ns: bool = False,
    on_unsorted: str = "error",
    cov_rot=None,
    cov_pos=None,
    printed_quaternions: bool = False,
) -> Trajectory:
    t, p = _own_columns(tab, t, p, time_unit, header_ns)
    _check_positions(tab, p)
    norms = geometry.norms(q_xyzw)  # np.linalg.norm's bits, faster
    zero = norms < 1e-6
    if zero.any():
        tab.fail(int(np.argmax(zero)), "zero quaternion")
    off = np.abs(norms - 1).max()
    # quaternions are unit to their printed digits; far off hints at wrong columns
    if off > QUAT_NORM_TOL:
        tab.notes.append(
            f"quaternions normalised (norm off by up to {off:.3g}; check the column order)"
        )
    # as printed: for the ETH3D program's arithmetic only (epa.metrics.eth3d), never a stage's poses
    q = np.ascontiguousarray(q_xyzw) if printed_quaternions else q_xyzw / norms[:, None]
    traj = Trajectory(t, p, q, cov_rot=cov_rot, cov_pos=cov_pos)
    return _check_order(traj, tab, on_unsorted)


def _own_columns(tab: Table, t, p, time_unit: str, header_ns: bool):
    """The stamps in seconds and the positions, each in an array of its own. The builders slice them
    out of the file's rows (TUM, OpenVINS and EuRoC take column views): kept, a view would hold the
    whole table for the run (2 x 61 MB at a million TUM poses, more with covariance) and every pass
    over t or p would stride across it (0.2 s of the 1M pair's CPU)."""
    return np.ascontiguousarray(_seconds(tab, t, time_unit, header_ns)), np.ascontiguousarray(p)


def _seconds(tab: Table, t: np.ndarray, time_unit: str, header_ns: bool) -> np.ndarray:
    """The stamps in seconds under ``time_unit`` (``auto``: told by the header or the median)."""
    if time_unit == "sec_nsec":
        return _sec_nsec(tab)
    if time_unit == "ns" or (
        time_unit == "auto" and (header_ns or ranks.median(np.abs(t)) > NS_THRESHOLD)
    ):
        if time_unit == "auto" and not header_ns:  # decided by the median: all must agree
            _check_one_unit(tab, t, ns=True)
            tab.notes.append("stamps read as nanoseconds (above 1e12, so not seconds)")
        return t / 1e9
    if time_unit == "auto":
        _check_one_unit(tab, t, ns=False)
    return t


def _check_one_unit(tab: Table, t: np.ndarray, *, ns: bool) -> None:
    """Stamps whose unit was told from their median: every one must be in that unit (a mix of
    seconds and nanoseconds would be sorted into nonsense)."""
    odd = (np.abs(t) <= NS_THRESHOLD) if ns else (np.abs(t) > NS_THRESHOLD)
    if odd.any():
        k = int(np.argmax(odd))
        if ns:
            tab.fail(
                k,
                f"timestamp {float(t[k])!r} is in seconds but most stamps are nanoseconds: the file mixes"
                " units (set load.time_unit if every stamp is in one unit)",
            )
        tab.fail(
            k,
            f"timestamp {float(t[k]):.0f} is in nanoseconds but most stamps are seconds: the file mixes units",
        )


def _check_positions(tab: Table, p: np.ndarray) -> None:
    k = beyond_reach(p)
    if k is not None:
        tab.fail(
            k,
            f"position {np.abs(p[k]).max():.3g} m is beyond {MAX_POSITION_M:.0e} m (a diverged or corrupt row)",
        )


def _sec_nsec(tab: Table) -> np.ndarray:
    """Stamps written as sec.nsec with nsec not zero-padded (e.g. OKVIS): sec + int(frac)/1e9."""
    tokens = [split_fields(line)[0] for line in tab.data_lines()[0]]
    out = np.empty(len(tokens))
    for k, tok in enumerate(tokens):
        sec, _, frac = tok.partition(".")
        if not sec.isdigit() or (frac and not frac.isdigit()):
            tab.fail(k, f"timestamp {tok!r} is not of the form sec.nsec")
        out[k] = int(sec) + (int(frac) / 1e9 if frac else 0.0)
    return out


def _check_order(traj: Trajectory, tab: Table, on_unsorted: str) -> Trajectory:
    try:
        traj, note = in_order(traj, on_unsorted)
    except Unordered as bad:
        tab.fail(
            bad.k,
            f"timestamp {float(traj.t[bad.k])!r} {bad.what} (set load.unsorted: sort to sort and drop"
            " duplicates)",
        )
    if note is not None:
        tab.notes.append(note)
    return traj


# ----------------------------------------------------------------------------- builders
def read_tum(tab: Table, *, time_unit="auto", on_unsorted="error", **kw) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] != 8:
        tab.fail(0, f"TUM needs 8 columns (t x y z qx qy qz qw), found {rows.shape[1]}")
    return _finish(
        tab,
        rows[:, 0],
        rows[:, 1:4],
        rows[:, 4:8],
        time_unit=time_unit,
        on_unsorted=on_unsorted,
        printed_quaternions=kw.get("printed_quaternions", False),
    )


def read_openvins(tab: Table, *, time_unit="auto", on_unsorted="error", **kw) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] != 20:
        tab.fail(0, f"OpenVINS needs 20 columns (TUM + 12 covariance), found {rows.shape[1]}")
    return _finish(
        tab,
        rows[:, 0],
        rows[:, 1:4],
        rows[:, 4:8],
        time_unit=time_unit,
        on_unsorted=on_unsorted,
        cov_rot=upper_to_full(rows[:, 8:14]),
        cov_pos=upper_to_full(rows[:, 14:20]),
        printed_quaternions=kw.get("printed_quaternions", False),
    )


def read_euroc(tab: Table, *, time_unit="auto", on_unsorted="error", **kw) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] < 8:
        tab.fail(
            0, f"EuRoC CSV needs at least 8 columns (t x y z qw qx qy qz), found {rows.shape[1]}"
        )
    q = rows[:, [5, 6, 7, 4]]
    printed = kw.get("printed_quaternions", False)
    return _finish(
        tab,
        rows[:, 0],
        rows[:, 1:4],
        q,
        time_unit=time_unit,
        on_unsorted=on_unsorted,
        printed_quaternions=printed,
    )


def read_positions(tab: Table, *, time_unit="auto", on_unsorted="error", **_) -> Trajectory:
    """Position-only ``t x y z`` rows (GNSS, UWB, some LiDAR odometry): orientations stay unknown."""
    rows = tab.rows
    if rows.shape[1] != 4:
        tab.fail(0, f"position needs 4 columns (t x y z), found {rows.shape[1]}")
    return _positions(tab, rows[:, 0], rows[:, 1:4], time_unit, False, on_unsorted)


def _positions(tab: Table, t, p, time_unit: str, header_ns: bool, on_unsorted: str) -> Trajectory:
    t, p = _own_columns(tab, t, p, time_unit, header_ns)
    _check_positions(tab, p)
    tab.notes.append("position only: no orientation, so every rotation quantity is null")
    return _check_order(Trajectory.positions(t, p), tab, on_unsorted)


def read_named_csv(tab: Table, *, time_unit="auto", on_unsorted="error", **kw) -> Trajectory:
    cols = named_columns(tab.header, tab.rows.shape[1])
    only = position_columns(tab.header, tab.rows.shape[1]) if cols is None else None
    if only is not None:
        p = tab.rows[:, [only["px"], only["py"], only["pz"]]]
        return _positions(tab, tab.rows[:, only["t"]], p, time_unit, only["ns"], on_unsorted)
    if cols is None:
        raise EpaError(
            "the header does not name time, x, y, z, qx, qy, qz, qw columns (or only t, x, y, z)"
            f" (header: {', '.join(tab.header or ['none'])})",
            path=str(tab.path),
        )
    rows = tab.rows
    cov = {k: upper_to_full(rows, cols["cov_" + k]) for k in ("rot", "pos") if "cov_" + k in cols}
    return _finish(
        tab,
        rows[:, cols["t"]],
        rows[:, [cols["px"], cols["py"], cols["pz"]]],
        rows[:, [cols["qx"], cols["qy"], cols["qz"], cols["qw"]]],
        time_unit=time_unit,
        header_ns=cols["ns"],
        on_unsorted=on_unsorted,
        cov_rot=cov.get("rot"),
        cov_pos=cov.get("pos"),
        printed_quaternions=kw.get("printed_quaternions", False),
    )


def read_kitti(
    tab: Table,
    *,
    times: np.ndarray | None = None,
    rate: float = 10.0,
    keep_printed: bool = False,
    **_,
) -> Trajectory:
    rows = tab.rows
    if rows.shape[1] != 12:
        tab.fail(0, f"KITTI needs 12 columns (3x4 row-major pose), found {rows.shape[1]}")
    n = len(rows)
    if times is None:
        t = np.arange(n) / float(rate)
    else:
        if len(times) != n:
            raise EpaError(f"times file has {len(times)} stamps for {n} poses", path=str(tab.path))
        t = np.asarray(times, float)
    m = rows.reshape(n, 3, 4)
    r = m[:, :, :3]
    det = np.linalg.det(r)
    bad = np.abs(det - 1) > 1e-2
    if bad.any():
        tab.fail(int(np.argmax(bad)), f"rotation block is not a rotation (det = {det[bad][0]:.4g})")
    _check_positions(tab, m[:, :, 3])
    traj = Trajectory(
        t,
        m[:, :, 3].copy(),
        # projected onto SO(3): KITTI files print about 7 digits, so R^T R is only approximately I
        geometry.rot_to_quat(geometry.nearest_rotation(r)),
        r_printed=r.copy() if keep_printed else None,
    )
    return _check_order(traj, tab, "error")


READERS = {
    "tum": read_tum,
    "openvins": read_openvins,
    "euroc": read_euroc,
    "csv": read_named_csv,
    "kitti": read_kitti,
    "position": read_positions,
}


def kitti_times_for(path: Path) -> Path | None:
    """evo's naming: ``X_times.txt`` beside ``X.txt``; else ``times.txt`` in the same folder."""
    for cand in (path.with_name(path.stem + "_times.txt"), path.with_name("times.txt")):
        try:
            if cand.is_file():
                return cand
        except OSError:  # an unusable path (too long): the trajectory's own read reports it
            return None
    return None
