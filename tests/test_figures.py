"""Reports and figures: every per-case figure of a simulated case renders headlessly, a bundle
re-renders to the same image without recomputation, and bad bundles are one-line errors."""
import json
import struct

import pytest

from epa import cli, simulate


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()[:24]
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fig")
    simulate.simulate(tmp / "sim")
    out = tmp / "out"
    assert cli.main(["eval", str(tmp / "sim/truth/drone_figure8.txt"),
                     str(tmp / "sim/algorithms/vio_body/drone_figure8/run1.txt"), "--out", str(out), "--report",
                     "--rate", "20"]) == 0
    return out / "10_report"


def test_every_case_figure_and_document_is_written(case):
    names = {"trajectory", "ape_time", "rpe_box", "xcorr", "steps", "sigma3"}  # sigma3: vio_body has covariance
    assert {p.stem for p in (case / "figures").glob("*.png")} == names
    assert {p.stem for p in (case / "bundles").glob("*.json")} == names
    for p in (case / "figures").glob("*.png"):
        w, h = png_size(p)
        assert 300 < w < 2200 and 200 < h < 2200, (p.name, w, h)
    doc = json.loads((case / "metrics.json").read_text())
    assert set(doc) == {"metrics", "drift", "consistency", "efficiency"}
    assert "| metrics.ate.trans_m.rmse |" in (case / "report_en.md").read_text()
    assert "## 步骤 1-3" in (case / "report_zh.md").read_text()
    rows = (case / "metrics_summary.csv").read_text().splitlines()
    assert rows[0] == "section,metric,value" and any(r.startswith("consistency,nees_pos_mean,") for r in rows)
    size = sum(p.stat().st_size for p in case.rglob("*") if p.is_file())
    assert size < 2_000_000, size  # the report of a case stays under 2 MB


def test_a_bundle_re_renders_to_the_same_image_without_recomputing(case, tmp_path):
    bundle = case / "bundles" / "ape_time.json"
    before = bundle.read_bytes()
    assert cli.main(["fig", str(bundle), "--out", str(tmp_path / "again")]) == 0
    assert png_size(tmp_path / "again.png") == png_size(case / "figures" / "ape_time.png")
    assert bundle.read_bytes() == before
    assert cli.main(["fig", str(bundle), "--out", str(tmp_path / "slide"), "--style", "slide", "--pdf"]) == 0
    assert png_size(tmp_path / "slide.png")[0] > png_size(tmp_path / "again.png")[0]
    assert (tmp_path / "slide.pdf").read_bytes()[:5] == b"%PDF-"


@pytest.mark.parametrize("content,message", [
    ("{", "not a plot bundle"),
    ('{"format": "epica-plot-bundle/1", "kind": "pie"}', "not an epica plot bundle"),
])
def test_a_bad_bundle_is_one_line(tmp_path, capsys, content, message):
    (tmp_path / "b.json").write_text(content)
    assert cli.main(["fig", str(tmp_path / "b.json"), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err and str(tmp_path / "b.json") in err
