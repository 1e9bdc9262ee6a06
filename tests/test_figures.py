"""Reports and figures: every per-case figure of a simulated case renders headlessly, a bundle
re-renders to the same image without recomputation, and bad bundles are one-line errors."""

import json
import struct

import pytest

from epa import simulate
from epa.cli import evaluate
from epa.cli import main as cli


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()[:24]
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fig")
    simulate.simulate(tmp / "sim")
    out = tmp / "out"
    assert (
        cli.main(
            [
                "eval",
                str(tmp / "sim/truth/drone_figure8.txt"),
                str(tmp / "sim/algorithms/vio_body/drone_figure8/run1.txt"),
                "--out",
                str(out),
                "--report",
                "--rate",
                "20",
            ]
        )
        == 0
    )
    return out / "10_report"


def test_every_case_figure_and_document_is_written(case):
    # sigma3: vio_body has covariance
    names = {"trajectory", "ape_time", "rpe_box", "xcorr", "steps", "sigma3"}
    assert {p.stem for p in (case / "figures").glob("*.png")} == names
    assert {p.stem for p in (case / "bundles").glob("*.json")} == names
    for p in (case / "figures").glob("*.png"):
        w, h = png_size(p)
        assert 300 < w < 2200 and 200 < h < 2200, (p.name, w, h)
    doc = json.loads((case / "metrics.json").read_text())
    assert set(doc) == {"metrics", "drift", "consistency", "efficiency"}
    en = (case / "report_en.md").read_text()
    assert "| ATE (m / deg) |" in en and "| drift rate 8 m (%) |" in en and "## Provenance" in en
    assert "## 步骤 1-3" in (case / "report_zh.md").read_text()
    rows = (case / "metrics_summary.csv").read_text().splitlines()
    assert rows[0] == "section,metric,value" and any(
        r.startswith("consistency,nees_pos_mean,") for r in rows
    )
    size = sum(p.stat().st_size for p in case.rglob("*") if p.is_file())
    assert size < 2_000_000, size  # the report of a case stays under 2 MB


def test_a_bundle_re_renders_to_the_same_image_without_recomputing(case, tmp_path):
    bundle = case / "bundles" / "ape_time.json"
    before = bundle.read_bytes()
    assert cli.main(["fig", str(bundle), "--out", str(tmp_path / "again")]) == 0
    assert png_size(tmp_path / "again.png") == png_size(case / "figures" / "ape_time.png")
    assert bundle.read_bytes() == before
    assert (
        cli.main(
            ["fig", str(bundle), "--out", str(tmp_path / "slide"), "--style", "slide", "--pdf"]
        )
        == 0
    )
    assert png_size(tmp_path / "slide.png")[0] > png_size(tmp_path / "again.png")[0]
    assert (tmp_path / "slide.pdf").read_bytes()[:5] == b"%PDF-"


def _scaled(obj, k):
    """Another case's bundle data: every number times ``k``."""
    if isinstance(obj, dict):
        return {key: _scaled(v, k) for key, v in obj.items()}
    if isinstance(obj, list):
        return [_scaled(v, k) for v in obj]
    return obj * k if isinstance(obj, (int, float)) and not isinstance(obj, bool) else obj


def test_a_reused_figure_gives_the_same_bytes_as_a_new_one(case, tmp_path):
    """A worker reuses each layout's figure for the next case (figures._KEPT); what it writes must
    not depend on what it drew before."""
    import matplotlib.pyplot as plt

    from epa.outputs import figures

    def fresh():
        for fig in figures._KEPT.values():
            plt.close(fig)
        figures._KEPT.clear()

    bundles = {p.stem: figures.read_bundle(p) for p in sorted((case / "bundles").glob("*.json"))}
    fresh()
    for name, b in bundles.items():  # another case first, every layout kept after it
        other = dict(b, data=_scaled(b["data"], 1.7))
        if name == "rpe_box":
            other["data"]["lengths"] = other["data"]["lengths"][:2]
            other["data"]["trans"] = other["data"]["trans"][:2]
        figures.render(other, tmp_path / "other" / name)
    no_peak = dict(
        bundles["xcorr"], data=dict(bundles["xcorr"]["data"], peak=None, reason="Step 1 not used")
    )
    figures.render(no_peak, tmp_path / "other" / "no_peak")  # its title on the single-axes layout
    assert len(figures._KEPT) >= 3  # single-axes, trajectory, ±3σ layouts
    reused = {name: figures.render(b, tmp_path / "reused" / name) for name, b in bundles.items()}
    for name, b in bundles.items():
        fresh()
        for new, old in zip(figures.render(b, tmp_path / "new" / name), reused[name]):
            assert new.read_bytes() == old.read_bytes(), old.name


