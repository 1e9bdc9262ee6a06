"""Table cells that pool different evaluations are marked (epa.outputs.tables.marks), and every table
is also a CSV of its cells (tables/<name>.csv, cells.csv, epa.read_cells) holding the numbers the .tex
prints: by hand on made-up cases, on the bundled example (two of vo_drifty's cases fall back to the
ov_eval way) and on a Sim3 grid where one algorithm's scale hides its error (flagged)."""

import csv
import re

import numpy as np
import pytest
from conftest import run_stages, smooth_path

import epa
from epa import readers, simulate
from epa.artifacts import files
from epa.artifacts.case import Case
from epa.core import geometry
from epa.core.errors import EpaError
from epa.core.trajectory import Trajectory
from epa.outputs import tables
from epa.outputs.tables import marks, tidy
from epa.outputs.tables.latex import restyle
from epa.outputs.tables.results import CaseResult
from epa.workflow import chain, settings


# ----------------------------------------------------------------------------- by hand
def _case(run, source="epa", method="se3", scale=None, fallback=False, **records):
    metrics = {
        "eval_source": source,
        "alignment": {"method": method, **({"scale": scale} if scale is not None else {})},
        "calibrate": {"plan": {"fallback": fallback}},
        **records,
    }
    return CaseResult(Case.unchecked(f"alg/ds/{run}"), metrics=metrics)


def test_a_cell_is_marked_by_what_differs_among_its_cases():
    plain = [_case("r1"), _case("r2")]
    assert marks.of_cases(plain) == "" and marks.of_cases([]) == ""
    fell_back = _case("r3", source="ov_eval", fallback=True)
    assert marks.of_cases([*plain, fell_back]) == "e"
    assert marks.of_cases([fell_back, fell_back]) == ""  # one recipe, if not the asked one
    sim3 = _case("r4", method="sim3", scale=5.0)
    assert marks.of_cases([*plain, sim3]) == "a"
    assert marks.of_cases([sim3]) == ""  # Sim3 alone: named in the footnote, not marked
    # any registered metric's warning flags its case, even alone in its cell
    warned = _case("r5", sim3_check={"warning": "the SE3 ATE (3 m) ..."})
    assert marks.of_cases([warned]) == "f"
    other = _case("r6", kitti={"warning": "a misfit"})  # not only the Sim3 check's
    assert marks.of_cases([other]) == "f" and marks.evaluation(other).warnings == (
        ("kitti", "a misfit"),
    )
    assert marks.of_cases([*plain, fell_back, sim3, warned]) == "e,a,f"
    assert marks.of_cases([_case("r7", sim3_check={"warning": None})]) == ""


def test_the_footnotes_say_what_each_mark_means_and_give_the_sim3_scales():
    from epa.outputs.tables.cells import Cell

    cell = Cell((1.0, 2.0))
    cell.cases = [_case("r1"), _case("r2", source="ov_eval", fallback=True)]
    cell.marks = marks.of_cases(cell.cases)
    mono = Cell((1.0, 2.0))
    mono.cases = [_case("r3", method="sim3", scale=4.0), _case("r4", method="sim3", scale=6.0)]
    mono.cases.append(_case("r5", method="sim3", scale=5.0, sim3_check={"warning": "w"}))
    mono.marks = marks.of_cases(mono.cases)
    assert mono.marks == "f"
    notes = marks.notes({"vio": [cell], "mono": [mono, mono]})  # a case counted once
    assert notes == [
        (
            "e",
            "pools cases evaluated differently (epa, ov_eval; ov_eval: Step 1 or 2 not trusted,"
            " evaluated without them)",
        ),
        (
            "f",
            "holds a flagged case: a metric warned (sim3_check; see summary.csv's notes and the case report)",
        ),
        ("", "Sim3-aligned rows (mean Sim3 scale of their cases): mono 5.000"),
    ]
    assert marks.notes({"vio": [Cell((1.0, 2.0))]}) == []


def test_booktabs_puts_the_bottom_rule_over_the_footnotes():
    from epa.outputs.tables.latex import tex_document

    note = r"\multicolumn{2}{l}{\footnotesize \textsuperscript{e} x} \\"
    tex = tex_document("T", [r" & \textbf{a} \\ \hline", r"b & 1\textsuperscript{e} \\"], 2, [note])
    assert tex.splitlines()[-3:] == [r"\hline", note, r"\end{tabular}"]
    assert restyle(tex, "booktabs").splitlines()[-3:] == [r"\bottomrule", note, r"\end{tabular}"]
    plain = tex_document("T", [r" & \textbf{a} \\ \hline", r"b & 1 \\"], 2)
    assert restyle(plain, "booktabs").splitlines()[-2:] == [r"\bottomrule", r"\end{tabular}"]


