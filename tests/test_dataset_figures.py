"""The per-dataset grid figures (trajectory overlays, relative-error boxes): their numbers by hand,
from per-case files written here, and on simulated cases run through every stage."""

import json

import numpy as np
import pytest

from epa.outputs import dataset_figures as df
from epa.outputs import figures, tables

HEAD = "algorithm,dataset,run,status,n_matched,ate_trans_rmse_m"


def _mpl_stats(values):
    from matplotlib import cbook

    return cbook.boxplot_stats(np.asarray(values, float))[0]


def test_box_statistics_of_every_segment_are_matplotlibs_of_the_pooled_segments():
    # two runs, every segment stored: the pooled [1, 2, 3, 4, 10]
    s = df.box_stats([(4, [1.0, 2.0, 3.0, 4.0]), (1, [10.0])])
    assert (s["q1"], s["med"], s["q3"]) == (2.0, 3.0, 4.0)
    assert (s["whislo"], s["whishi"]) == (1.0, 4.0)  # 10 is beyond 4 + 1.5 * 2
    assert (s["n"], s["runs"]) == (5, 2)
    rng = np.random.default_rng(3)
    parts = [rng.gamma(2.0, 0.1, n) for n in (40, 7, 90)]
    s = df.box_stats([df.order_statistics(p) for p in parts])
    ref = _mpl_stats(np.concatenate(parts))
    for key in ("q1", "med", "q3", "whislo", "whishi"):
        assert s[key] == pytest.approx(float(ref[key]), rel=1e-12), key
    assert df.box_stats([]) is None and df.box_stats([(0, [])]) is None
    one = df.box_stats([(1, [0.5])])
    assert one["med"] == one["q1"] == one["whishi"] == 0.5


def test_thinned_runs_weigh_by_their_segments():
    """A run of 10,000 segments kept as 101 order statistics and a run of 10 segments: the pooled
    median is that of the 10,010 segments, not of 111 values weighted alike."""
    n, q = df.order_statistics(np.linspace(0.0, 1.0, 10_000))
    assert n == 10_000 and len(q) == df.MAX_ORDER_STATISTICS and (q[0], q[-1]) == (0.0, 1.0)
    pooled = np.concatenate([np.linspace(0.0, 1.0, 10_000), np.full(10, 5.0)])
    s = df.box_stats([(n, q), (10, np.full(10, 5.0))])
    # the segments' median is 0.5005; unweighted, the 111 values' would be 0.55
    assert s["med"] == pytest.approx(np.median(pooled), abs=0.002)
    assert s["q3"] == pytest.approx(np.percentile(pooled, 75), abs=0.002)
    assert s["n"] == 10_010
    # a value that is not finite is no segment
    assert df.order_statistics([1.0, np.nan, np.inf, 2.0])[0] == 2


def test_thinned_runs_are_interpolated_as_one_call_per_run_would_bit_for_bit():
    """box_stats interpolates every thinned run in one np.interp call: the same doubles as a call
    per run onto its own ranks, so the quartiles and whiskers are those of the runs' segments."""
    rng = np.random.default_rng(5)
    parts = [df.order_statistics(rng.gamma(2.0, 0.1, n)) for n in (354, 1000, 60, 5000, 102, 7)]
    per_run = np.concatenate(
        [
            q if len(q) == n else np.interp(np.arange(n), figures.thin(n, len(q)), q)
            for n, q in parts
        ]
    )
    q1, med, q3 = np.percentile(per_run, [25, 50, 75])
    iqr = q3 - q1
    s = df.box_stats(parts)
    assert (s["q1"], s["med"], s["q3"]) == (q1, med, q3)
    assert s["whislo"] == per_run[per_run >= q1 - 1.5 * iqr].min()
    assert s["whishi"] == per_run[per_run <= q3 + 1.5 * iqr].max()
    assert (s["n"], s["runs"]) == (len(per_run), 6) == (6523, 6)


def test_the_median_run_is_the_lower_middle_ate():
    rows = [
        {"run": "r1", "ate_trans_rmse_m": "0.3"},
        {"run": "r2", "ate_trans_rmse_m": "0.1"},
        {"run": "r3", "ate_trans_rmse_m": "nan"},
        {"run": "r4", "ate_trans_rmse_m": "0.2"},
    ]
    assert df.median_run(rows)["run"] == "r4"
    assert df.median_run([*rows, {"run": "r5", "ate_trans_rmse_m": "0.4"}])["run"] == "r4"
    assert df.median_run(rows[2:3]) is None


