"""Scale that hides a failure (metrics.sim3_check): with a Sim3 alignment, the scale and the ATE of an
SE3 fit of the same poses beside the Sim3 ATE, and a warning when the scale may hide a failure, in
metrics.json, the log, summary.csv's notes, its table and the case report. Injected scales come back,
the SE3 ATE is the hand-derived one. Under an alignment without scale the mirror check: a Sim3 fit
beside the case's ATE, a warning where a scale far from 1 removes most of the error."""

import json

import numpy as np
import pytest
from conftest import smooth_path

from epa.artifacts import files
from epa.cli import main as cli
from epa.core import geometry
from epa.core.trajectory import Trajectory
from epa.metrics import sim3_check
from epa.outputs import tables
from epa.steps import align as alignment
from epa.workflow import chain, settings

R0 = geometry.so3_exp(np.array([0.2, -0.1, 1.0]))  # the estimate's own world frame


def _estimate(ref, scale, noise=0.0, seed=3):
    """The reference seen by an estimator of that scale, in another world frame, with noise (m)."""
    rng = np.random.default_rng(seed)
    p = scale * (ref.p + rng.normal(0, noise, ref.p.shape)) @ R0.T + [5.0, -2.0, 1.0]
    return Trajectory(ref.t, p, geometry.rot_to_quat(R0 @ ref.r))


def _fit_rmse(src, dst, with_scale):
    """Test oracle: the RMSE after the least-squares (similarity or rigid) fit of src onto dst,
    written out from Umeyama's paper."""
    ms, md = src.mean(0), dst.mean(0)
    xs, xd = src - ms, dst - md
    u, d, vt = np.linalg.svd(xd.T @ xs / len(src))
    e = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ e @ vt
    s = np.trace(np.diag(d) @ e) / np.mean(np.sum(xs**2, 1)) if with_scale else 1.0
    return np.sqrt(np.mean(np.sum((xd - s * xs @ r.T) ** 2, 1))), s


CFG = {
    "max_log_scale": 0.05,
    "max_ate_ratio": 10.0,
    "min_error_removed": 0.5,
    "max_residual_path_pct": 1.0,
    "enabled": True,
}


def _check(ref, est, metric_scale=None, first_n=-1):
    """The record, as the metrics stage computes it after a Sim3 Step 3."""
    fit = alignment.fit(ref, est, method="sim3", first_n=first_n)
    info = {"method": "sim3", "first_n": first_n, "fallback": False, **fit.to_dict()}
    source = {} if metric_scale is None else {"metric_scale": metric_scale}
    cfg = {"metrics": {"sim3_check": CFG}, "align": {"method": "sim3"}}
    record, arrays, notes = sim3_check.compute(
        ref, fit.apply(est), cfg, transform=info, estimate_source=source
    )
    assert arrays == {} and "; ".join(notes) == (record["warning"] or "")
    return record


def test_an_injected_scale_of_a_half_comes_back_with_the_hand_derived_se3_ate():
    """An estimate at half scale, exactly: the Sim3 fit's scale is 2 and its ATE 0; the SE3 fit of
    0.5 x onto x is the identity rotation and the centroids' offset, leaving 0.5 (x - mean x):
    its RMSE is half the path's RMS distance from its centroid."""
    ref = smooth_path()
    record = _check(ref, _estimate(ref, 0.5), metric_scale=True)
    assert record["scale"] == pytest.approx(2.0, rel=1e-12)
    assert record["log_scale"] == pytest.approx(np.log(2.0), rel=1e-12)
    spread = np.sqrt(np.mean(np.sum((ref.p - ref.p.mean(0)) ** 2, 1)))
    assert record["ate_se3"]["trans_m"]["rmse"] == pytest.approx(0.5 * spread, rel=1e-12)
    assert record["ate_se3"]["rot_deg"]["rmse"] < 1e-9  # the rotation fits exactly
    assert record["ate_ratio"] > 1e9  # the Sim3 ATE is rounding only
    assert record["warning"].startswith("Sim3 scale 2 for an algorithm declared metric")
    assert "hides most of the error" in record["warning"]