# ----------------------------------------------------------------------------- the example
@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The bundled example with a spread (std): vo_drifty's two urban_drive cases fall back."""
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
    run_stages(cases, out, cfg, stages=chain.NAMES[:-1])  # all but the per-case report
    assert tables.make(sorted(manifest["cases"]), out, cfg) == []
    return out, cfg


_TEX_CELL = re.compile(
    r"^(?P<body>.*?)(?: \(n=(?P<n>\d+)\))?(?:\\textsuperscript\{(?P<marks>[a-z,]+)\})?$"
)


def _tex_cells(path):
    """{(row name, column): (numbers, spreads, n, marks)} of a .tex table, as printed."""
    lines = path.read_text().splitlines()
    header = [
        re.sub(r"\\textbf\{(.*)\}", r"\1", h.strip())
        for h in lines[2].split(" \\\\")[0].split("&")[1:]
    ]
    out = {}
    for line in lines[3:]:
        if not line.endswith(r" \\") or line.startswith(r"\multicolumn"):
            continue
        name, *cells = line[: -len(r" \\")].split(" & ")
        for column, text in zip(header, cells):
            m = _TEX_CELL.match(text.strip())
            numbers, spreads = [], []
            for part in m["body"].split(" / "):
                value, _, pm = part.partition(" $\\pm$ ")
                numbers.append(value)
                spreads.append(pm or None)
            out[(name.replace("\\_", "_"), column.replace("\\_", "_").replace("\\%", "%"))] = (
                numbers,
                spreads,
                m["n"],
                m["marks"] or "",
            )
    return out


def _decimals(text: str) -> int:
    return len(text.split(".")[1]) if "." in text else 0