def _case(root, key, est, ref, samples=None):
    rep = root / "cases" / key / "10_report"
    figures.write_bundle(
        rep / "bundles/trajectory.json",
        figures.bundle("trajectory", "t", {"ref": ref, "est": est, "err": np.zeros(len(est))}),
    )
    if samples is not None:
        figures.write_bundle(rep / df.SAMPLES_FILE, samples)


def _samples(lengths, trans, rot):
    rel = {"lengths": lengths, "n": [], "trans_m": [], "rot_deg": []}
    for t, r in zip(trans, rot):
        rel["n"].append([len(t), len(r)])
        rel["trans_m"].append(np.sort(t))
        rel["rot_deg"].append(np.sort(r))
    return {"format": df.SAMPLES_FORMAT, "source": "rpe", "rotation": "rotation", "relative": rel}


def test_grid_bundles_by_hand(tmp_path):
    """Two algorithms on d1 (a: three runs, b: one, whose failed run is left out), one on d2 with its
    own segment lengths: the overlay holds each algorithm's median-ATE run, the boxes one box per
    algorithm and length with the pooled segments' median."""
    line = np.c_[np.arange(5.0), np.zeros(5), np.ones(5)]
    ref = np.c_[np.arange(6.0), np.ones(6), np.zeros(6)]
    rows = [
        "a,d1,run1,ok,5,0.3",
        "a,d1,run2,ok,6,0.1",
        "a,d1,run3,ok,5,0.2",
        "b,d1,run1,ok,5,0.5",
        "b,d1,run2,failed: no poses,,",
        "b,d2,run1,ok,5,0.4",
    ]
    (tmp_path / "summary.csv").write_text("\n".join([HEAD, *rows]) + "\n")
    trans = {
        "a/d1/run1": ([1.0, 2.0], [5.0]),
        "a/d1/run2": ([3.0], [6.0, 7.0]),
        "a/d1/run3": ([4.0, 9.0], []),
        "b/d1/run1": ([0.5], [0.1]),
        "b/d2/run1": ([2.0, 4.0, 6.0],),
    }
    for k, (key, t) in enumerate(trans.items()):
        lengths = [8.0, 16.0] if "d1" in key else [100.0]
        _case(tmp_path, key, line + k, ref, _samples(lengths, t, [np.ones(len(x)) for x in t]))
    got = df.grid_bundles(tmp_path, df.read_summary(tmp_path / "summary.csv"), tables.has_result)
    assert list(got) == df.names(["d1", "d2"])
    over = got["trajectories_d1"]["data"]
    # a's median-ATE run is run3 (0.2; written third: line + 2), b's its only successful one
    assert [(x["label"], x["run"], x["color"]) for x in over["lines"]] == [
        ("a", "run3", 0),
        ("b", "run1", 1),
    ]
    assert np.allclose(over["lines"][0]["xyz"], line + 2) and np.allclose(over["ref"], ref)
    boxes = got["relative_error_d1"]["data"]
    assert boxes["lengths"] == [8.0, 16.0]
    med = [[s["med"] for s in alg["trans"]] for alg in boxes["algorithms"]]
    assert med == [[3.0, 6.0], [0.5, 0.1]]  # a at 8 m: [1, 2, 3, 4, 9]; at 16 m: [5, 6, 7]
    assert [s["n"] for s in boxes["algorithms"][0]["trans"]] == [5, 3]
    d2 = got["relative_error_d2"]["data"]
    # only b ran on d2, with its own lengths; its colour stays the grid's second
    assert d2["lengths"] == [100.0] and [a["color"] for a in d2["algorithms"]] == [1]
    assert d2["algorithms"][0]["trans"][0]["med"] == 4.0
    for name, b in got.items():
        assert figures.render(b, tmp_path / name, formats=("png",))[0].stat().st_size > 5000