def test_a_kept_font_subset_gives_the_bytes_matplotlib_writes(case, tmp_path, monkeypatch):
    """A PDF's font subset is made once per set of glyphs in a process (figures._SUBSETS) and given
    again: every PDF is the one matplotlib writes when it subsets the font itself."""
    import matplotlib
    from matplotlib.backends import _backend_pdf_ps as pdf_ps

    from epa.outputs import figures

    figures.prepare()
    # the locked matplotlib is patched (a CI on it runs this comparison)
    assert matplotlib.__version__.startswith(figures.PATCHED_MATPLOTLIB) == hasattr(
        pdf_ps.get_glyphs_subset, "epa_kept"
    )
    if not hasattr(pdf_ps.get_glyphs_subset, "epa_kept"):
        pytest.skip(
            f"matplotlib {matplotlib.__version__} is not patched (only 3.11.x): nothing to compare"
        )
    bundles = {p.stem: figures.read_bundle(p) for p in sorted((case / "bundles").glob("*.json"))}
    figures._SUBSETS.clear()
    kept, made = {}, []
    for rep in range(2):  # the second time, every subset is a kept one
        kept[rep] = {
            n: figures.render(b, tmp_path / f"kept{rep}" / n, formats=("pdf",))[0]
            for n, b in bundles.items()
        }
        made.append(set(figures._SUBSETS))
    assert made[0] and made[1] == made[0]
    monkeypatch.setattr(pdf_ps, "get_glyphs_subset", pdf_ps.get_glyphs_subset.__wrapped__)
    monkeypatch.setattr(pdf_ps, "font_as_file", pdf_ps.font_as_file.__wrapped__)
    monkeypatch.setattr(figures, "_keep_font_subsets", lambda: None)
    for name, b in bundles.items():
        own = figures.render(b, tmp_path / "own" / name, formats=("pdf",))[0].read_bytes()
        assert b"FontFile2" in own, name  # a TrueType font embedded
        assert kept[0][name].read_bytes() == own == kept[1][name].read_bytes(), name


def test_a_png_holds_the_pixels_matplotlib_writes(case, tmp_path, monkeypatch):
    """figures._write_png encodes Agg's pixels itself (RGB, unfiltered rows): decoded, every case
    figure is matplotlib's own PNG without its alpha channel, which is opaque, at the same dpi."""
    import numpy as np
    from PIL import Image

    from epa.outputs import figures

    bundles = {p.stem: figures.read_bundle(p) for p in sorted((case / "bundles").glob("*.json"))}
    ours = {
        n: figures.render(b, tmp_path / "ours" / n, formats=("png",))[0] for n, b in bundles.items()
    }
    monkeypatch.setattr(figures, "_write_png", lambda fig, path: fig.savefig(path, format="png"))
    for name, b in bundles.items():
        theirs = Image.open(figures.render(b, tmp_path / "theirs" / name, formats=("png",))[0])
        mine = Image.open(ours[name])
        assert (mine.mode, theirs.mode) == ("RGB", "RGBA") and mine.size == theirs.size, name
        assert mine.info["dpi"] == theirs.info["dpi"] == pytest.approx((150, 150), abs=0.02)
        pixels = np.asarray(theirs)
        assert (pixels[..., 3] == 255).all(), name
        assert np.array_equal(np.asarray(mine), pixels[..., :3]), name


