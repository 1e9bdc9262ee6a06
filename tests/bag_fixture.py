"""Writing trajectories as ROS 1 / ROS 2 bags, for the tests (a fixture, not a reader)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from epa.core.trajectory import Trajectory


def write_bag(
    path,
    topics: dict[str, tuple[str, Trajectory]],
    *,
    storage: str = "ros1",
    frames: tuple[str, str] = ("world", "body"),
    extra: dict[str, tuple[str, list]] | None = None,
    compressed: bool = False,
) -> None:
    """Write trajectories as bag topics: ``topics`` maps topic -> (message type, trajectory).
    ``storage``: ``ros1`` (.bag), ``sqlite3`` or ``mcap`` (ROS 2 bag folder). TFMessage topics carry
    ``frames`` (parent, child); a Path topic is one message holding every pose. ``extra`` adds raw
    topics: topic -> (message type, [(record_ns, message)]). ``compressed``: bz2 chunks (ROS 1) or
    zstd chunks (MCAP storage), so that a damaged chunk is a decompressor's error."""
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    ros1 = storage == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.types:  # the Noetic store lacks tf2_msgs
        from rosbags.typesys import get_types_from_msg

        ts.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    T = ts.types
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
        if compressed:
            writer.set_compression(Writer.CompressionFormat.BZ2)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        writer = Writer(
            path,
            version=9,
            storage_plugin=StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3,
        )
        if compressed:
            from rosbags.rosbag2 import CompressionFormat, CompressionMode

            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)

    def header(t, frame):
        sec = int(np.floor(t))
        stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t - sec) * 1e9)))
        return (
            T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
            if ros1
            else T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)
        )

    def pose(p, q):
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
            orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )

    def cov(traj, k):
        if traj.cov_ros is not None:
            return traj.cov_ros[k].reshape(36).astype(float)
        c = np.zeros((6, 6))
        if traj.cov_pos is not None:
            c[:3, :3], c[3:, 3:] = traj.cov_pos[k], traj.cov_rot[k]
        return c.reshape(36)

    def messages(msgtype, traj):
        parent, child = frames
        for k in range(len(traj)):
            t, p, q = traj.t[k], traj.p[k], traj.q[k]
            if msgtype == "geometry_msgs/msg/PoseStamped":
                yield t, T[msgtype](header=header(t, parent), pose=pose(p, q))
            elif msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped":
                pwc = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=pose(p, q), covariance=cov(traj, k)
                )
                yield t, T[msgtype](header=header(t, parent), pose=pwc)
            elif msgtype == "nav_msgs/msg/Odometry":
                pwc = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=pose(p, q), covariance=cov(traj, k)
                )
                tw = T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](
                        linear=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                        angular=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                    ),
                    covariance=np.zeros(36),
                )
                yield (
                    t,
                    T[msgtype](header=header(t, parent), child_frame_id=child, pose=pwc, twist=tw),
                )
            elif msgtype in ("geometry_msgs/msg/TransformStamped", "tf2_msgs/msg/TFMessage"):
                tf = T["geometry_msgs/msg/TransformStamped"](
                    header=header(t, parent),
                    child_frame_id=child,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
                        rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
                    ),
                )
                yield (
                    t,
                    (tf if msgtype.endswith("TransformStamped") else T[msgtype](transforms=[tf])),
                )
        if msgtype == "nav_msgs/msg/Path":
            poses = [
                T["geometry_msgs/msg/PoseStamped"](
                    header=header(traj.t[k], parent), pose=pose(traj.p[k], traj.q[k])
                )
                for k in range(len(traj))
            ]
            yield traj.t[-1], T[msgtype](header=header(traj.t[-1], parent), poses=poses)

    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    with writer:
        for topic, (msgtype, traj) in topics.items():
            conn = writer.add_connection(topic, msgtype, typestore=ts)
            for t, msg in messages(msgtype, traj):
                writer.write(conn, int(round(t * 1e9)), serialize(msg, msgtype))
        for topic, (msgtype, items) in (extra or {}).items():
            conn = writer.add_connection(topic, msgtype, typestore=ts)
            for record_ns, msg in items:
                writer.write(conn, record_ns, serialize(msg, msgtype))