def test_an_empty_dataset_draws(tmp_path):
    """Every run failed (or no per-case reports): empty panels, not an error."""
    (tmp_path / "summary.csv").write_text(HEAD + "\na,d1,run1,failed: no poses,,\n")
    got = df.grid_bundles(tmp_path, df.read_summary(tmp_path / "summary.csv"), tables.has_result)
    for name, b in got.items():
        assert b["data"].get("lines", b["data"].get("algorithms")) == []
        assert figures.render(b, tmp_path / name, formats=("png",))


@pytest.fixture(scope="module")
def sim_grid(tmp_path_factory):
    """Two algorithms of the example on one dataset, two runs each, Sim3-aligned: every stage, the
    tables and the grid figures in this process."""
    from conftest import run_stages

    from epa import simulate
    from epa.outputs import report
    from epa.workflow import settings

    tmp = tmp_path_factory.mktemp("dsfig")
    simulate.simulate(tmp / "sim")
    out = tmp / "results"
    cfg = settings.resolve(
        {
            "truth_dir": str(tmp / "sim/truth"),
            "algorithms_dir": str(tmp / "sim/algorithms"),
            "align": {"method": "sim3"},
            "metrics": {"segments": [10, 30]},
            "efficiency": {"sensor_rate_hz": 20},
            "report": {"figures": "none"},
        }
    )
    cases = [
        {
            "key": f"{alg}/handheld_office/{run}",
            "truth": str(tmp / "sim/truth/handheld_office.txt"),
            "estimate": str(tmp / f"sim/algorithms/{alg}/handheld_office/{run}.txt"),
        }
        for alg in ("vio_body", "vo_drifty")
        for run in ("run1", "run2")
    ]
    run_stages(cases, out, cfg)
    keys = [c["key"] for c in cases]
    assert tables.make(keys, out, cfg) == []
    written = report.write_grid_figures(out, cfg["metrics"]["segments"])
    return out, written


def test_the_overlay_draws_the_aligned_estimate_of_the_median_run(sim_grid):
    from epa.artifacts.case import CaseFolder

    out, written = sim_grid
    names = {p.name for p in written}
    for name in df.names(["handheld_office"]):
        assert {f"{name}.png", f"{name}.pdf"} <= names
    rows = df.read_summary(out / "summary.csv")
    b = json.loads((out / "figures/bundles/trajectories_handheld_office.json").read_text())
    assert [x["label"] for x in b["data"]["lines"]] == ["vio_body", "vo_drifty"]
    for line in b["data"]["lines"]:
        mine = [r for r in rows if r["algorithm"] == line["label"]]
        assert line["run"] == df.median_run(mine)["run"]
        case = out / "cases" / line["label"] / "handheld_office" / line["run"]
        aligned = CaseFolder(case).tum("align", "aligned.tum").p  # row k: matched pose k
        per_case = aligned[figures.thin(len(aligned))]  # the case's trajectory bundle
        expected = per_case[figures.thin(len(per_case), df.OVERLAY_POINTS)]
        assert len(line["xyz"]) == df.OVERLAY_POINTS < len(aligned)
        # the bundles' 7 significant digits, on positions of tens of metres
        assert np.allclose(line["xyz"], expected, rtol=0, atol=1e-4)
        assert json.loads((case / "05_align/transform.json").read_text())["method"] == "sim3"


def test_the_boxes_are_each_algorithms_segments_per_length(sim_grid):
    from epa.artifacts import files

    out, _ = sim_grid
    b = json.loads((out / "figures/bundles/relative_error_handheld_office.json").read_text())
    assert b["data"]["lengths"] == [10.0, 30.0]
    for alg in b["data"]["algorithms"]:
        segs = [
            files.read_csv(
                out / "cases" / alg["label"] / "handheld_office" / r / "06_metrics/rpe_segments.csv"
            )
            for r in ("run1", "run2")
        ]
        for j, length in enumerate((10.0, 30.0)):
            trans = np.concatenate([s["trans_m"][s["length_m"] == length] for s in segs])
            box = alg["trans"][j]
            assert box["n"] == len(trans) > df.MAX_ORDER_STATISTICS and box["runs"] == 2
            # from 101 order statistics of each run: within 1 % of the segments in rank
            lo, hi = np.percentile(trans, [49, 51])
            assert lo <= box["med"] <= hi
            lo, hi = np.percentile(trans, [24, 26])
            assert lo <= box["q1"] <= hi