@pytest.mark.parametrize(
    "scale, declared, warns",
    [
        # 8 % too large, 5 cm noise: |ln s| = 0.077 > 0.05, SE3/Sim3 = 3.6 < 10
        (1.08, True, ["scale"]),
        (1.08, None, []),
        (1.08, False, []),
        # half scale, 1 cm noise: SE3/Sim3 = 56
        (0.5, True, ["scale", "ratio"]),
        (0.5, None, ["ratio"]),
        (0.5, False, []),  # declared not metric: its scale is arbitrary
        (1.0, True, []),
    ],
)
def test_each_check_fires_only_where_it_applies(scale, declared, warns):
    ref = smooth_path()
    noise = 0.05 if scale == 1.08 else 0.01
    est = _estimate(ref, scale, noise)
    record = _check(ref, est, declared)
    sim3_rmse, s = _fit_rmse(est.p, ref.p, True)
    se3_rmse, _ = _fit_rmse(est.p, ref.p, False)
    assert record["scale"] == pytest.approx(s, rel=1e-12)
    assert record["ate_se3"]["trans_m"]["rmse"] == pytest.approx(se3_rmse, rel=1e-9)
    assert record["ate_ratio"] == pytest.approx(se3_rmse / sim3_rmse, rel=1e-9)
    assert record["metric_scale"] == declared
    got = []
    if "declared metric" in (record["warning"] or ""):
        got.append("scale")
    if "hides most of the error" in (record["warning"] or ""):
        got.append("ratio")
    assert got == warns, record
    if "ratio" in warns and declared is None:
        assert "declare metric_scale: false if its scale is arbitrary" in record["warning"]


def test_the_se3_fit_uses_the_same_first_poses_as_the_sim3_fit():
    ref = smooth_path()
    est = _estimate(ref, 0.7, 0.02)
    record = _check(ref, est, first_n=100)
    # the oracle: the SE3 fit of the first 100 poses, applied to all
    src, dst = est.p[:100], ref.p[:100]
    ms, md = src.mean(0), dst.mean(0)
    u, _, vt = np.linalg.svd((dst - md).T @ (src - ms))
    r = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    err = ref.p - ((est.p - ms) @ r.T + md)
    want = np.sqrt(np.mean(np.sum(err**2, 1)))
    assert record["ate_se3"]["trans_m"]["rmse"] == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize(
    "scale, metric_scale, warns",
    [(5.0, None, True), (1.02, None, False), (5.0, False, False), (1.3, True, True)],
)
def test_under_se3_a_sim3_fit_beside_finds_the_injected_scale(scale, metric_scale, warns):
    """An estimate at an arbitrary scale aligned SE3 (as an undeclared monocular one is): the Sim3
    fit beside it finds 1/scale and the hand-derived Sim3 RMSE; it warns where the scale is beyond
    max_log_scale and the fit removes more than half the error, unless declared not metric."""
    ref = smooth_path()
    est = _estimate(ref, scale, 0.01)
    fit = alignment.fit(ref, est, method="se3")
    info = {"method": "se3", "first_n": -1, "fallback": False, **fit.to_dict()}
    aligned = fit.apply(est)
    source = {} if metric_scale is None else {"metric_scale": metric_scale}
    cfg = {"metrics": {"sim3_check": CFG}}
    record, _, notes = sim3_check.compute(ref, aligned, cfg, transform=info, estimate_source=source)
    want_rmse, want_s = _fit_rmse(aligned.p, ref.p, with_scale=True)
    se3_rmse = np.sqrt(np.mean(np.sum((aligned.p - ref.p) ** 2, 1)))
    assert record["fitted"] == "se3" and record["scale"] == pytest.approx(want_s, rel=1e-9)
    assert record["scale"] == pytest.approx(1 / scale, rel=2e-3)  # the injected one, inverted
    assert record["ate_sim3_rmse_m"] == pytest.approx(want_rmse, rel=1e-9)
    assert record["ate_rmse_m"] == pytest.approx(se3_rmse, rel=1e-12)
    assert record["error_removed"] == pytest.approx(1 - want_rmse / se3_rmse, rel=1e-9)
    assert bool(notes) is warns and (record["warning"] is not None) is warns
    if warns and metric_scale is None:
        assert "metric_scale: false" in record["warning"]
    assert record["evaluated_scale"] is None  # nothing fitted a scale for this evaluation