def test_each_csv_holds_the_numbers_its_tex_prints(example):
    out, cfg = example
    names = tables.cell_tables(cfg)
    assert names and all((out / f"tables/{n}.csv").is_file() for n in names)
    checked = 0
    for name in names:
        printed = _tex_cells(out / f"tables/{name}.tex")
        with open(out / f"tables/{name}.csv", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            quantities = [c for c in reader.fieldnames[2:] if c not in ("n", "marks", "note")]
            rows = list(reader)
        values = [q for q in quantities if not q.endswith("_spread")]
        assert len(rows) == len(printed), name
        for r in rows:
            label = r["algorithm"] + (f" ({r['note']})" if r["note"] else "")
            numbers, spreads, n, mark = printed[(label, r["column"])]
            assert len(numbers) == len(values), (name, label)
            for q, text, pm in zip(values, numbers, spreads):
                if text in ("-", "nan"):
                    assert r[q] == "", (name, label, q)
                    continue
                d = _decimals(text)
                assert d == (2 if name.startswith("success") else 3)
                assert f"{float(r[q]):.{d}f}" == text, (name, label, q)
                if pm is not None:
                    assert f"{float(r[q + '_spread']):.{d}f}" == pm, (name, label, q)
                else:
                    assert r[q + "_spread"] == "", (name, label, q)
                checked += 1
            if n is not None:
                assert r["n"] == n
            assert r["marks"] == mark, (name, label, r["column"])
    assert checked == 300  # every number of the 15 tables but those printed - or nan


def test_cells_csv_is_every_table_cell_and_read_cells_returns_it(example):
    out, cfg = example
    frame = epa.read_cells(out)
    assert list(frame.columns) == list(tidy.CELLS_COLUMNS)
    ate = frame[(frame.metric == "ate") & (frame.statistic == "trans_m")]
    with open(out / "tables/ate.csv", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            got = ate[(ate.algorithm == r["algorithm"]) & (ate.dataset == r["column"])]
            assert len(got) == 1 and got.value.iloc[0] == float(r["trans_m"])
            assert got.n.iloc[0] == int(r["n"]) and got.marks.iloc[0] == r["marks"]
            if r["column"] == "Average":  # a mean over datasets: no spread over runs
                assert r["trans_m_spread"] == "" and np.isnan(got.spread.iloc[0])
            else:
                assert got.spread.iloc[0] == float(r["trans_m_spread"])
    rpe = frame[(frame.metric == "rpe_distance") & (frame.statistic == "trans_m_8m")]
    assert set(rpe.dataset) == {"all"} and len(rpe) == 3
    # each algorithm and dataset's cases: vo_drifty's two urban_drive runs fell back
    cases = frame[frame.metric == "cases"].set_index(["algorithm", "dataset", "statistic"])
    assert cases.loc[("vo_drifty", "urban_drive", "fallback"), "value"] == 2
    assert cases.loc[("vo_drifty", "drone_figure8", "fallback"), "value"] == 0
    assert cases.loc[("vio_body", "urban_drive", "with_result"), "value"] == 2
    assert (frame[frame.metric == "cases"].value.sum()) == 18 + 2  # 18 with a result, 2 fell back
    assert not (frame.metric == "alignment").any()  # no Sim3 case
    # the marks: only vo_drifty's cells that pool its urban_drive runs with its others
    marked = frame[frame.marks != ""]
    assert set(marked.algorithm) == {"vo_drifty"} and set(marked.marks) == {"e"}
    assert set(marked.dataset) == {"Average", "all"}


def test_the_example_marks_and_counts_its_fallbacks(example):
    out, _ = example
    text = (out / "error_comparison.txt").read_text()
    assert text.endswith(
        "FELL BACK (STEP 1 OR 2 NOT TRUSTED, EVALUATED THE OV_EVAL WAY): 2 of 18 cases with a result\n"
        + "=" * 44
        + "\n"
    )
    assert "FLAGGED" not in text
    # the text tables: the letter after the numbers, the footnote under the rows
    row = next(r for r in text.splitlines() if r.startswith("vo\\_drifty & 0.584 ± "))
    assert row.endswith(" [e] \\\\") and row.count("[e]") == 1  # its Average only
    assert "\n[e] pools cases evaluated differently (epa, ov_eval; " in text
    ate = (out / "tables/ate.tex").read_text().splitlines()
    assert ate[-3] == r"\hline" and ate[-2].startswith(
        r"\multicolumn{5}{l}{\footnotesize \textsuperscript{e} pools"
    )
    assert ate[-1] == r"\end{tabular}"
    vio = [line for line in ate if line.startswith("vio")]
    assert vio and not any("textsuperscript" in line for line in vio)
    report = tables.failure_report(out / "summary.csv")
    assert report.splitlines() == [
        "epica: every case has a result (18 cases)",
        "epica: cases evaluated without Steps 1-2 or flagged (marked in the tables; cells.csv):",
        "  vo_drifty: 2 of 6 cases fell back to the ov_eval way (Step 1 or 2 not trusted), 0 flagged",
    ]


def test_read_cells_without_tables_is_one_line(tmp_path):
    with pytest.raises(EpaError, match="no cells.csv: run the workflow"):
        epa.read_cells(tmp_path)


# ----------------------------------------------------------------------------- flagged, Sim3
R0 = geometry.so3_exp(np.array([0.2, -0.1, 1.0]))


def _estimate(ref, scale, noise, seed):
    rng = np.random.default_rng(seed)
    p = scale * (ref.p + rng.normal(0, noise, ref.p.shape)) @ R0.T + [5.0, -2.0, 1.0]
    return Trajectory(ref.t, p, geometry.rot_to_quat(R0 @ ref.r))


@pytest.fixture(scope="module")
def sim3_grid(tmp_path_factory):
    """Sim3 alignment on two datasets: `stereo` declared metric, its estimates at half scale (the
    Sim3 check warns); `mono` undeclared, at 1.02 scale (healthy)."""
    root = tmp_path_factory.mktemp("sim3")
    cfg = settings.resolve(
        {
            "truth_dir": str(root / "truth"),
            "algorithms_dir": str(root / "algs"),
            "align": {"method": "sim3"},
            "sync": {"estimate_offset": False},
            "calibrate": {"enabled": False},
            "sources": {"algorithms": {"stereo": {"metric_scale": True}}},
            "report": {"per_case": False},
        }
    )
    ref = smooth_path()
    cases = []
    for k, ds in enumerate(("hall", "office")):
        files.write_trajectory(root / f"truth/{ds}.txt", ref, "tum")
        for alg, scale in (("stereo", 0.5), ("mono", 1.02)):
            est = root / f"algs/{alg}/{ds}/run1.txt"
            files.write_trajectory(est, _estimate(ref, scale, 0.01, seed=k), "tum")
            cases.append(
                {
                    "key": f"{alg}/{ds}/run1",
                    "truth": str(root / f"truth/{ds}.txt"),
                    "estimate": str(est),
                    "truth_source": readers.options(cfg, "reference", dataset=ds),
                    "estimate_source": readers.options(cfg, "estimate", algorithm=alg),
                }
            )
    out = root / "results"
    run_stages(cases, out, cfg, stages=chain.NAMES[:-1])
    assert tables.make(sorted(c["key"] for c in cases), out, cfg) == []
    return out, cfg


def test_a_flagged_case_marks_its_cells_in_every_table(sim3_grid):
    out, cfg = sim3_grid
    frame = epa.read_cells(out)
    table_cells = frame[~frame.metric.isin(["cases", "alignment"])]
    stereo = table_cells[(table_cells.algorithm == "stereo") & table_cells.value.notna()]
    mono = table_cells[table_cells.algorithm == "mono"]
    assert len(stereo) > 50 and set(stereo.marks) == {"f"}  # every table, one case a cell
    assert set(mono.marks) == {""}
    for name in tables.cell_tables(cfg):
        tex = (out / f"tables/{name}.tex").read_text()
        if "\nstereo" in tex and re.search(r"\nstereo[^\n]*\d", tex):
            assert (
                "\\textsuperscript{f}" in tex
                and "holds a flagged case: a metric warned (sim3\\_check" in tex
            ), name
    # the Sim3 rows and their scales, in the footnote and in cells.csv
    scales = frame[frame.metric == "alignment"].set_index(["algorithm", "dataset"])
    assert scales.loc[("stereo", "hall"), "value"] == pytest.approx(2.0, rel=0.01)
    assert scales.loc[("mono", "office"), "value"] == pytest.approx(1 / 1.02, rel=0.01)
    s = frame[frame.metric == "alignment"].groupby("algorithm").value.mean()
    ate = (out / "tables/ate.tex").read_text()
    assert (
        f"Sim3-aligned rows (mean Sim3 scale of their cases): mono {s['mono']:.3f}, stereo {s['stereo']:.3f}"
        in ate
    )
    text = (out / "error_comparison.txt").read_text()
    assert "\nstereo & " in text and "[f] holds a flagged case" in text
    assert text.endswith(
        "FLAGGED (A METRIC WARNED, SEE summary.csv NOTES): 2 of 4 cases with a result\n"
        + "=" * 44
        + "\n"
    )
    assert "FELL BACK" not in text


def test_the_end_of_run_summary_names_each_flagged_case_and_its_fix(sim3_grid):
    out, _ = sim3_grid
    lines = tables.failure_report(out / "summary.csv").splitlines()
    assert lines[:3] == [
        "epica: every case has a result (4 cases)",
        "epica: cases evaluated without Steps 1-2 or flagged (marked in the tables; cells.csv):",
        "  stereo: 0 of 2 cases fell back to the ov_eval way (Step 1 or 2 not trusted), 2 flagged",
    ]
    assert [line.split(": ")[0] for line in lines[3:]] == [
        "  stereo/hall/run1",
        "  stereo/office/run1",
    ]
    assert all("sim3_check: Sim3 scale 2" in line and "metric_scale" in line for line in lines[3:])
    assert len(tables.failure_report(out / "summary.csv", most=1).splitlines()) == 5
    assert tables.failure_report(out / "summary.csv", most=1).endswith("  ... and 1 more flagged")


def test_rpg_tables_mark_their_cells_as_the_others_do():
    from epa.outputs.tables import rpg

    flagged = _case("r1", method="sim3", scale=3.0, sim3_check={"warning": "w"})
    held = [[[_case("r2"), _case("r3")], [flagged]], [[_case("r4")], []]]
    tex = rpg._tex("T", [["0.100", "0.200"], ["0.300", "-"]], ["a", "b"], ["x", "y"], "hline", held)
    lines = tex.splitlines()
    assert lines[3:5] == [r"a & 0.100 & 0.200\textsuperscript{f} \\", r"b & 0.300 & - \\"]
    assert lines[5] == r"\hline" and "holds a flagged case" in lines[6]
    assert lines[7] == (
        r"\multicolumn{3}{l}{\footnotesize Sim3-aligned rows (mean Sim3 scale of their cases):"
        r" a 3.000} \\"
    )
    # without marks: the table as it was
    plain = rpg._tex("T", [["0.100"]], ["a"], ["x"], "hline", [[[_case("r5")]]])
    assert plain == rpg._tex("T", [["0.100"]], ["a"], ["x"], "hline")
    assert plain.splitlines()[-2:] == [r"a & 0.100 \\", r"\end{tabular}"]


# ----------------------------------------------------------------------------- real data
GT = "rpng_open_vins/ov_data/euroc_mav/MH_01_easy.txt"
ORB = "spsingh37_ORB_SLAM3_ubuntu22/f_dataset-MH01_{}.txt"


def _warned(record: dict) -> bool:
    """Whether any metric's record in metrics.json carries a warning (the test's own reading)."""
    return any(isinstance(v, dict) and v.get("warning") for v in record.values())


def test_real_orb_slam3_mono_and_stereo_pooled_in_one_cell_are_marked(data, tmp_path):
    """ORB-SLAM3 mono and stereo on EuRoC MH_01 as two runs of one algorithm, default settings: the
    monocular run's Step 2 is not trusted (its scale), so it is evaluated the ov_eval way and its
    cell pools two evaluations; the stereo-only algorithm's row is one recipe. The expected marks
    are read from each case's metrics.json, not from the tables' code."""
    import json

    (tmp_path / "truth").mkdir()
    (tmp_path / "truth/MH_01.txt").symlink_to(data / GT)
    runs = {"orb/MH_01/mono": "mono", "orb/MH_01/stereo": "stereo", "stereo/MH_01/run1": "stereo"}
    for key, kind in runs.items():
        (tmp_path / "algorithms" / key).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "algorithms" / f"{key}.txt").symlink_to(data / ORB.format(kind))
    cfg = settings.resolve(
        {
            "truth_dir": str(tmp_path / "truth"),
            "algorithms_dir": str(tmp_path / "algorithms"),
            "report": {"per_case": False},
        }
    )
    cases = [
        {
            "key": k,
            "truth": str(tmp_path / "truth/MH_01.txt"),
            "estimate": str(tmp_path / f"algorithms/{k}.txt"),
        }
        for k in runs
    ]
    out = tmp_path / "results"
    run_stages(cases, out, cfg, stages=chain.NAMES[:-1])
    assert tables.make(sorted(runs), out, cfg) == []
    m = {k: json.loads((out / "cases" / k / "06_metrics/metrics.json").read_text()) for k in runs}
    assert m["orb/MH_01/mono"]["eval_source"] == "ov_eval"  # Step 2 not trusted: its scale
    assert m["orb/MH_01/stereo"]["eval_source"] == "epa"

    def expected(keys):
        letters = []
        if len({m[k]["eval_source"] for k in keys}) > 1:
            letters.append("e")
        if len({m[k]["alignment"]["method"] for k in keys}) > 1:
            letters.append("a")
        if any(_warned(m[k]) for k in keys):
            letters.append("f")
        return ",".join(letters)

    orb, stereo = expected(["orb/MH_01/mono", "orb/MH_01/stereo"]), expected(["stereo/MH_01/run1"])
    assert orb.startswith("e")
    frame = epa.read_cells(out)
    ate = frame[frame.metric == "ate"].groupby("algorithm").marks.agg(set)
    assert ate["orb"] == {orb} and ate["stereo"] == {stereo}
    tex = (out / "tables/ate.tex").read_text()
    assert f"\\textsuperscript{{{orb}}} \\\\" in next(
        r for r in tex.splitlines() if r.startswith("orb &")
    )
    assert "pools cases evaluated differently (epa, ov\\_eval;" in tex
    fell_back = sum(bool(r["calibrate"]["plan"]["fallback"]) for r in m.values())
    text = (out / "error_comparison.txt").read_text()
    assert (
        f"FELL BACK (STEP 1 OR 2 NOT TRUSTED, EVALUATED THE OV_EVAL WAY): {fell_back} of 3" in text
    )
    report = tables.failure_report(out / "summary.csv")
    assert f"  orb: {fell_back} of 2 cases fell back to the ov_eval way" in report


def test_error_comparison_counts_only_what_there_is():
    from epa.outputs.tables.text import count_lines

    plain = [_case("r1"), _case("r2")]
    assert count_lines(plain) == []  # the file ends as it always did
    fell_back = _case("r3", source="ov_eval", fallback=True)
    by_choice = _case("r4", source="ov_eval")  # mode ov_eval: no fallback
    warned = _case("r5", kitti={"warning": "w"})
    failed = CaseResult(Case.unchecked("alg/ds/r6"), status="failed: load: x")
    assert count_lines([*plain, fell_back, by_choice, warned, failed]) == [
        "FELL BACK (STEP 1 OR 2 NOT TRUSTED, EVALUATED THE OV_EVAL WAY): 1 of 5 cases with a result",
        "FLAGGED (A METRIC WARNED, SEE summary.csv NOTES): 1 of 5 cases with a result",
        "=" * 44,
    ]
