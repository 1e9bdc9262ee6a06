"""Run-to-run spread in the tables, the algorithm comparison and the threshold-free success rate, on
the example grid and on rpg's 10-run EuRoC data; the statistics against hand values and scipy."""

import csv
import json
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import DATA, run_stages
from scipy import stats

from epa import simulate
from epa.cli import main as cli
from epa.metrics import drift, statistics
from epa.outputs import tables
from epa.workflow import settings


def test_spread_by_hand():
    v = [1.0, 2.0, 3.0, 4.0]
    assert statistics.spread(v, "std") == pytest.approx(np.sqrt(5 / 3), abs=1e-12)
    assert statistics.spread(v, "ci") == pytest.approx(
        3.182446305284263 * np.sqrt(5 / 3) / 2, abs=1e-9
    )
    assert np.isnan(statistics.spread([2.0], "ci")) and np.isnan(statistics.spread(v, "none"))


def test_exact_wilcoxon_matches_scipy(rng):
    for n in range(1, 12):
        d = rng.normal(0.3, 1.0, n)
        assert statistics.wilcoxon_exact(d) == pytest.approx(
            stats.wilcoxon(d, method="exact").pvalue, abs=1e-12
        )
    assert statistics.min_datasets_for(0.05) == 6  # 2 / 2^6 = 0.031 is the first below 0.05


