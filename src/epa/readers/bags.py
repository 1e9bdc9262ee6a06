"""ROS bags as trajectory sources: ROS 1 ``.bag``, ROS 2 bag folders (``metadata.yaml`` + ``.db3`` or
``.mcap``) and bare ``.mcap`` files, read with ``rosbags`` (no ROS installation).

Only the chosen topic's messages are deserialised (and ``/tf_static`` for TF). Poses are stamped
with the message header (``stamp: record`` uses the bag's record time). A ``nav_msgs/Path`` topic
gives the poses of its *last* message, the final (most optimised) path. TF poses are those of the
chosen parent -> child chain at the stamps of its dynamic transforms, composed through
``/tf_static``; no resampling.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory

# what is a bag is told by its name, without importing this module (readers.detect); here too
from epa.readers.detect import BAG_SUFFIXES as BAG_SUFFIXES
from epa.readers.detect import bag_files as bag_files
from epa.readers.detect import is_bag as is_bag

log = logging.getLogger(__name__)

POSE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped",
    "nav_msgs/msg/Odometry",
    "nav_msgs/msg/Path",
    "tf2_msgs/msg/TFMessage",
)


@dataclass(frozen=True)
class TopicInfo:
    topic: str
    msgtype: str
    count: int
    start_s: float | None  # record time of the first and last message (None without an index)
    end_s: float | None

    @property
    def supported(self) -> bool:
        return self.msgtype in POSE_TYPES


class _Open:
    """An open bag whose errors are one line naming it."""

    def __init__(self, path):
        self.path = Path(path)

    def __enter__(self):
        from rosbags.highlevel import AnyReader

        if not self.path.exists():
            raise EpaError(
                "file not found" if self.path.suffix else "bag folder not found",
                path=str(self.path),
            )
        try:
            self.reader = AnyReader([self.path])
            self.reader.open()
        except EpaError:
            raise
        except Exception as exc:  # rosbags raises its own types for every kind of damage
            raise EpaError(f"cannot read the bag: {_reason(exc)}", path=str(self.path)) from None
        return self.reader

    def __exit__(self, exc_type, exc, tb):
        try:
            self.reader.close()
        except Exception:
            pass
        if isinstance(exc, Exception) and not isinstance(exc, EpaError):
            # damage met while reading (a decompressor's, a parser's error): one line, as on opening
            raise EpaError(f"cannot read the bag: {_reason(exc)}", path=str(self.path)) from None
        return False


def _reason(exc: Exception) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return f"{type(exc).__name__}: {text}" if type(exc).__name__ not in text else text


def topics(path) -> list[TopicInfo]:
    """Every topic of a bag with its type, message count and record-time span."""
    with _Open(path) as reader:
        out = []
        for topic in sorted(reader.topics):
            conns = [c for c in reader.connections if c.topic == topic]
            count = sum(c.msgcount for c in conns)
            out.append(TopicInfo(topic, conns[0].msgtype, count, *_span(reader, conns, count)))
        return out


def _span(reader, conns, count) -> tuple[float | None, float | None]:
    if not count:
        return None, None
    if not reader.is2:  # a ROS 1 bag's index holds every record's time: no message is read
        try:
            times = [ix.time for c in conns for ix in reader.readers[0].indexes[c.id]]
            return min(times) / 1e9, max(times) / 1e9
        except (AttributeError, KeyError, IndexError):  # another rosbags layout: read the records
            pass
    first = last = None
    for _, stamp, _ in reader.messages(connections=conns):
        first = stamp if first is None else first
        last = stamp
    if first is None or last is None:  # the index counted messages the reader does not give
        return None, None
    return first / 1e9, last / 1e9


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def read_bag(
    path,
    topic: str | None = None,
    *,
    frames: tuple[str, str] | list | None = None,
    stamp: str = "header",
    static_topic: str = "/tf_static",
    tf_rate: float | None = None,
    notes: list | None = None,
) -> Trajectory:
    """The trajectory of one topic of a bag (or one TF chain, given ``frames`` parent, child). A TF
    chain is sampled at the stamps of its busiest link, or with ``tf_rate`` (Hz) as evo samples it."""
    path = Path(path)
    with _Open(path) as reader:
        available = {t: reader.topics[t].msgtype for t in reader.topics}
        if topic is None:
            topic = _only_pose_topic(path, available, frames)
            if notes is not None:
                notes.append(f"topic {topic} (the bag's only pose topic)")
            log.warning(
                "%s: reading topic %s (the bag's only pose topic; set topic to choose)", path, topic
            )
        where = f"{path} topic {topic}"
        if topic not in available:
            raise EpaError(f"no topic {topic!r}; the bag has {_listing(available)}", path=str(path))
        msgtype = available[topic]
        if msgtype not in POSE_TYPES:
            raise EpaError(
                f"topic {topic} is {msgtype}, not a pose type ({', '.join(t.split('/')[-1] for t in POSE_TYPES)})",
                path=str(path),
            )
        if msgtype == "tf2_msgs/msg/TFMessage":
            if not frames or len(frames) != 2:
                raise EpaError(
                    f"topic {topic} is TF: give the parent and child frame (frames: [parent, child])",
                    path=str(path),
                )
            try:
                return _read_tf(
                    reader,
                    path,
                    topic,
                    static_topic,
                    tuple(frames),
                    stamp,
                    notes,
                    evo_lookup_hz=tf_rate,
                )
            except EpaError as exc:
                raise (exc if exc.path else EpaError(exc.message, path=where)) from None
            except Exception as exc:  # a damaged chunk: as the pose reader says it
                raise EpaError(f"cannot read the messages: {_reason(exc)}", path=where) from None
        conns = [c for c in reader.connections if c.topic == topic]
        try:
            traj = _read_poses(reader, conns, msgtype, stamp)
        except EpaError as exc:
            raise EpaError(exc.message, path=where) from None
        except Exception as exc:
            raise EpaError(f"cannot read the messages: {_reason(exc)}", path=where) from None
    if len(traj) == 0:
        raise EpaError(f"topic {topic} has no messages", path=str(path))
    if notes is not None:
        notes.append(f"bag topic {topic} ({msgtype.split('/')[-1]}, {stamp} stamps)")
    return traj


def _listing(available: dict) -> str:
    return (
        ", ".join(f"{t} ({m.split('/')[-1]})" for t, m in sorted(available.items())) or "no topics"
    )


def _only_pose_topic(path, available: dict, frames) -> str:
    poses = sorted(
        t
        for t, m in available.items()
        if m in POSE_TYPES and (frames or m != "tf2_msgs/msg/TFMessage")
    )
    if frames and "/tf" in available:
        return "/tf"
    if len(poses) != 1:
        raise EpaError(f"choose a topic: the bag has {_listing(available)}", path=str(path))
    return poses[0]


def _pose_of(msg, msgtype: str):
    """(position, orientation xyzw, 6x6 covariance or None) of one message."""
    if msgtype == "geometry_msgs/msg/TransformStamped":
        tr, ro = msg.transform.translation, msg.transform.rotation
        return (tr.x, tr.y, tr.z), (ro.x, ro.y, ro.z, ro.w), None
    pose, cov = msg.pose, None
    if msgtype in ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry"):
        pose, cov = msg.pose.pose, msg.pose.covariance
    po, ro = pose.position, pose.orientation
    return (po.x, po.y, po.z), (ro.x, ro.y, ro.z, ro.w), cov


def _read_poses(reader, conns, msgtype: str, stamp: str) -> Trajectory:
    if msgtype == "nav_msgs/msg/Path":
        last = None
        for conn, record_ns, raw in reader.messages(connections=conns):
            last = (conn, record_ns, raw)
        if last is None:
            return Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)))
        msg = reader.deserialize(last[2], last[0].msgtype)
        n = len(msg.poses)
        t, p, q = np.empty(n), np.empty((n, 3)), np.empty((n, 4))
        for k, ps in enumerate(msg.poses):
            t[k] = _stamp(ps.header) if stamp == "header" else last[1] / 1e9
            (p[k], q[k], _) = _pose_of(ps, "geometry_msgs/msg/PoseStamped")
        return _finish(t, p, q, None)
    raws, records = [], []
    for _, record_ns, raw in reader.messages(connections=conns):
        raws.append(raw)
        records.append(record_ns)
    fast = _decode_all(reader, raws, conns[0].msgtype, msgtype, ros1=not reader.is2)
    # every message decoded at once from fixed offsets (checked against rosbags)
    if fast is not None:
        t, p, q, cov = fast
        if stamp == "record":
            t = np.asarray(records, float) / 1e9
        return _finish(t, p, q, cov)
    count = len(raws)
    t, p, q = np.empty(count), np.empty((count, 3)), np.empty((count, 4))
    cov = (
        np.empty((count, 36))
        if msgtype in ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry")
        else None
    )
    for k, (record_ns, raw) in enumerate(zip(records, raws)):
        msg = reader.deserialize(raw, conns[0].msgtype)
        t[k] = _stamp(msg.header) if stamp == "header" else record_ns / 1e9
        p[k], q[k], c = _pose_of(msg, msgtype)
        if cov is not None:
            cov[k] = c
    return _finish(t, p, q, cov)


# Doubles after the header (and child frame id) of each fixed-layout type: pose (7), covariance (36).
_LAYOUT = {
    "geometry_msgs/msg/PoseStamped": (False, 7),
    "geometry_msgs/msg/PoseWithCovarianceStamped": (False, 43),
    "nav_msgs/msg/Odometry": (True, 43),
    "geometry_msgs/msg/TransformStamped": (True, 7),
}


def _decode_all(reader, raws: list, conn_type: str, msgtype: str, ros1: bool):
    """Stamps, poses and covariances of all messages at once, when every message has the same length
    (the frame ids do not change): the fields sit at the same offsets, found from the first message.
    Verified against rosbags' own deserialisation of the first and last message; else None."""
    if msgtype not in _LAYOUT or not raws or len({len(r) for r in raws}) != 1:
        return None
    child, n_doubles = _LAYOUT[msgtype]
    first = raws[0]

    def u32(off):
        return int.from_bytes(first[off : off + 4], "little")

    if ros1:  # seq, sec, nsec, frame_id; no alignment
        sec_at, off = 4, 16 + u32(12)
        if child:
            off += 4 + u32(off)
    else:  # CDR: 4-byte encapsulation header; fields aligned to their size, counted after it
        if first[1] != 1:  # not little-endian CDR
            return None
        sec_at, off = 4, 16 + u32(12)
        if child:
            off = 4 + ((off - 4 + 3) & ~3)
            off += 4 + u32(off)
        off = 4 + ((off - 4 + 7) & ~7)
    size = len(first)
    if off + 8 * n_doubles > size:
        return None
    rows = np.frombuffer(b"".join(raws), np.uint8).reshape(len(raws), size)
    sec = rows[:, sec_at : sec_at + 4].copy().view("<u4" if ros1 else "<i4")[:, 0].astype(float)
    nsec = rows[:, sec_at + 4 : sec_at + 8].copy().view("<u4")[:, 0].astype(float)
    doubles = rows[:, off : off + 8 * n_doubles].copy().view("<f8")
    t = sec + nsec * 1e-9
    p, q = doubles[:, 0:3], doubles[:, 3:7]
    cov = doubles[:, 7:43] if n_doubles == 43 else None
    for k in (0, len(raws) - 1):
        msg = reader.deserialize(raws[k], conn_type)
        pos, quat, c = _pose_of(msg, msgtype)
        if (
            _stamp(msg.header) != t[k]
            or tuple(p[k]) != tuple(pos)
            or tuple(q[k]) != tuple(quat)
            or (cov is not None and not np.array_equal(cov[k], np.asarray(c, float)))
        ):
            return None
    return t, p, q, cov