@pytest.mark.parametrize("rows", [False, True])
def test_an_estimate_standing_still_has_no_sim3_fit_beside_it(rows):
    """Under SE3 an estimate whose positions are all one point has no Sim3 fit (its extent is
    taken on pair_rows' position rows where the metrics stage gives them, else on its positions);
    one that moves along one axis only has one."""
    ref = smooth_path()
    info = {"method": "se3", "first_n": -1}
    cfg = {"metrics": {"sim3_check": CFG}}
    still = Trajectory(ref.t, np.broadcast_to(ref.p[5], ref.p.shape).copy(), ref.q)
    along = still.p.copy()
    along[:, 1] += np.linspace(0.0, 1.0, len(ref))
    for p, available in ((still.p, False), (along, True)):
        est = Trajectory(ref.t, p, ref.q)
        given = geometry.pair_rows(None, ref.p, est.p, q=(ref.q, est.q)) if rows else None
        record, _, _ = sim3_check.compute(
            ref, est, cfg, transform=info, estimate_source={}, pair_rows=given
        )
        assert record["available"] is available
        if not available:
            assert record["reason"] == "no Sim3 fit: the estimate does not move"


def test_the_scale_evaluated_with_is_step_2s_times_step_3s():
    calib = {"plan": {"apply_extrinsic": True}, "extrinsic": {"scale": 5.0, "scale_std": 0.01}}
    got = sim3_check.estimate_scale({"method": "sim3", "scale": 1.1}, calib)
    assert got == {
        "value": pytest.approx(5.5),
        "std": pytest.approx(0.011),
        "fitted_by": "step2+step3",
    }
    unapplied = {"plan": {"apply_extrinsic": False}, "extrinsic": {"scale": 5.0}}
    assert sim3_check.estimate_scale({"method": "sim3", "scale": 2.0}, unapplied) == {
        "value": 2.0,
        "std": None,
        "fitted_by": "step3",
    }
    assert sim3_check.estimate_scale({"method": "se3"}, unapplied) is None


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """Two algorithms on one dataset, Sim3, run by Snakemake: `stereo` declared metric, its estimate
    at 0.5 scale (a failure the scale hides); `mono` undeclared, 1.02 scale (healthy)."""
    from test_workflow import smk

    root = tmp_path_factory.mktemp("sim3")
    ref = smooth_path()
    files.write_trajectory(root / "truth/office.txt", ref, "tum")
    for alg, scale in (("stereo", 0.5), ("mono", 1.02)):
        files.write_trajectory(
            root / f"algs/{alg}/office/run1.txt", _estimate(ref, scale, 0.01), "tum"
        )
    (root / "cfg.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\nalign: {method: sim3}\n"
        "sync: {estimate_offset: false}\ncalibrate: {enabled: false}\n"
        "sources: {algorithms: {stereo: {metric_scale: true}}}\n"
    )
    smk(root)
    return root / "results"


