"""Per-axis errors (metrics.per_axis): known injected errors come back on their axis, the axes add up
to the ATE and the RPE, and the metric reaches metrics.json, ape.csv and its table."""

import numpy as np
import pytest
from conftest import smooth_path

from epa import simulate
from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.metrics import accuracy, per_axis
from epa.workflow import chain, settings


def test_an_injected_offset_and_roll_are_on_their_axes():
    ref = smooth_path()
    roll = geometry.so3_exp(np.array([np.radians(2.0), 0.0, 0.0]))  # a body-frame roll error
    est = Trajectory(ref.t, ref.p + [0.1, -0.2, 0.0], geometry.rot_to_quat(ref.r @ roll))
    e = per_axis.ate_errors(ref, est)
    np.testing.assert_allclose(e[:, :3], np.tile([0.1, -0.2, 0.0], (len(ref), 1)), atol=1e-12)
    np.testing.assert_allclose(e[:, 3:], np.tile([2.0, 0.0, 0.0], (len(ref), 1)), atol=1e-9)


def test_the_axes_add_up_to_the_ate_and_the_rpe():
    ref = smooth_path()
    rng = np.random.default_rng(5)
    noise = geometry.so3_exp(rng.normal(0, 0.01, (len(ref), 3)))
    est = Trajectory(
        ref.t, ref.p + rng.normal(0, 0.05, ref.p.shape), geometry.rot_to_quat(ref.r @ noise)
    )
    e = per_axis.ate_errors(ref, est)
    trans, _ = accuracy.ape(ref, est)
    np.testing.assert_allclose(np.linalg.norm(e[:, :3], axis=1), trans, rtol=1e-12)
    i, j = accuracy.segment_pairs(geometry.path_distances(ref.p), 8.0)
    rel = per_axis.rpe_errors(ref, est, i, j)
    rot_deg, trans_m = geometry.relative_errors(
        geometry.pose_discrepancy(ref.q, est.q), ref.p, est.p, i, j
    )
    np.testing.assert_allclose(np.linalg.norm(rel[:, :3], axis=1), trans_m, rtol=1e-9)
    # small rotations: the Euler angles' norm is the rotation angle to first order
    np.testing.assert_allclose(np.linalg.norm(rel[:, 3:], axis=1), rot_deg, rtol=0.02)


@pytest.mark.parametrize("enabled", [False, True])
def test_the_metric_is_in_metrics_json_and_ape_csv_only_when_asked(tmp_path, enabled):
    simulate.simulate(tmp_path / "sim")
    cfg = settings.resolve(
        {
            "truth_dir": str(tmp_path),
            "algorithms_dir": str(tmp_path),
            "metrics": {"per_axis": enabled},
            "efficiency": {"sensor_rate_hz": 20},
        }
    )
    est = tmp_path / "sim/algorithms/vio_body/handheld_office/run1.txt"
    out = tmp_path / "o"
    m = chain.run_case(
        tmp_path / "sim/truth/handheld_office.txt", est, out, cfg, write_arrays=True
    )["metrics"]
    header = (out / "06_metrics/ape.csv").read_text().splitlines()[0].split(",")
    assert ("per_axis" in m) == enabled and ("err_roll_deg" in header) == enabled
    if enabled:
        assert list(m).index("per_axis") == list(m).index("ate_2d") + 1
        rmse = [m["per_axis"]["ate"][f"{a}_m"]["rmse"] for a in "xyz"]
        assert np.hypot.reduce(rmse) == pytest.approx(m["ate"]["trans_m"]["rmse"], rel=1e-12)
        assert set(m["per_axis"]["rpe_distance"]) == set(m["rpe_distance"])
