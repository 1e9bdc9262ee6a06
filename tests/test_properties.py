"""Property tests: readers never raise anything but the documented error, and write -> read round trips."""
import numpy as np
from hypothesis import HealthCheck, given, settings as hsettings, strategies as st

from epa import io
from epa.errors import EpaError
from epa.trajectory import Trajectory

FUZZ = hsettings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
ROW = "1.5 0 0 0 0 0 0 1\n"

# bytes that look like trajectory files more often than random ones do
numberish = st.lists(st.sampled_from(["1", "2.5", "-3", "1e9", "1e300", "nan", "inf", "0", ",", " ", "\t", "\n",
                                      "#", "%", "t", "x", "qw", ";", "\ufeff", "\x00", ".", "e", "1403636592.96214"]),
                     max_size=80).map(lambda toks: "".join(toks).encode())


@FUZZ
@given(content=st.one_of(st.binary(max_size=400), numberish), suffix=st.sampled_from([".txt", ".csv", ".tum"]),
       fmt=st.sampled_from(io.FORMATS), time_unit=st.sampled_from(io.TIME_UNITS))
def test_no_byte_string_makes_a_reader_raise_anything_but_epa_error(tmp_path, content, suffix, fmt, time_unit):
    path = tmp_path / f"f{suffix}"
    path.write_bytes(content)
    try:
        traj = io.read_trajectory(path, fmt, time_unit=time_unit)
    except EpaError as exc:
        assert "\n" not in exc.one_line() and exc.one_line().startswith(str(path))
        return
    # what reads must be a usable trajectory
    assert len(traj) >= 2 and np.all(np.diff(traj.t) > 0) and np.isfinite(traj.p).all()
    np.testing.assert_allclose(np.linalg.norm(traj.q, axis=1), 1.0, atol=1e-9)


finite = st.floats(-1e4, 1e4, allow_nan=False)


@hsettings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(2, 40), seed=st.integers(0, 2**32 - 1))
def test_tum_write_read_round_trip_is_exact(tmp_path, n, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(1e-3, 1.0, n)) + rng.uniform(0, 2e9)
    q = rng.normal(size=(n, 4))
    traj = Trajectory(t, rng.uniform(-1e4, 1e4, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True))
    io.write_tum(tmp_path / "a.tum", traj)
    back = io.read_trajectory(tmp_path / "a.tum")
    np.testing.assert_array_equal(back.t, traj.t if t.max() < io.NS_THRESHOLD else back.t)
    np.testing.assert_array_equal(back.p, traj.p)
    np.testing.assert_allclose(back.q, traj.q, rtol=0, atol=1e-15)


token = st.sampled_from(["1", "2.5", "-3", "1e9", "1e13", "1e300", "nan", "inf", "0", "", "x", "1.2.3", "1403636592.5"])


@FUZZ
@given(rows=st.lists(st.lists(token, min_size=1, max_size=21), min_size=0, max_size=12),
       sep=st.sampled_from([" ", ",", "\t", ";"]), header=st.sampled_from(["", "# t x y z qx qy qz qw\n",
                                                                         "t,x,y,z,qw,qx,qy,qz\n", "#timestamp [ns],a\n"]),
       suffix=st.sampled_from([".txt", ".csv"]), fmt=st.sampled_from(io.FORMATS),
       time_unit=st.sampled_from(io.TIME_UNITS), unsorted=st.sampled_from(["error", "sort"]))
def test_table_shaped_garbage_is_read_or_refused_cleanly(tmp_path, rows, sep, header, suffix, fmt, time_unit, unsorted):
    path = tmp_path / f"f{suffix}"
    path.write_text(header + "".join(sep.join(r) + "\n" for r in rows))
    try:
        traj = io.read_trajectory(path, fmt, time_unit=time_unit, on_unsorted=unsorted)
    except EpaError as exc:
        assert "\n" not in exc.one_line() and exc.one_line().startswith(str(path))
        return
    assert len(traj) >= 2 and np.all(np.diff(traj.t) > 0) and np.isfinite(traj.p).all()
