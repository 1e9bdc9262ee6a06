"""ROS bags: every supported message type in ROS 1, ROS 2 sqlite3 and MCAP bags read back exactly;
TF chains composed; evo 1.38.1's reading of the shared bags reproduced; damage is one line."""

import bag_fixture
import numpy as np
import pytest

from epa import readers
from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.readers import bags

TYPES = [
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped",
    "nav_msgs/msg/Odometry",
    "nav_msgs/msg/Path",
    "tf2_msgs/msg/TFMessage",
]
STORAGES = {"ros1": "b.bag", "sqlite3": "b2", "mcap": "b3"}


def known(n=60, seed=0, cov=True):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    a = rng.normal(size=(n, 6, 6))
    t = 1_700_000_000 + np.round(np.cumsum(rng.uniform(0.01, 0.2, n)), 9)
    return Trajectory(
        t,
        rng.normal(0, 10, (n, 3)),
        q / np.linalg.norm(q, axis=1, keepdims=True),
        cov_ros=a @ a.transpose(0, 2, 1) if cov else None,
    )


@pytest.mark.parametrize("storage", STORAGES)
def test_every_message_type_reads_back_exactly(tmp_path, storage):
    traj = known()
    path = tmp_path / STORAGES[storage]
    bag_fixture.write_bag(path, {f"/t{k}": (m, traj) for k, m in enumerate(TYPES)}, storage=storage)
    assert bags.is_bag(path)
    listed = {i.topic: (i.msgtype, i.count) for i in bags.topics(path)}
    assert listed["/t0"] == (TYPES[0], 60) and listed["/t4"] == (TYPES[4], 1)
    for k, msgtype in enumerate(TYPES):
        back = bags.read_bag(path, f"/t{k}", frames=("world", "body") if "TF" in msgtype else None)
        np.testing.assert_array_equal(back.t, traj.t)  # sec + nanosec, as evo reads them
        np.testing.assert_array_equal(back.p, traj.p)
        np.testing.assert_allclose(back.q, traj.q, rtol=0, atol=1e-15)
        # arrays of their own, not views of the decoded messages (kept for the run)
        assert all(a.flags.c_contiguous and a.base is None for a in (back.t, back.p, back.q))
        if msgtype.endswith(("PoseWithCovarianceStamped", "Odometry")):
            np.testing.assert_array_equal(back.cov_ros, traj.cov_ros)  # 6x6, ROS order
            np.testing.assert_array_equal(back.cov_pos, traj.cov_ros[:, :3, :3])
            # ROS's orientation covariance is about the parent's axes; epica's is the local error
            r = traj.r
            np.testing.assert_allclose(
                back.cov_rot,
                np.einsum("nba,nbc,ncd->nad", r, traj.cov_ros[:, 3:, 3:], r),
                rtol=1e-12,
                atol=1e-12,
            )
        else:
            assert back.cov_ros is None


def test_record_time_on_request(tmp_path):
    traj = known(cov=False)
    bag_fixture.write_bag(tmp_path / "b.bag", {"/p": ("geometry_msgs/msg/PoseStamped", traj)})
    record = bags.read_bag(tmp_path / "b.bag", "/p", stamp="record")
    # written at the header stamp (ns)
    np.testing.assert_allclose(record.t, traj.t, rtol=0, atol=1e-6)


def test_tf_chains_compose_through_tf_static(tmp_path):
    rng = np.random.default_rng(3)
    n = 40
    t = 100 + np.arange(n) * 0.1
    r1, r2 = (
        geometry.so3_exp(rng.normal(0, 0.5, (n, 3))),
        geometry.so3_exp(rng.normal(0, 0.5, (n, 3))),
    )
    p1, p2 = rng.normal(0, 3, (n, 3)), rng.normal(0, 3, (n, 3))
    rc, pc = geometry.so3_exp(np.array([0.2, -0.4, 1.0])), np.array([0.1, 0.2, -0.3])
    edges = {
        ("world", "odom"): Trajectory.from_rp(t, r1, p1),
        ("odom", "body"): Trajectory.from_rp(t, r2, p2),
    }
    _write_tf(tmp_path / "tf.bag", edges, static={("body", "cam"): (rc, pc)})
    got = bags.read_bag(tmp_path / "tf.bag", "/tf", frames=("world", "cam"))
    r_want = r1 @ r2 @ rc
    p_want = p1 + np.einsum("nab,nb->na", r1, p2 + np.einsum("nab,b->na", r2, pc))
    np.testing.assert_allclose(got.t, t)
    np.testing.assert_allclose(got.r, r_want, atol=1e-12)
    np.testing.assert_allclose(got.p, p_want, atol=1e-12)
    # the inverse chain: cam -> world
    inv = bags.read_bag(tmp_path / "tf.bag", "/tf", frames=("cam", "world"))
    np.testing.assert_allclose(inv.r, r_want.transpose(0, 2, 1), atol=1e-12)
    np.testing.assert_allclose(inv.p, -np.einsum("nba,nb->na", r_want, p_want), atol=1e-10)
    with pytest.raises(
        EpaError,
        match=r"tf.bag topic /tf: unknown frame 'base'; the TF frames are body, cam, odom, world",
    ):
        bags.read_bag(tmp_path / "tf.bag", "/tf", frames=("world", "base"))