def test_wilcoxon_beyond_the_enumeration_equals_scipy_bit_for_bit(rng):
    """Over 16 datasets: scipy's exact null distribution up to 50 without ties, else its normal
    approximation with the tie correction; the same floats (the comparison prints them), either tail,
    without importing scipy.stats."""
    for trial in range(400):
        n = int(rng.integers(17, 80))
        d = rng.normal((-0.8, 0.0, 0.4, 1.2)[trial % 4], 1.0, n)
        if trial % 3 == 0:  # ties
            d = np.round(d, 1)
        d = d[d != 0]
        if d.size > 16:  # up to 16 the sign assignments are enumerated (exact with ties too)
            assert statistics.wilcoxon_exact(d) == float(stats.wilcoxon(d).pvalue), d
    code = (
        "import sys, numpy as np; from epa.metrics import statistics;"
        "p = statistics.wilcoxon_exact(np.arange(1.0, 31.0) - 9.5);"
        "print(p, 'scipy.stats' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    p = float(stats.wilcoxon(np.arange(1.0, 31.0) - 9.5).pvalue)
    assert out.stdout.split() == [repr(p), "False"] and p < 0.05


def test_mann_whitney_and_ranks_equal_scipy_bit_for_bit(rng):
    """Exact (no ties, a side of at most 8), tie-corrected normal (ties) and large samples; the
    Student-t interval without scipy.stats. Equal floats, not close ones: the tables print them."""
    for trial in range(600):
        n1, n2 = rng.integers(1, 14, 2)
        if trial % 3 == 0:  # ties
            a, b = rng.integers(0, 4, n1).astype(float), rng.integers(0, 4, n2).astype(float)
        else:
            a, b = rng.normal(0.0, 1.0, n1), rng.normal(0.7, 1.0, n2)
        p = stats.mannwhitneyu(a, b, alternative="two-sided").pvalue
        assert statistics.mann_whitney(a, b) == float(p), (a, b)
        assert np.array_equal(statistics.average_ranks(a)[0], stats.rankdata(a))
    v = rng.normal(size=5)
    assert statistics.spread(v, "ci") == float(stats.t.ppf(0.975, 4) * v.std(ddof=1) / np.sqrt(5))
    assert statistics.mann_whitney([1.0, 1.0], [1.0, 1.0]) == 1.0  # nothing to rank apart


def test_binomial_equals_scipy_bit_for_bit():
    """The exact Mann-Whitney p divides by C(n1 + n2, n1) as scipy.special.binom computes it (its
    float loop below k = 20, its own formula beyond), without importing scipy.special."""
    from scipy import special

    for n in range(0, 600):
        for k in range(0, min(n, 40) + 1):
            assert statistics._binom(n, k) == float(special.binom(n, k)), (n, k)


def read_summary(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def cell(tex_path, row, column):
    """The text of one cell of a .tex table, by row name and header column (0 = first data column)."""
    for line in tex_path.read_text().splitlines():
        if line.startswith(tables.latex_escape(row) + " & "):
            return line.removesuffix(r" \\").split(" & ")[1 + column]
    raise KeyError(row)


def runs_of(rows, alg, ds, key):
    return np.array(
        [float(r[key]) for r in rows if r["algorithm"] == alg and r["dataset"] == ds and r[key]]
    )


# ----------------------------------------------------------------------------- the example grid
@pytest.fixture(scope="module")
def example(tmp_path_factory):
    root = tmp_path_factory.mktemp("example")
    manifest = simulate.simulate(root / "data")
    cfg = settings.resolve(
        {
            "truth_dir": str(root / "data/truth"),
            "algorithms_dir": str(root / "data/algorithms"),
            "report": {"per_case": False},
            "tables": {"spread": "std"},
        }
    )
    cases = [
        {
            "key": key,
            "truth": str(root / "data/truth" / f"{key.split('/')[1]}.txt"),
            "estimate": str(next((root / "data/algorithms").glob(key + ".*"))),
        }
        for key in manifest["cases"]
    ]
    out = root / "results"
    run_stages(
        cases,
        out,
        cfg,
        stages=[
            "load",
            "crop",
            "sync",
            "calibrate",
            "align",
            "metrics",
            "drift",
            "consistency",
            "efficiency",
        ],
    )
    assert tables.make(sorted(manifest["cases"]), out, cfg) == []
    return out, manifest


def test_summary_has_the_step_confidences(example):
    out, manifest = example
    rows = read_summary(out / "summary.csv")
    for r in rows:
        truth = manifest["cases"][f"{r['algorithm']}/{r['dataset']}/{r['run']}"]
        if r["step1_status"] == "trusted":  # the true offset lies within 3 std of what was used
            assert abs(float(r["time_offset_s"]) - truth["time_offset_s"]) <= 3 * float(
                r["time_offset_std_s"]
            )
        if r["step2_status"] == "trusted":
            assert (
                0 < float(r["extrinsic_rot_std_deg"]) < 0.1
                and 0 < float(r["extrinsic_trans_std_m"]) < 0.05
            )
    status = {
        (r["algorithm"], r["dataset"], r["run"]): (r["step1_status"], r["step2_status"])
        for r in rows
    }
    assert status["vio_camera", "drone_figure8", "run1"] == ("trusted", "trusted")
    # the diverging run: its Step 1 peak is weak, so Step 2 is not run
    assert status["vo_drifty", "urban_drive", "run2"] == ("weak peak", "not run")
    # the drifting VO on the vehicle: its lever arm along z is pinned only to 8 cm, so not applied
    assert status["vo_drifty", "urban_drive", "run1"] == ("trusted", "uncertain")


def test_cells_show_their_spread_over_runs_and_how_many(example):
    out, _ = example
    rows = read_summary(out / "summary.csv")
    for alg, ds, col in (("vio_body", "drone_figure8", 0), ("vio_camera", "urban_drive", 2)):
        rot, trans = (
            runs_of(rows, alg, ds, "ate_rot_rmse_deg"),
            runs_of(rows, alg, ds, "ate_trans_rmse_m"),
        )
        expected = (
            f"{rot.mean():.3f} $\\pm$ {rot.std(ddof=1):.3f} / {trans.mean():.3f} $\\pm$ "
            f"{trans.std(ddof=1):.3f} (n=2)"
        )
        assert cell(out / "tables/ate.tex", alg, col) == expected
    # the Average column: no runs of its own
    assert cell(out / "tables/ate.tex", "vio_body", 3).count("$\\pm$") == 0
    assert "± SAMPLE STD OVER RUNS, n = RUNS" in (out / "tables/ate.tex").read_text()
    # and in the text report, with a plain ±
    assert re.search(
        r"vio\\_body & \d\.\d{3} ± \d\.\d{3} / \d\.\d{3} ± \d\.\d{3} \(n=2\)",
        (out / "error_comparison.txt").read_text(),
    )


def test_comparison_on_the_example(example):
    out, _ = example
    text = (out / "comparison.txt").read_text()
    rows = read_summary(out / "summary.csv")
    block = text[text.index("vio_body vs vo_drifty") :].split("=" * 44)[0]
    assert "3 shared datasets" in block and "ATE better on: vio_body 3, vo_drifty 0" in block
    # three datasets can never give p < 0.05 (the exact p of 3 wins is 0.25): said, not hidden
    assert "p = 0.250 (only 3 datasets: at least 6 are needed to reach p < 0.05)" in block
    assert "verdict: the data cannot tell vio_body and vo_drifty apart" in block
    ratio = np.median(
        [
            runs_of(rows, "vio_body", d, "ate_trans_rmse_m").mean()
            / runs_of(rows, "vo_drifty", d, "ate_trans_rmse_m").mean()
            for d in ("drone_figure8", "handheld_office", "urban_drive")
        ]
    )
    assert f"median ratio vio_body / vo_drifty: ATE {ratio:.3f}," in block
    assert "Mann-Whitney p = 0.333" in block  # 2 runs against 2, all of one below all of the other
    tex = (out / "comparison.tex").read_text()
    assert r"vio\_body vs vo\_drifty & 3 & 3--0 & " in tex and "cannot tell apart" in tex


def test_success_rate_curve_and_area(example):
    out, _ = example
    d = json.loads((out / "cases/vo_drifty/urban_drive/run1/07_drift/drift.json").read_text())
    curve = d["success_curve"]
    assert np.allclose(curve["factor"], drift.CURVE_FACTORS)
    rates = np.array(curve["success_rate_distance_pct"])
    assert np.all(np.diff(rates) >= -1e-9)  # looser thresholds never lose path
    # factor 1 is the configured threshold
    assert rates[10] == pytest.approx(d["success_rate_distance_pct"])
    assert d["success_auc_pct"] == pytest.approx(rates.mean())
    assert 0 < d["success_auc_pct"] < 100
    assert cell(out / "tables/success_auc.tex", "vio_body", 0).startswith("100.00")
    with open(out / "success_curves.csv", newline="") as fh:
        rows = [
            r
            for r in csv.DictReader(fh)
            if r["algorithm"] == "vo_drifty" and r["dataset"] == "urban_drive"
        ]
    assert len(rows) == len(drift.CURVE_FACTORS) and rows[0]["runs"] == "2"


# ----------------------------------------------------------------------------- rpg's 10 runs
@pytest.fixture(scope="module")
def rpg(tmp_path_factory):
    if not DATA.is_dir():
        pytest.skip(f"real data not found at {DATA} (CI keeps ../shared/data beside the checkout)")
    gt = DATA / "rpng_open_vins/ov_data/euroc_mav"
    root = DATA / "uzh-rpg_rpg_trajectory_evaluation/results/euroc_vislam_mono/laptop"
    truth = {
        "MH_01": "MH_01_easy.txt",
        "MH_03": "MH_03_medium.txt",
        "MH_04": "MH_04_difficult.txt",
        "MH_05": "MH_05_difficult.txt",
    }
    cases = []
    for s in truth:
        for k in range(10):
            cases.append(
                {
                    "key": f"vislam_ba/{s}/run{k}",
                    "truth": str(gt / truth[s]),
                    "estimate": str(
                        root / f"vislam_ba/laptop_vislam_ba_{s}/stamped_ba_estimate{k}.txt"
                    ),
                }
            )
        cases.append(
            {
                "key": f"vislam_rp/{s}/run0",
                "truth": str(gt / truth[s]),
                "estimate": str(
                    root / f"vislam_rp/laptop_vislam_rp_{s}/stamped_traj_estimate0.txt"
                ),
            }
        )
    out = tmp_path_factory.mktemp("rpg") / "results"
    cfg = settings.resolve(
        {
            "truth_dir": str(gt),
            "algorithms_dir": str(root),
            "report": {"per_case": False},
            "tables": {"spread": "ci"},
        }
    )
    run_stages(
        cases, out, cfg, stages=["load", "crop", "sync", "calibrate", "align", "metrics", "drift"]
    )
    assert tables.make([c["key"] for c in cases], out, cfg) == []
    return out


def test_ten_run_cells_carry_their_confidence_interval(rpg):
    rows = read_summary(rpg / "summary.csv")
    for col, ds in enumerate(("MH_01", "MH_03", "MH_04", "MH_05")):
        trans = runs_of(rows, "vislam_ba", ds, "ate_trans_rmse_m")
        assert len(trans) == 10
        half = stats.t.ppf(0.975, 9) * trans.std(ddof=1) / np.sqrt(10)
        # a cell pooling runs evaluated with Steps 1-2 and the ov_eval way is marked e
        sources = {
            r["eval_source"] for r in rows if r["algorithm"] == "vislam_ba" and r["dataset"] == ds
        }
        mark = "\\textsuperscript{e}" if len(sources) > 1 else ""
        assert cell(rpg / "tables/ate.tex", "vislam_ba", col).endswith(
            f" / {trans.mean():.3f} $\\pm$ {half:.3f} (n=10){mark}"
        )
        # one run: the mean, no ±, and n=1 says why
        assert cell(rpg / "tables/ate.tex", "vislam_rp", col).endswith(" (n=1)")
        assert "$\\pm$" not in cell(rpg / "tables/ate.tex", "vislam_rp", col)
    # pinned: MH_01's ten runs spread widely (SOURCES.md: 0.047-0.323 m with SE3; Step 1 is uncertain
    # on these keyframes, so each is evaluated the ov_eval way, SE3 on all poses)
    assert (
        cell(rpg / "tables/ate.tex", "vislam_ba", 0)
        == "1.945 $\\pm$ 0.810 / 0.163 $\\pm$ 0.066 (n=10)"
    )


def test_ten_run_comparison(rpg):
    text = (rpg / "comparison.txt").read_text()
    assert "vislam_ba vs vislam_rp: 4 shared datasets" in text
    assert "ATE better on: vislam_ba 2, vislam_rp 2" in text
    assert "median ratio vislam_ba / vislam_rp: ATE 1.041, RPE 1.116" in text
    assert "p = 0.625 (only 4 datasets" in text
    assert "MH_01: ATE 0.1627 vs 0.1958 m over 10 / 1 runs" in text
    assert text.count("no test (fewer than 2 runs each)") == 4  # rp has one run per dataset
    assert "verdict: the data cannot tell vislam_ba and vislam_rp apart" in text


def test_selftest_command(capsys, data):
    assert (
        cli.main(
            [
                "selftest",
                str(data / "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"),
                "--trials",
                "2",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    low = next(line for line in out.splitlines() if line.startswith("low"))
    assert low.split()[1:4] == ["2", "of", "2"]  # Step 1 trusted in both low-noise trials
    assert "verdict: Steps 1-2 recover offset and extrinsic on this motion" in out


def test_selftest_on_planar_motion_says_what_is_unobservable(tmp_path, capsys):
    from epa.artifacts import files
    from epa.core import geometry
    from epa.core.trajectory import Trajectory

    t = np.arange(0, 120, 0.01)
    yaw = 0.8 * np.sin(t / 2) + 0.3 * np.sin(1.3 * t)
    ref = Trajectory.from_rp(
        t,
        geometry.so3_exp(yaw[:, None] * [0.0, 0.0, 1.0]),
        np.c_[20 * np.cos(t / 10), 15 * np.sin(t / 7), 0 * t],
    )
    files.write_tum(tmp_path / "planar.txt", ref)
    assert cli.main(["selftest", str(tmp_path / "planar.txt"), "--trials", "1"]) == 0
    out = capsys.readouterr().out
    assert (
        "this motion leaves part of the extrinsic unobservable: unobservable: rotation about" in out
    )
    assert "Steps 1-2 are trusted in 0 of 3 trials" in out


def test_pooled_cells_are_the_same_from_length_runs_and_from_the_length_column(rng):
    """The tables take a segment length's pairs as its run of rows where the metrics stage wrote them
    so (results._pairs), else by comparing the length column: the same cells, spread included, and
    the values by hand (the mean over the pairs pooled from every run)."""
    from epa.artifacts.case import Case
    from epa.outputs.tables import cells

    lengths = np.repeat([8.0, 16.0, 24.0], [5, 4, 3])
    by_column, by_runs = [], []
    for k in range(3):
        seg = {
            "length_m": lengths.copy(),
            "rot_deg": rng.random(12),
            "trans_m": rng.random(12),
            "valid": rng.random(12) > 0.3,
        }
        drift_record = {"global_failed": False, "success_rate_distance_pct": 50.0}
        runs = {k: v for k, v in seg.items() if k != "length_m"}
        runs["length_runs"] = drift.length_runs(seg["length_m"])
        for out, segments in ((by_column, seg), (by_runs, runs)):
            out.append(
                tables.CaseResult(
                    Case("alg", "ds", f"run{k}"), drift=drift_record, segments=segments
                )
            )
    for length in (8.0, 16, 24.0, 32.0):
        for valid in (False, True):
            sel = [
                (c.segments["length_m"] == length) & (c.segments["valid"] | (not valid))
                for c in by_column
            ]
            rot = np.concatenate([c.segments["rot_deg"][s] for c, s in zip(by_column, sel)])
            trans = np.concatenate([c.segments["trans_m"][s] for c, s in zip(by_column, sel)])
            a = cells.mean_pair_cell(by_column, "segments", valid, length)
            b = cells.mean_pair_cell(by_runs, "segments", valid, length)
            if length == 32.0:  # no such pairs
                assert np.isnan(a.values).all() and np.isnan(b.values).all()
                continue
            assert a.values == b.values == (rot.mean(), trans.mean())
            assert a.fmt(4, "std") == b.fmt(4, "std") and "(n=3)" in b.fmt(4, "std")
            per_run = [c.segments["trans_m"][s].mean() for c, s in zip(by_column, sel)]
            assert np.array_equal(b.runs[:, 1], per_run)
            drift_a = cells.drift_rate_cell(by_column, valid, length)
            drift_b = cells.drift_rate_cell(by_runs, valid, length)
            assert drift_a.values == drift_b.values == (np.mean(trans / length) * 100,)
            assert drift_a.fmt(3, "ci") == drift_b.fmt(3, "ci")


def test_a_cases_segments_are_read_as_runs_of_rows_or_by_their_lengths(tmp_path):
    """results._pairs keeps each length's run of rows where the metrics stage wrote them so, and the
    length column where a length comes back after another; the validity as booleans either way."""
    from epa.artifacts.case import CaseFolder
    from epa.outputs.tables import results

    folder = CaseFolder(tmp_path)
    for lengths, runs in (
        ([8, 8, 16, 16, 16], {8.0: slice(0, 2), 16.0: slice(2, 5)}),
        ([8, 16, 8, 16, 16], None),
    ):
        errors = np.arange(5.0)
        folder.write_table(
            "metrics",
            "rpe_segments.csv",
            {
                "length_m": np.array(lengths, float),
                "i": errors,
                "j": errors,
                "rot_deg": errors,
                "trans_m": 2 * errors,
            },
        )
        folder.write_table(
            "drift", "rpe_segments_valid.csv", {"valid": np.array([1.0, 0, 1, 1, 0])}
        )
        seg = results._pairs(folder, "rpe_segments", ("length_m", "rot_deg", "trans_m"))
        assert seg.get("length_runs") == runs and ("length_m" in seg) == (runs is None)
        assert seg["valid"].tolist() == [True, False, True, True, False]
        assert np.array_equal(seg["trans_m"], 2 * errors)