@pytest.mark.parametrize(
    "content,message",
    [
        ("{", "not a plot bundle"),
        ('{"format": "epica-plot-bundle/1", "kind": "pie"}', "not an epica plot bundle"),
    ],
)
def test_a_bad_bundle_is_one_line(tmp_path, capsys, content, message):
    (tmp_path / "b.json").write_text(content)
    assert cli.main(["fig", str(tmp_path / "b.json"), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err and str(tmp_path / "b.json") in err


# ----------------------------------------------------------------------------- a grid of real EuRoC files
@pytest.fixture(scope="module")
def euroc_grid(tmp_path_factory):
    """MH_01 and MH_04 (OpenVINS ground truth): OpenVINS with covariance, rpg's VI-SLAM (3 runs each)
    and VIO mono; every stage and the report run in one process, then the tables and grid figures."""
    from conftest import DATA

    if not DATA.is_dir():
        pytest.skip(f"real data not found at {DATA} (CI keeps ../shared/data beside the checkout)")
    from conftest import run_stages

    from epa.outputs import report, tables
    from epa.workflow import settings

    gt = DATA / "rpng_open_vins/ov_data/euroc_mav"
    rpg = DATA / "uzh-rpg_rpg_trajectory_evaluation/results"
    sources = {
        ("openvins", "MH_01", "run0"): DATA
        / "aau-cns_cnspy_trajectory_evaluation/test/sample_data/MH01_ov_est.csv",
        ("openvins", "MH_04", "run0"): DATA / "qmy0519_open_vins-master/traj_estimate.txt",
        ("vio_mono", "MH_01", "run0"): rpg
        / "euroc_mono_stereo/laptop/vio_mono/laptop_vio_mono_MH_01/stamped_traj_estimate.txt",
    }
    for s in ("MH_01", "MH_04"):
        for k in range(3):
            sources["vislam_ba", s, f"run{k}"] = (
                rpg / f"euroc_vislam_mono/laptop/vislam_ba/laptop_vislam_ba_{s}/"
                f"stamped_ba_estimate{k}.txt"
            )
    truth = {"MH_01": gt / "MH_01_easy.txt", "MH_04": gt / "MH_04_difficult.txt"}
    out = tmp_path_factory.mktemp("euroc") / "results"
    cfg = settings.resolve(
        {
            "truth_dir": str(gt),
            "algorithms_dir": str(rpg),
            "report": {"pdf": True, "figures": "all"},
        }
    )
    cases = [
        {"key": "/".join(k), "truth": str(truth[k[1]]), "estimate": str(v)}
        for k, v in sources.items()
    ]
    run_stages(cases, out, cfg)
    keys = [c["key"] for c in cases]
    assert tables.make(keys, out, cfg) == []
    report.write_grid_figures(out, cfg["metrics"]["segments"])
    return out, keys


def test_every_figure_renders_for_a_real_euroc_grid(euroc_grid):
    out, keys = euroc_grid
    for key in keys:
        folder = out / "cases" / key / "10_report"
        expected = set(report_names := ("trajectory", "ape_time", "rpe_box", "xcorr", "steps"))
        if key.startswith("openvins/"):  # OpenVINS writes covariance: the 3-sigma plot exists
            expected.add("sigma3")
        assert {p.stem for p in (folder / "figures").glob("*.png")} == expected, key
        assert {p.stem for p in (folder / "figures").glob("*.pdf")} == expected, key
        for p in (folder / "figures").glob("*.png"):
            w, h = png_size(p)
            assert 300 < w < 2200 and 200 < h < 2200, (key, p.name, w, h)
        for name in report_names:  # each bundle holds data, not an empty frame
            data = json.loads((folder / "bundles" / f"{name}.json").read_text())["data"]
            assert any(isinstance(v, list) and len(v) > 0 for v in data.values()), (key, name)
        size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
        assert size < 2_000_000, (key, size)  # PNG and PDF included
    for name in ("ate", "success_rate", "drift_rate", "rmse_time"):
        for fmt in ("png", "pdf"):
            assert (out / "figures" / f"{name}.{fmt}").stat().st_size > 5_000, (name, fmt)


def test_one_colour_per_algorithm_across_the_grid_figures(euroc_grid):
    out, _ = euroc_grid
    colour_of = {}
    for name in ("ate", "success_rate", "drift_rate", "rmse_time"):
        d = json.loads((out / "figures/bundles" / f"{name}.json").read_text())["data"]
        colours = d["colors"]
        if "algorithms" in d:
            pairs = [(alg, colours[k]) for k, alg in enumerate(d["algorithms"])]
        else:
            pairs = [
                (line["label"], colours[line.get("color", k)])
                for panel in d["panels"]
                for k, line in enumerate(panel["lines"])
            ]
        for alg, colour in pairs:
            assert colour_of.setdefault(alg, colour) == colour, (name, alg)
    assert set(colour_of) >= {"openvins", "vislam_ba", "vio_mono"}
    assert len(set(colour_of.values())) == len(colour_of)


def test_bundle_arrays_are_written_at_seven_digits_with_nan_as_null(tmp_path):
    import numpy as np

    from epa.outputs import figures

    b = figures.bundle(
        "ape_time",
        "t",
        {
            "t": np.array([0.0, 1.0, 2.0]),
            "ape": np.array([0.123456789, np.nan, 1e-9]),
            "fail_start": [],
            "fail_end": [],
            "threshold": None,
        },
    )
    figures.write_bundle(tmp_path / "b.json", b)
    back = figures.read_bundle(tmp_path / "b.json")
    assert back["data"]["ape"] == [0.1234568, None, 1e-9] and back["data"]["threshold"] is None
    assert np.isnan(figures._arr(back["data"]["ape"])[1])


def test_epa_eval_prints_its_stages_on_a_large_input(case, capsys, monkeypatch, tmp_path):
    sim = case.parents[1] / "sim"
    monkeypatch.setattr(evaluate, "LARGE_INPUT_MB", 0)  # every input counts as large
    assert (
        cli.main(
            [
                "eval",
                str(sim / "truth/drone_figure8.txt"),
                str(sim / "algorithms/vio_body/drone_figure8/run1.txt"),
                "--out",
                str(tmp_path / "out"),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("epa: ") and "MB of input" in err[0]
    done = [line.split()[1] for line in err if line.endswith(" s")]
    assert done == [
        "load",
        "crop",
        "sync",
        "calibrate",
        "align",
        "metrics",
        "drift",
        "consistency",
        "efficiency",
        "report",
    ]


def test_a_rerun_recording_holds_the_case(case, tmp_path):
    pytest.importorskip("rerun", reason="the rerun extra is not installed")
    import numpy as np
    from rerun.chunk import RrdReader

    from epa.artifacts import files

    sim = case.parents[1] / "sim"
    out = tmp_path / "out"
    assert (
        cli.main(
            [
                "eval",
                str(sim / "truth/drone_figure8.txt"),
                str(sim / "algorithms/vio_body/drone_figure8/run1.txt"),
                "--out",
                str(out),
                "--rerun",
                "--rate",
                "20",
            ]
        )
        == 0
    )
    rrd = next((out / "10_report").glob("*.rrd"))
    chunks = {str(c.entity_path): c for c in RrdReader(rrd).stream().to_chunks()}
    assert {
        "/world/reference",
        "/world/estimate",
        "/world/estimate/now",
        "/errors/ape_m",
        "/consistency/nees_pos",
    } <= set(chunks)
    ape = files.read_csv(out / "06_metrics/ape.csv")["trans_m"]
    batch = chunks["/errors/ape_m"].to_record_batch()
    column = next(name for name in batch.schema.names if name.endswith("scalars"))
    got = np.array([v[0] for v in batch.column(column).to_pylist()])
    np.testing.assert_allclose(got, ape, rtol=0, atol=0)
    assert json.loads((out / "10_report/report.json").read_text())["rerun"] is True


def test_report_rerun_without_the_extra_is_refused_at_config_time(monkeypatch):
    from epa.core.errors import EpaError
    from epa.outputs import recording
    from epa.workflow import settings

    monkeypatch.setattr(recording, "available", lambda: False)
    with pytest.raises(EpaError, match=r'pip install "epica\[rerun\]"'):
        settings.resolve({"truth_dir": "t", "algorithms_dir": "a", "report": {"rerun": True}})


def test_the_cases_drawn_by_default_are_the_failed_and_the_warned():
    from epa.outputs import report as report_module

    fallback = {"calibrate": {"plan": {"fallback": True}, "reason": "Step 2 not trusted"}}
    assert not report_module.failed({"drift": {}, "metrics": fallback})
    assert report_module.failed({"drift": {"n_fail_segments": 2}, "metrics": {}})
    assert report_module.failed({"drift": {"global_failed": True}, "metrics": {}})
    warned = {"sim3_check": {"warning": "scale 0.5 for an algorithm declared metric"}}
    assert report_module.failed({"drift": {}, "metrics": warned})
    assert report_module.flags({"drift": {}, "metrics": {**fallback, **warned}}) == [
        "evaluated the ov_eval way (Step 2 not trusted)",
        "sim3_check: scale 0.5 for an algorithm declared metric",
    ]


def test_figures_are_drawn_for_flagged_cases_and_one_command_draws_the_rest(tmp_path):
    """report.figures: flagged (the default) draws a case's figures only when drift detection failed
    it; a Step 2 fallback is flagged, not drawn; every case keeps its bundles, and its report names
    the command that draws the rest: `epa fig --case` then gives the figures `report.figures: all`
    gives."""
    from epa.artifacts.case import CaseFolder
    from epa.outputs import report as report_module
    from epa.workflow import chain
    from epa.workflow import settings as settings_module

    simulate.simulate(tmp_path / "sim")
    cases = {
        "clean": ("handheld_office", "vio_body", "run1"),
        "diverged": ("urban_drive", "vo_drifty", "run2"),  # fail segments, globally failed
        "fallback": ("urban_drive", "vo_drifty", "run1"),  # Step 2 not trusted, no failure
    }
    base = settings_module.resolve({"truth_dir": str(tmp_path), "algorithms_dir": str(tmp_path)})
    base["efficiency"]["sensor_rate_hz"] = 20
    folders = {}
    for label, (ds, alg, run) in cases.items():
        est = next((tmp_path / f"sim/algorithms/{alg}/{ds}").glob(f"{run}.*"))
        out = tmp_path / label
        chain.run_case(tmp_path / f"sim/truth/{ds}.txt", est, out, base, write_arrays=True)
        folders[label] = out
    for label, out in folders.items():
        done = report_module.write_case_report(chain.CaseData(CaseFolder(out)), label, base)
        assert bool(done["flags"]) == (label != "clean"), done["flags"]
        md = (out / "10_report/report_en.md").read_text()
        drawn = {p.stem for p in (out / "10_report/figures").glob("*.png")}
        bundles = {p.stem for p in (out / "10_report/bundles").glob("*.json")}
        assert {"trajectory", "ape_time", "xcorr"} <= bundles
        if label == "diverged":
            assert drawn == bundles and "epa fig --case" not in md
        else:
            assert drawn == set() and "`epa fig --case ..`" in md and "not flagged" in md
    clean = folders["clean"]
    assert cli.main(["fig", "--case", str(clean)]) == 0
    by_command = {p.name: p.read_bytes() for p in (clean / "10_report/figures").glob("*.png")}
    everything = {**base, "report": {**base["report"], "figures": "all"}}
    report_module.write_case_report(chain.CaseData(CaseFolder(clean)), "clean", everything)
    assert {
        p.name: p.read_bytes() for p in (clean / "10_report/figures").glob("*.png")
    } == by_command
    assert cli.main(["fig"]) == 2  # neither a bundle nor a case


@pytest.mark.parametrize("values", [[0.0, 0.0], [float("nan"), float("nan")], []])
def test_a_log_axis_without_positive_values_stays_linear(tmp_path, values):
    """A grid whose every case failed (no values) or whose errors are all zero still gets its
    figures: matplotlib refuses to log-scale such an axis, which failed the figures rule."""
    from epa.outputs import figures

    lines = {"label": "a", "x": [1.0, 2.0][: len(values)], "y": values}
    b = figures.bundle(
        "lines",
        "RMSE over time across runs",
        {"panels": [{"title": "d", "lines": [lines]}], "xlabel": "t", "ylabel": "m", "log": True},
    )
    grouped = figures.bundle(
        "grouped",
        "ATE",
        {"datasets": ["d"], "algorithms": ["a"], "values": [[values]], "ylabel": "m", "log": True},
    )
    for name, bundle in (("lines", b), ("grouped", grouped)):
        written = figures.render(bundle, tmp_path / name, formats=("png",))
        assert [p.name for p in written] == [f"{name}.png"]


def test_grid_bundles_take_each_cells_runs_in_row_order(tmp_path):
    """The grid figures' numbers from summary.csv and success_curves.csv, by hand, with the rows of
    algorithms and datasets interleaved (they are grouped once, in their order): a failed run left
    out, a value that is not finite left out of its cell, an algorithm's drift rate over all its runs."""
    from epa.outputs import report

    head = (
        "algorithm,dataset,run,status,ate_trans_rmse_m,success_rate_distance_pct,drift_rate_8m_pct"
    )
    rows = [
        "b,d2,run1,ok,0.5,80,2.0",
        "a,d1,run1,ok,0.1,100,1.0",
        "b,d1,run1,ok,0.3,60,6.0",
        "a,d2,run1,ok,0.2,90,",
        "a,d1,run2,ok,0.4,50,5.0",
        "a,d1,run3,failed: no poses,,,",
        "b,d2,run2,ok,nan,70,4.0",
    ]
    (tmp_path / "summary.csv").write_text("\n".join([head, *rows]) + "\n")
    curves = ["algorithm,dataset,runs,factor,success_rate_distance_pct"]
    curves += ["b,d1,1,1,60", "a,d1,2,0.5,40", "b,d1,1,2,70", "a,d1,2,1,75", "a,d2,1,1,90"]
    (tmp_path / "success_curves.csv").write_text("\n".join(curves) + "\n")
    b = report.grid_bundles(tmp_path / "summary.csv", tmp_path / "consistency", [8])
    ate = b["ate"]["data"]
    assert ate["algorithms"] == ["a", "b"] and ate["datasets"] == ["d1", "d2"]
    assert ate["values"] == [[[0.1, 0.4], [0.2]], [[0.3], [0.5]]]
    assert b["success_rate"]["data"]["values"] == [[[75.0], [90.0]], [[60.0], [75.0]]]
    lines = b["drift_rate"]["data"]["panels"][0]["lines"]
    # each algorithm's own runs (all runs pooled would be 3.6)
    assert [(line["label"], line["y"]) for line in lines] == [("a", [3.0]), ("b", [4.0])]
    panels = b["success_curve"]["data"]["panels"]
    got = [[(line["label"], line["x"], line["y"]) for line in p["lines"]] for p in panels]
    assert got == [
        [("a", [0.5, 1.0], [40.0, 75.0]), ("b", [1.0, 2.0], [60.0, 70.0])],
        [("a", [1.0], [90.0])],
    ]


def test_the_per_dataset_figures_of_a_real_euroc_grid(euroc_grid):
    """Each dataset's overlay has one line per algorithm (its median-ATE run) over the reference, and
    its boxes one box per algorithm and segment length, the median that of the runs' segments."""
    import numpy as np

    from epa.artifacts import files
    from epa.outputs import dataset_figures as df

    out, keys = euroc_grid
    rows = df.read_summary(out / "summary.csv")
    exact = []
    for ds, algs in (
        ("MH_01", ["openvins", "vio_mono", "vislam_ba"]),
        ("MH_04", ["openvins", "vislam_ba"]),
    ):
        for fmt in ("png", "pdf"):
            assert (out / "figures" / f"trajectories_{ds}.{fmt}").stat().st_size > 5_000
            assert (out / "figures" / f"relative_error_{ds}.{fmt}").stat().st_size > 5_000
        over = json.loads((out / f"figures/bundles/trajectories_{ds}.json").read_text())["data"]
        assert [line["label"] for line in over["lines"]] == algs and len(over["ref"]) > 100
        for line in over["lines"]:
            mine = [r for r in rows if (r["algorithm"], r["dataset"]) == (line["label"], ds)]
            assert line["run"] == df.median_run(mine)["run"]
        boxes = json.loads((out / f"figures/bundles/relative_error_{ds}.json").read_text())["data"]
        assert boxes["lengths"] == [8.0, 16.0, 24.0, 32.0, 40.0, 48.0]
        assert [a["label"] for a in boxes["algorithms"]] == algs
        for alg in boxes["algorithms"]:
            assert all(s is not None for s in alg["trans"] + alg["rot"]), alg["label"]
            segs = [
                files.read_csv(out / "cases" / k / "06_metrics/rpe_segments.csv")
                for k in keys
                if k.startswith(f"{alg['label']}/{ds}/")
            ]
            trans = np.concatenate([s["trans_m"][s["length_m"] == 8.0] for s in segs])
            box = alg["trans"][0]
            assert (box["n"], box["runs"]) == (len(trans), len(segs))
            # vislam_ba's runs have fewer segments than are stored: its median is exact (to the
            # bundle's 7 digits); OpenVINS' thousands are thinned to 101 order statistics: within
            # 1 % of the segments in rank
            counts = [int((s["length_m"] == 8.0).sum()) for s in segs]
            if max(counts) <= df.MAX_ORDER_STATISTICS:
                assert box["med"] == pytest.approx(np.median(trans), rel=1e-6), alg["label"]
                exact.append((alg["label"], ds))
            else:
                lo, hi = np.percentile(trans, [49, 51])
                assert lo <= box["med"] <= hi, alg["label"]
    assert ("vislam_ba", "MH_01") in exact


def test_the_report_documents_are_the_plain_encoders_text(case, tmp_path):
    # metrics.json is composed of the records' texts and metrics_summary.csv joined by hand: each
    # must be the bytes write_json and csv.writer write of the same values
    import csv
    import io

    from epa.artifacts import files
    from epa.outputs import report

    doc = json.loads((case / "metrics.json").read_text())
    files.write_json(tmp_path / "again.json", doc)
    assert (case / "metrics.json").read_bytes() == (tmp_path / "again.json").read_bytes()

    def by_csv_writer(d):
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["section", "metric", "value"])
        for s, m, v in report.summary_rows(d):
            w.writerow([s, m, f"{v:.9g}" if isinstance(v, float) else v])
        return buf.getvalue()

    assert (case / "metrics_summary.csv").read_text() == by_csv_writer(doc)
    odd = {"metrics": {"a,b": 1.5, 'q"x': {"y z": 2, "é": 3.0}, "": 4, "n": 0.1 + 0.2}}
    assert report.summary_csv(odd) == by_csv_writer(odd)
    assert '"a,b"' in report.summary_csv(odd)


def test_an_overlay_drawn_into_a_kept_figure_is_the_fresh_one(tmp_path):
    # a worker keeps one figure per layout; a tall trajectory narrows the overlay's views, and the
    # next dataset's was drawn into the previous one's axes (its figure of the same height)
    import numpy as np

    from epa.core import runtime
    from epa.outputs import figures

    t = np.linspace(0, 2 * np.pi, 200)

    def overlay(sx, sy):
        xyz = np.column_stack([sx * np.cos(t), sy * np.sin(t), 0.1 * t])
        line = {"label": "a", "run": "run0", "color": 0, "xyz": xyz + 0.05}
        return figures.bundle("overlay", "o", {"dataset": "d", "ref": xyz, "lines": [line]})

    # both as tall as an overlay gets, so of one figure height, each of its own width
    other, tall = overlay(10.0, 20.0), overlay(5.0, 40.0)
    runtime.reset()
    figures.render(tall, tmp_path / "fresh", style="wide", formats=("png",))
    runtime.reset()
    figures.render(other, tmp_path / "first", style="wide", formats=("png",))
    figures.render(tall, tmp_path / "kept", style="wide", formats=("png",))
    runtime.reset()
    assert (tmp_path / "kept.png").read_bytes() == (tmp_path / "fresh.png").read_bytes()