def _quat_norms(q: np.ndarray, what: str = "message") -> np.ndarray:
    """The norms of finite quaternions; a zero one (or one too large to normalise) is an error."""
    with np.errstate(over="ignore", invalid="ignore"):
        norms = np.linalg.norm(q, axis=1)
    bad = ~np.isfinite(norms) | (norms < 1e-6)
    if len(q) and bad.any():
        k = int(np.argmax(bad))
        raise EpaError(
            f"{what} {k + 1}: "
            + ("zero quaternion" if norms[k] < 1e-6 else "quaternion too large to normalise")
        )
    return norms


def _finish(t, p, q, cov36) -> Trajectory:
    if len(t) and (not np.isfinite(p).all() or not np.isfinite(q).all()):
        k = int(np.argmax(~(np.isfinite(p).all(axis=1) & np.isfinite(q).all(axis=1))))
        raise EpaError(f"message {k + 1}: non-finite pose (nan or inf)")
    norms = _quat_norms(q)
    q = q / norms[:, None] if len(t) else q
    # an array of its own: a view would keep every message's decoded doubles for the run (344 bytes
    # a pose with covariance, for 24 of positions)
    p = np.ascontiguousarray(p)
    extra = {}
    if cov36 is not None and np.any(cov36):  # all zeros (a common placeholder) is no covariance
        c = cov36.reshape(-1, 6, 6)  # ROS order: x y z, rotation about the fixed x y z axes
        # ROS's orientation error is about the parent's axes; epica's is the local one
        cov_rot = geometry.local_covariance(geometry.quat_to_rot(q), c[:, 3:, 3:])
        extra = {"cov_pos": c[:, :3, :3].copy(), "cov_rot": cov_rot, "cov_ros": c.copy()}
    return Trajectory(t, p, q, **extra)