def test_the_warning_reaches_metrics_json_the_log_summary_the_table_and_the_report(grid):
    out = grid
    case = out / "cases/stereo/office/run1"
    m = json.loads((case / "06_metrics/metrics.json").read_text())
    assert list(m).index("sim3_check") == list(m).index("ate") + 1
    check = m["sim3_check"]
    assert check["scale"] == m["alignment"]["scale"] == pytest.approx(2.0, rel=1e-2)
    assert check["metric_scale"] is True and check["warning"].startswith("Sim3 scale 2")
    assert "; ".join(n for n in m["notes"] if "Sim3" in n) == check["warning"]
    log = "\n".join(p.read_text() for p in out.rglob("*.log"))
    assert "Sim3 scale 2" in log and "hides most of the error" in log
    # summary.csv: the warning in the notes column of that case only
    rows = (out / "summary.csv").read_text().splitlines()
    stereo = next(r for r in rows if r.startswith("stereo,"))
    mono = next(r for r in rows if r.startswith("mono,"))
    assert "Sim3 scale 2" in stereo and "Sim3 scale" not in mono
    # its table: scale / SE3 ATE per dataset, the algorithm with a warning noted
    tex = (out / "tables/sim3_check.tex").read_text()
    assert "stereo (scale warning: 1 of 1 runs) & " in tex
    mono_m = json.loads((out / "cases/mono/office/run1/06_metrics/metrics.json").read_text())
    mono_check = mono_m["sim3_check"]
    assert mono_check["warning"] is None and mono_check["metric_scale"] is None
    scale, se3 = mono_check["scale"], mono_check["ate_se3"]["trans_m"]["rmse"]
    assert f"mono & {scale:.3f} / {se3:.3f} & {scale:.3f} / {se3:.3f} \\\\" in tex
    assert "SIM3 SCALE" in (out / "error_comparison.txt").read_text()
    # the case report: the warning under the lead, the SE3 ATE beside Step 3, a flag
    report = (case / "10_report/report_en.md").read_text()
    assert f"**Warning**: sim3_check: {check['warning']}" in report
    assert "An SE3 fit of the same matched poses gives an ATE RMSE of" in report
    assert "**警告**: sim3_check:" in (case / "10_report/report_zh.md").read_text()
    flags = json.loads((case / "10_report/report.json").read_text())["flags"]
    assert flags == [f"sim3_check: {check['warning']}"]
    assert (
        json.loads((out / "cases/mono/office/run1/10_report/report.json").read_text())["flags"]
        == []
    )


def test_every_case_is_checked_unless_turned_off(tmp_path):
    ref = smooth_path()
    files.write_trajectory(tmp_path / "ref.txt", ref, "tum")
    files.write_trajectory(tmp_path / "est.txt", _estimate(ref, 0.5, 0.01), "tum")
    base = {"truth_dir": ".", "algorithms_dir": ".", "sync": {"estimate_offset": False}}
    off = {"metrics": {"sim3_check": {"enabled": False}}, "align": {"method": "sim3"}}
    cfg = settings.resolve({**base, "calibrate": {"enabled": False}, **off})
    m = chain.run_case(tmp_path / "ref.txt", tmp_path / "est.txt", tmp_path / "o", cfg)
    assert "sim3_check" not in m["metrics"] and "sim3_check" not in tables.table_names(cfg)
    cfg = settings.resolve({**base, "calibrate": {"enabled": False}})
    m = chain.run_case(tmp_path / "ref.txt", tmp_path / "est.txt", tmp_path / "o", cfg)
    check = m["metrics"]["sim3_check"]
    assert check["fitted"] == "se3" and check["scale"] == pytest.approx(2.0, rel=1e-2)
    assert "metric_scale: false" in check["warning"]
    assert "sim3_check" in tables.table_names(cfg)


@pytest.mark.parametrize(
    "config, says",
    [
        ("sources: {reference: {metric_scale: true}}", "sources.reference.metric_scale: "),
        ("sources: {datasets: {d: {metric_scale: false}}}", "sources.datasets.d.metric_scale: "),
        ("metrics: {sim3_check: {max_ate_ratio: 1}}", "metrics.sim3_check.max_ate_ratio: "),
        ("metrics: {sim3_check: {max_log_scale: 0}}", "metrics.sim3_check.max_log_scale: "),
        ("sources: {algorithms: {a: {metric_scale: yes please}}}", "metric_scale: "),
    ],
)
def test_a_bad_setting_is_one_line_naming_the_key(tmp_path, capsys, config, says):
    ref = smooth_path()
    files.write_trajectory(tmp_path / "ref.txt", ref, "tum")
    (tmp_path / "cfg.yaml").write_text(config + "\n")
    argv = [
        "eval",
        str(tmp_path / "ref.txt"),
        str(tmp_path / "ref.txt"),
        "--out",
        str(tmp_path / "o"),
    ]
    assert cli.main(argv + ["--config", str(tmp_path / "cfg.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("epa: error: ") and says in err and err.count("\n") == 1