def test_the_paper_captions_a_dataset_figure_with_its_kinds_caption(tmp_path):
    from pathlib import Path

    from epa.outputs import paper

    (tmp_path / "trajectories.rst").write_text("Trajectories, ``aligned``.\n")
    caps = paper.figure_captions(tmp_path)
    tex = paper.paper_tex(
        [], [Path("figures/trajectories_MH_01.pdf"), Path("figures/relative_error_V1.pdf")], caps
    )
    assert r"\includegraphics[width=0.9\linewidth]{figures/trajectories_MH_01.pdf}" in tex
    assert r"\caption{MH\_01: Trajectories, aligned.}" in tex
    assert r"\caption{relative error V1}" in tex  # no caption file: its name


@pytest.mark.parametrize("content", ["{not json", '{"format": "something else"}', "[]"])
def test_a_bad_samples_file_is_one_line_naming_it(tmp_path, content):
    from epa.core.errors import EpaError

    (tmp_path / "summary.csv").write_text(HEAD + "\na,d1,run1,ok,5,0.3\n")
    path = tmp_path / "cases/a/d1/run1/10_report" / df.SAMPLES_FILE
    path.parent.mkdir(parents=True)
    path.write_text(content)
    with pytest.raises(EpaError) as err:
        df.grid_bundles(tmp_path, df.read_summary(tmp_path / "summary.csv"), tables.has_result)
    line = err.value.one_line()
    assert str(path) in line and "not a grid samples file" in line and "\n" not in line


def _overlay_bundle(dataset, xy_scale, k):
    t = np.linspace(0.0, 6.0, 300)
    ref = np.c_[xy_scale[0] * np.sin(t), xy_scale[1] * np.cos(t), 0.1 * t]
    lines = [
        {
            "label": f"alg{a}",
            "run": "run1",
            "color": a,
            "xyz": ref + 0.05 * (a + k) * np.sin(3 * t)[:, None],
        }
        for a in range(3)
    ]
    return figures.bundle(
        "overlay",
        "t",
        {"dataset": dataset, "ref": ref, "lines": lines, "colors": figures.OKABE_ITO},
    )


def _boxes_bundle(dataset, n_alg, spread):
    algs = [
        {
            "label": f"alg{a}",
            "color": a,
            "trans": [
                df.box_stats([(5, np.array([1.0, 2.0, 3.0, 4.0, 5.0]) * spread**a * L)])
                for L in (1, 2)
            ],
            "rot": [df.box_stats([(3, np.array([0.1, 0.2, 0.4]) * L)]) for L in (1, 2)],
        }
        for a in range(n_alg)
    ]
    data = {
        "dataset": dataset,
        "lengths": [8.0, 16.0],
        "algorithms": algs,
        "ylabels": ["t [m]", "r [deg]"],
    }
    return figures.bundle("boxes", "t", data)


def test_a_reused_dataset_figure_gives_the_same_bytes_as_a_new_one(tmp_path):
    """A worker draws dataset after dataset into one kept figure per layout (figures._KEPT),
    resized for each overlay's shape (a wide one, then a tall one whose views are narrower): what
    it writes must not depend on what it drew before, legends and log axes included."""
    import matplotlib.pyplot as plt

    def fresh():
        for fig in figures._KEPT.values():
            plt.close(fig)
        figures._KEPT.clear()

    first = [_overlay_bundle("wide", (4.0, 1.0), 0), _boxes_bundle("a", 3, 1.0)]
    second = [_overlay_bundle("tall", (1.0, 6.0), 1), _boxes_bundle("b", 2, 1000.0)]
    fresh()
    for k, b in enumerate(first):
        figures.render(b, tmp_path / "first" / str(k), style="wide")
    assert len(figures._KEPT) == 2
    reused = [
        figures.render(b, tmp_path / "reused" / str(k), style="wide") for k, b in enumerate(second)
    ]
    for k, b in enumerate(second):
        fresh()
        for new, old in zip(figures.render(b, tmp_path / "new" / str(k), style="wide"), reused[k]):
            assert new.read_bytes() == old.read_bytes(), old.name