# ----------------------------------------------------------------------------- TF
def _tf_edges(
    reader, topic: str, stamp: str
) -> tuple[dict[tuple[str, str], tuple[list, list]], int | None]:
    """Per (frame_id, child_frame_id): its rows (t, x, y, z, qx, qy, qz, qw) and their stamps in
    integer ns; and the stamp of the topic's first transform, in message order (where evo starts)."""
    conns = [c for c in reader.connections if c.topic == topic]
    edges: dict[tuple[str, str], tuple[list, list]] = {}
    first_ns = None
    for conn, record_ns, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        for tf in msg.transforms:
            (pos, quat, _) = _pose_of(tf, "geometry_msgs/msg/TransformStamped")
            ns = (
                tf.header.stamp.sec * 10**9 + tf.header.stamp.nanosec
                if stamp == "header"
                else int(record_ns)
            )
            t = _stamp(tf.header) if stamp == "header" else record_ns / 1e9
            rows, stamps = edges.setdefault(
                (tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/")), ([], [])
            )
            rows.append((t, *pos, *quat))
            stamps.append(ns)
            first_ns = ns if first_ns is None else first_ns
    return edges, first_ns


def _chain(
    edges: set[tuple[str, str]], parent: str, child: str
) -> list[tuple[str, str, bool]] | None:
    """The path parent -> child in the frame tree as (frame_id, child_frame_id, inverted) steps.
    Searched in sorted order (never hash order); a loop among the frames linked to ``parent``
    (``odom -> world`` beside ``world -> odom``, say) is an error: a TF tree has one path."""
    _no_loop(edges, parent)
    nbrs: dict[str, list] = {}
    for a, b in sorted(edges):
        nbrs.setdefault(a, []).append((b, (a, b), False))
        nbrs.setdefault(b, []).append((a, (a, b), True))
    prev: dict[str, tuple | None] = {parent: None}
    queue = [parent]
    while queue:
        f = queue.pop(0)
        if f == child:
            break
        for g, edge, inv in nbrs.get(f, []):
            if g not in prev:
                prev[g] = (f, edge, inv)
                queue.append(g)
    if child not in prev:
        return None
    steps = []
    f = child
    while (link := prev[f]) is not None:
        f0, edge, inv = link
        steps.append((edge[0], edge[1], inv))
        f = f0
    return steps[::-1]


def _no_loop(edges: set[tuple[str, str]], parent: str) -> None:
    root: dict[str, str] = {}

    def find(f: str) -> str:
        while root.setdefault(f, f) != f:
            f = root[f]
        return f

    linked = {parent}
    grew = True
    while grew:  # the frames linked to parent
        grew = False
        for a, b in edges:
            if (a in linked) != (b in linked):
                linked |= {a, b}
                grew = True
    for a, b in sorted(e for e in edges if e[0] in linked):
        ra, rb = find(a), find(b)
        if ra == rb:
            both = " and ".join(f"{x} -> {y}" for x, y in sorted({(a, b), (b, a)} & set(edges)))
            raise EpaError(
                f"the TF frames form a loop ({both} close it): a TF tree links two frames one way only"
            )
        root[ra] = rb


def _interp(rows: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (linear) and rotations (slerp) of a transform's time series at ``t``."""
    if len(rows) == 1:
        return np.repeat(rows[:, 1:4], len(t), axis=0), np.repeat(rows[:, 4:8], len(t), axis=0)
    return geometry.interpolate(rows[:, 0], rows[:, 1:4], rows[:, 4:8], t)


def _read_tf(
    reader,
    path: Path,
    topic: str,
    static_topic: str,
    frames: tuple[str, str],
    stamp: str,
    notes,
    evo_lookup_hz: float | None = None,
):
    """The poses of the TF chain ``frames`` (parent, child) of ``topic``, through ``static_topic``.
    ``evo_lookup_hz``: sampled as evo samples a chain, a lookup every 1/evo_lookup_hz s from the
    topic's first message with stamps through double seconds (:func:`_as_evo_looks_up`); None: at
    the stamps of the chain's busiest dynamic link."""
    parent, child = (f.lstrip("/") for f in frames)
    where = f"{path} topic {topic}"
    dynamic, first_ns = _tf_edges(reader, topic, stamp)
    static = _tf_edges(reader, static_topic, stamp)[0] if static_topic in reader.topics else {}
    steps = _tf_steps(dynamic, static, parent, child, where)
    series = _tf_series(steps, dynamic, static)
    moving = [e for e, (_, _, is_static) in series.items() if not is_static]
    if not moving or first_ns is None:
        raise EpaError(
            f"the chain {parent} -> {child} is static (only {static_topic}): no trajectory",
            path=where,
        )
    if evo_lookup_hz is not None:
        series, t_ns = _as_evo_looks_up(series, moving, first_ns, evo_lookup_hz)
        sampled = f"every {1 / evo_lookup_hz:g} s from the first message of {topic}, as evo"
    else:
        # the stamps of the dynamic link with most messages; the others are interpolated within their span
        t_ns = series[max(moving, key=lambda e: len(series[e][0]))][1]
        sampled = f"at the stamps of {topic}"
    for e in moving:
        ns = series[e][1]
        t_ns = t_ns[(t_ns >= ns[0]) & (t_ns <= ns[-1])]
    t_ns = np.unique(t_ns)
    if evo_lookup_hz is None and len(steps) == 1 and not steps[0][2]:  # one direct link
        rows = series[(steps[0][0], steps[0][1])][0]
        return _direct_link(rows, f"{parent} -> {child}", topic, stamp, notes)
    if len(t_ns) == 0:
        raise EpaError(f"the transforms of {parent} -> {child} never overlap in time", path=where)
    r_total, p_total = _compose(series, steps, t_ns)
    if notes is not None:
        chain_text = " -> ".join([parent] + [b if not inv else a for a, b, inv in steps])
        notes.append(f"bag TF {chain_text} ({len(t_ns)} poses {sampled}, {stamp} stamps)")
    return Trajectory.from_rp(_to_sec(t_ns), r_total, p_total)


def _tf_steps(dynamic: dict, static: dict, parent: str, child: str, where: str) -> list:
    """The chain's steps (:func:`_chain`), or an error naming the frames there are."""
    steps = _chain(set(dynamic) | set(static), parent, child)
    if steps is None:
        known = sorted({f for e in set(dynamic) | set(static) for f in e})
        missing = [f for f in (parent, child) if f not in known]
        what = (
            f"unknown frame {', '.join(map(repr, missing))}"
            if missing
            else f"no chain from {parent!r} to {child!r}"
        )
        raise EpaError(f"{what}; the TF frames are {', '.join(known) or 'none'}", path=where)
    return steps


def _tf_series(steps: list, dynamic: dict, static: dict) -> dict:
    """Per link of the chain: its rows and integer-ns stamps in stamp order, and whether it is
    static; every pose finite, every quaternion one that normalises."""
    series = {}
    for a, b, _ in steps:
        rows, ns = dynamic.get((a, b)) or static[(a, b)]
        order = np.argsort(np.asarray(ns), kind="stable")
        series[(a, b)] = (
            np.array(rows, float)[order],
            np.asarray(ns, np.int64)[order],
            (a, b) not in dynamic,
        )
    for (a, b), (rows, _, _) in series.items():
        if not np.isfinite(rows).all():
            k = int(np.argmax(~np.isfinite(rows).all(axis=1)))
            raise EpaError(f"transform {a} -> {b}, message {k + 1}: non-finite pose (nan or inf)")
        _quat_norms(rows[:, 4:8], f"transform {a} -> {b}, message")
    return series


def _as_evo_looks_up(series: dict, moving: list, first_ns: int, lookup_hz: float):
    """The links' stamps and the lookup instants as evo has them. evo looks up through ROS 1's
    tf2_py, which carries every stamp as a double of seconds (fromSec(to_sec())): up to 1.2e-7 s off
    for epoch stamps, 1e-7 m in the poses. So do we."""
    series = {
        e: (rows, _through_double_seconds(ns), is_static)
        for e, (rows, ns, is_static) in series.items()
    }
    t_ns = _through_double_seconds(
        _evo_lookup_stamps(first_ns, min(int(series[e][1][-1]) for e in moving), lookup_hz)
    )
    return series, t_ns


def _direct_link(rows: np.ndarray, link: str, topic: str, stamp: str, notes) -> Trajectory:
    """A chain of one direct link: its own poses, bit for bit (the first of repeated stamps)."""
    rows = rows[np.concatenate([[True], np.diff(rows[:, 0]) > 0])]
    if notes is not None:
        notes.append(f"bag TF {link} ({len(rows)} poses of {topic}, {stamp} stamps)")
    q = rows[:, 4:8]
    t, p = np.ascontiguousarray(rows[:, 0]), np.ascontiguousarray(rows[:, 1:4])  # as _finish's p
    return Trajectory(t, p, q / np.linalg.norm(q, axis=1, keepdims=True))


def _compose(series: dict, steps: list, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The chain's rotations and positions at ``t_ns``: each link interpolated there, composed from
    the parent on (an inverted link transposed)."""
    # interpolate in time since the first stamp: ns differences are exact, epoch seconds are not
    origin = int(t_ns[0])
    since = (t_ns - origin) * 1e-9
    r_total, p_total = (
        np.broadcast_to(np.eye(3), (len(t_ns), 3, 3)).copy(),
        np.zeros((len(t_ns), 3)),
    )
    for a, b, inverted in steps:
        rows, ns, is_static = series[(a, b)]
        if is_static:
            rows, ns = rows[-1:], ns[-1:]
        p_e, q_e = _interp(np.column_stack([(ns - origin) * 1e-9, rows[:, 1:]]), since)
        r_e = geometry.quat_to_rot(q_e / np.linalg.norm(q_e, axis=1, keepdims=True))
        if inverted:
            r_e = r_e.transpose(0, 2, 1)
            p_e = -np.einsum("nab,nb->na", r_e, p_e)
        p_total = p_total + np.einsum("nab,nb->na", r_total, p_e)
        r_total = r_total @ r_e
    return r_total, p_total


def _to_sec(ns: np.ndarray) -> np.ndarray:
    """Stamps (int ns) in seconds as ROS 1's Time.to_sec() gives them: secs + nsecs / 1e9."""
    return (ns // 10**9) + (ns % 10**9) / 1e9


def _through_double_seconds(ns: np.ndarray) -> np.ndarray:
    """Stamps (int ns) after ROS 1's to_sec() and Time.fromSec(): floor the seconds, round the ns."""
    t = _to_sec(ns)
    sec = np.floor(t)
    return sec.astype(np.int64) * 10**9 + np.round((t - sec) * 1e9).astype(np.int64)


def _evo_lookup_stamps(start_ns: int, latest_ns: int, rate: float) -> np.ndarray:
    """evo's TF lookup instants (tf_cache.get_trajectory): from the topic's first stamp, one step of
    1/rate s (a ROS Duration: whole ns, truncated) at a time, up to the chain's latest common time."""
    if latest_ns < start_ns:
        return np.array([latest_ns], np.int64)
    period = 1.0 / rate
    step_ns = int(period) * 10**9 + int((period - int(period)) * 1e9)
    if step_ns <= 0:
        raise EpaError(f"TF lookup rate {rate} Hz is too high (steps under 1 ns)")
    return np.arange(start_ns, latest_ns + 1, step_ns, dtype=np.int64)
