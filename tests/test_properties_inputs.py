"""Property tests for the other inputs: bags (damaged chunks, truncated records, random bytes in a
valid container), timing files and covariance columns. Whatever the bytes, a reader returns a usable
result or raises the one-line EpaError naming the source; never another exception, never a numpy
warning, never inf or nan as a result."""

import shutil
import tempfile
import warnings
from functools import cache
from pathlib import Path

import bag_fixture
import catalogue
import numpy as np
from hypothesis import HealthCheck, example, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st

from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.metrics import efficiency
from epa.readers import bags, text, timing

SOME = hsettings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
N = 120  # poses per topic: several chunks' worth of records, small enough to write once


@cache
def _bag(kind: str) -> Path:
    """A valid bag written once per kind: ros1 / ros1-bz2 (.bag), mcap / mcap-zstd (ROS 2 folder)."""
    folder = Path(tempfile.mkdtemp(prefix="epa-bag-"))
    storage = "ros1" if kind.startswith("ros1") else "mcap"
    path = folder / ("b.bag" if storage == "ros1" else "b")
    good = Trajectory(catalogue.T[:N], catalogue.P[:N], catalogue.Q[:N])
    c = np.tile(np.eye(3) * 0.01, (N, 1, 1))
    bag_fixture.write_bag(
        path,
        {
            "/pose": ("geometry_msgs/msg/PoseStamped", good),
            "/odom": (
                "nav_msgs/msg/Odometry",
                Trajectory(good.t, good.p, good.q, cov_pos=c, cov_rot=c),
            ),
            "/tf": ("tf2_msgs/msg/TFMessage", good),
        },
        storage=storage,
        compressed=kind.endswith(("bz2", "zstd")),
    )
    return path


def _data_file(path: Path) -> Path:
    return next(path.glob("*.mcap")) if path.is_dir() else path


def _damaged_copy(tmp: Path, kind: str, damage) -> Path:
    src = _bag(kind)
    dst = tmp / src.name
    if dst.exists():
        shutil.rmtree(dst) if dst.is_dir() else dst.unlink()
    (shutil.copytree if src.is_dir() else shutil.copy)(src, dst)
    f = _data_file(dst)
    f.write_bytes(damage(f.read_bytes()))
    return dst


def _read_cleanly(path: Path, call) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not even a numpy warning
        try:
            result = call()
        except EpaError as exc:
            line = exc.one_line()
            assert "\n" not in line and str(path) in line, line
            return
    if isinstance(result, Trajectory):
        assert np.isfinite(result.t).all() and np.isfinite(result.p).all()
        np.testing.assert_allclose(np.linalg.norm(result.q, axis=1), 1.0, atol=1e-9)


READS = (
    lambda p: bags.topics(p),
    lambda p: bags.read_bag(p, "/pose"),
    lambda p: bags.read_bag(p, "/odom"),
    lambda p: bags.read_bag(p, "/tf", frames=("world", "body")),
    lambda p: bags.read_bag(p, "/tf", frames=("world", "body"), tf_rate=10.0),
)
KINDS = st.sampled_from(["ros1", "ros1-bz2", "mcap", "mcap-zstd"])


@SOME
@given(
    kind=KINDS,
    at=st.floats(0, 1, exclude_max=True),
    length=st.integers(1, 300),
    xor=st.integers(1, 255),
    read=st.sampled_from(range(len(READS))),
)
def test_a_damaged_chunk_is_read_or_refused_in_one_line(tmp_path, kind, at, length, xor, read):
    def damage(data: bytes) -> bytes:
        b = bytearray(data)
        k = int(at * len(b))
        for j in range(k, min(len(b), k + length)):
            b[j] ^= xor
        return bytes(b)

    path = _damaged_copy(tmp_path, kind, damage)
    _read_cleanly(path, lambda: READS[read](path))


@SOME
@given(kind=KINDS, at=st.floats(0, 1, exclude_max=True), read=st.sampled_from(range(len(READS))))
def test_a_truncated_bag_is_read_or_refused_in_one_line(tmp_path, kind, at, read):
    path = _damaged_copy(tmp_path, kind, lambda data: data[: int(at * len(data))])
    _read_cleanly(path, lambda: READS[read](path))


@SOME
@given(
    kind=KINDS,
    at=st.floats(0, 1, exclude_max=True),
    junk=st.binary(min_size=1, max_size=200),
    replace=st.booleans(),
    read=st.sampled_from(range(len(READS))),
)
def test_random_bytes_in_a_valid_container_are_read_or_refused(
    tmp_path, kind, at, junk, replace, read
):
    def damage(data: bytes) -> bytes:
        k = int(at * len(data))
        return data[:k] + junk + data[k + (len(junk) if replace else 0) :]

    path = _damaged_copy(tmp_path, kind, damage)
    _read_cleanly(path, lambda: READS[read](path))