def _write_tf(path, edges: dict, static: dict):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    T = ts.types

    def tf(t, parent, child, r, p):
        q = geometry.rot_to_quat(r)
        sec = int(np.floor(t))
        return T["geometry_msgs/msg/TransformStamped"](
            header=T["std_msgs/msg/Header"](
                seq=0,
                stamp=T["builtin_interfaces/msg/Time"](
                    sec=sec, nanosec=int(round((t - sec) * 1e9))
                ),
                frame_id=parent,
            ),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
                rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
            ),
        )

    msgtype = "tf2_msgs/msg/TFMessage"
    with Writer(path) as w:
        dyn = w.add_connection("/tf", msgtype, typestore=ts)
        stat = w.add_connection("/tf_static", msgtype, typestore=ts)
        w.write(
            stat,
            1,
            ts.serialize_ros1(
                T[msgtype](transforms=[tf(0.0, a, b, r, p) for (a, b), (r, p) in static.items()]),
                msgtype,
            ),
        )
        first = next(iter(edges.values()))
        for k, t in enumerate(first.t):
            msg = T[msgtype](
                transforms=[tf(t, a, b, e.r[k], e.p[k]) for (a, b), e in edges.items()]
            )
            w.write(dyn, int(t * 1e9), ts.serialize_ros1(msg, msgtype))


# ----------------------------------------------------------------------------- the shared bags and evo
def _evo_read(path, topic):
    pytest.importorskip("evo")
    from evo.tools import file_interface
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    reader = Reader1(path) if str(path).endswith(".bag") else Reader2(path)
    with reader:
        return file_interface.read_bag_trajectory(reader, topic)


@pytest.mark.parametrize("topic", ["/amcl_pose", "/odom"])
def test_mcap_topics_equal_evos_reading(data, topic):
    path = data / "MichaelGrupp_evo/test/data/nav2_turtlebot.mcap"
    ours = bags.read_bag(path, topic)
    evo = _evo_read(path, topic)
    np.testing.assert_allclose(ours.t, evo.timestamps, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours.p, evo.positions_xyz, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        ours.q, evo.orientations_quat_wxyz[:, [1, 2, 3, 0]], rtol=0, atol=1e-9
    )
    assert len(ours) == {"/amcl_pose": 135, "/odom": 2639}[topic]
    # PoseWithCovarianceStamped keeps its 6x6 (SOURCES.md: sigma about 0.15-0.2 m)
    if topic == "/amcl_pose":
        sigma = np.sqrt(ours.cov_pos[:, 0, 0])
        assert ours.cov_ros.shape == (135, 6, 6) and abs(sigma[0] - 0.16803) < 1e-5


def test_tf_example_bags_ros1_and_ros2_agree_and_match_sources_md(data):
    folder = data / "MichaelGrupp_evo/test/data"
    one = bags.read_bag(folder / "tf_example.bag", "/tf", frames=("odom", "base_footprint"))
    two = bags.read_bag(folder / "tf_example", "/tf", frames=("odom", "base_footprint"))
    np.testing.assert_array_equal(one.t, two.t)
    np.testing.assert_array_equal(one.p, two.p)
    assert (
        len(one) == 517
        and abs((one.t[-1] - one.t[0]) - 51.6) < 0.05
        and abs(one.length() - 4.0) < 0.01
    )
    # through /tf_static: base_link is base_footprint moved by the static transform
    link = bags.read_bag(folder / "tf_example.bag", "/tf", frames=("odom", "base_link"))
    static = np.median(np.einsum("nba,nb->na", one.r, link.p - one.p), axis=0)
    np.testing.assert_allclose(
        np.einsum("nba,nb->na", one.r, link.p - one.p), np.tile(static, (517, 1)), atol=1e-12
    )


# ----------------------------------------------------------------------------- sources and settings
def test_a_topic_on_a_text_file_is_refused(tmp_path):
    (tmp_path / "a.txt").write_text("1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n")
    with pytest.raises(EpaError, match="a topic is set for this source but it is not a bag"):
        readers.read(tmp_path / "a.txt", {"topic": "/x"})


def test_per_source_settings_override_the_load_section():
    from epa.workflow import settings

    cfg = settings.resolve(
        {
            "truth_dir": "t",
            "algorithms_dir": "a",
            "load": {"unsorted": "sort"},
            "sources": {
                "reference": {"topic": "/gt"},
                "datasets": {"V102": {"topic": "/vicon"}},
                "algorithms": {"okvis": {"topic": "/okvis/odom", "stamp": "record"}},
            },
        }
    )
    assert readers.options(cfg, "reference", dataset="MH01")["topic"] == "/gt"
    assert readers.options(cfg, "reference", dataset="V102")["topic"] == "/vicon"
    est = readers.options(cfg, "estimate", algorithm="okvis")
    assert est["topic"] == "/okvis/odom" and est["stamp"] == "record" and est["unsorted"] == "sort"
    assert readers.options(cfg, "estimate", algorithm="vins")["topic"] is None
    with pytest.raises(
        EpaError, match="sources.algorithms.okvis: Additional properties are not allowed"
    ):
        settings.resolve(
            {
                "truth_dir": "t",
                "algorithms_dir": "a",
                "sources": {"algorithms": {"okvis": {"topik": "/x"}}},
            }
        )


@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_the_all_at_once_decoder_equals_message_by_message(tmp_path, storage, monkeypatch):
    traj = known(200, seed=5)
    path = tmp_path / STORAGES[storage]
    kinds = TYPES[:4]
    bag_fixture.write_bag(path, {f"/t{k}": (m, traj) for k, m in enumerate(kinds)}, storage=storage)
    fast = [bags.read_bag(path, f"/t{k}") for k in range(len(kinds))]
    monkeypatch.setattr(bags, "_decode_all", lambda *a, **k: None)
    for k, f in enumerate(fast):
        slow = bags.read_bag(path, f"/t{k}")
        for name in ("t", "p", "q", "cov_ros"):
            np.testing.assert_array_equal(getattr(f, name), getattr(slow, name))