# ----------------------------------------------------------------------------- timing files
timing_token = st.sampled_from(
    ["1403636580.0", "1403636580.05", "12", "0", "-3", "1e5", "1e300", "nan", "inf", "x", ","]
)


@hsettings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    rows=st.lists(st.lists(timing_token, min_size=1, max_size=4), max_size=10),
    header=st.sampled_from(["", "timestamp (sec),tracking,total\n", "# t ms\n"]),
    sep=st.sampled_from([" ", ","]),
)
def test_a_timing_file_is_read_or_refused_in_one_line(tmp_path, rows, header, sep):
    path = tmp_path / "run_timing.txt"
    path.write_text(header + "".join(sep.join(r) + "\n" for r in rows))
    try:
        t, ms, _ = timing.read_timing(path)
    except EpaError as exc:
        assert "\n" not in exc.one_line() and exc.one_line().startswith(str(path))
        return
    assert np.isfinite(t).all() and np.isfinite(ms).all() and (ms >= 0).all()


@hsettings(max_examples=150, deadline=None)
@given(
    ms=st.lists(st.floats(0, 1e12, allow_nan=False), min_size=1, max_size=30),
    rate=st.floats(0.1, 1000),
    err=st.floats(0, 1e3),
)
# a weight below the overflowing frame's bound whose square times the error's overflows (M2UD)
@example(ms=[591.0], rate=593.0, err=228.0)
def test_ea_drift_is_a_finite_number_or_empty_with_a_reason(ms, rate, err):
    n = len(ms)
    t = 100 + np.arange(n) * 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        record, _ = efficiency.evaluate(t, t, np.full(n, err), 10.0, (t, np.array(ms)), rate, 0.01)
    for key in ("ea_drift", "ea_drift_seed", "ea_drift_m2ud"):
        v = record[key]
        assert v is None or np.isfinite(v), (key, v)
    assert (record["ea_drift"] is None) == ("ea_drift_reason" in record)


# ----------------------------------------------------------------------------- covariance columns
cov_value = st.one_of(
    st.floats(-1e3, 1e3, allow_nan=False), st.sampled_from([0.0, 1e300, -1e-300, float("nan")])
)


@hsettings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(covs=st.lists(st.lists(cov_value, min_size=12, max_size=12), min_size=2, max_size=8))
def test_covariance_columns_are_read_or_refused_in_one_line(tmp_path, covs):
    n = len(covs)
    rows = [
        [f"{100 + 0.1 * k:.3f}", f"{k}", "0", "0", "0", "0", "0", "1", *map(repr, c)]
        for k, c in enumerate(covs)
    ]
    path = tmp_path / "est.txt"
    path.write_text("".join(" ".join(r) + "\n" for r in rows))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            traj = text.read_trajectory(path, "openvins")
        except EpaError as exc:
            assert "\n" not in exc.one_line() and exc.one_line().startswith(str(path))
            return
    assert len(traj) == n and traj.cov_rot is not None
    for c in (traj.cov_rot, traj.cov_pos):
        assert np.isfinite(c).all() and np.array_equal(c, c.transpose(0, 2, 1))


@hsettings(
    max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(seed=st.integers(0, 2**32 - 1), covariance=st.booleans())
def test_traj_export_writes_covariance_only_when_asked(tmp_path, seed, covariance):
    from epa.artifacts import files
    from epa.cli import main as cli

    rng = np.random.default_rng(seed)
    n = 5
    a, b = rng.normal(size=(n, 3, 3)), rng.normal(size=(n, 3, 3))
    q = rng.normal(size=(n, 4))
    traj = Trajectory(
        100 + np.arange(n) * 0.1,
        rng.normal(size=(n, 3)),
        q / np.linalg.norm(q, axis=1, keepdims=True),
        cov_rot=a @ a.transpose(0, 2, 1) * 1e-4,
        cov_pos=b @ b.transpose(0, 2, 1) * 1e-2,
    )
    files.write_trajectory(tmp_path / "in.txt", traj, "openvins")
    out = tmp_path / "out.tum"
    assert (
        cli.main(
            ["traj", str(tmp_path / "in.txt"), "--export", str(out)]
            + (["--covariance"] if covariance else [])
        )
        == 0
    )
    widths = {
        len(line.split()) for line in out.read_text().splitlines() if not line.startswith("#")
    }
    assert widths == {20 if covariance else 8}
    back = text.read_trajectory(out)
    np.testing.assert_array_equal(back.p, traj.p)
    if covariance:
        np.testing.assert_allclose(back.cov_rot, traj.cov_rot, rtol=1e-15)
