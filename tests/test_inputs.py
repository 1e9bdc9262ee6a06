"""The three ways to name a grid's inputs (docs/inputs.md): the OpenVINS layout of truth_dir and
algorithms_dir, path patterns (inputs.reference / inputs.estimate), and a run sheet (inputs.sheet).
For the same files they give the same case names, results and tables: on the bundled example, and
on real files of ../shared/data left where they lie (the layout then made of symlinks)."""

import os
from pathlib import Path

import pytest
from conftest import run_stages

from epa.core.errors import EpaError
from epa.outputs import tables
from epa.workflow import chain, discovery, settings

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "example"
# the grid's printed outputs that must be the same text whichever way the inputs are named
COMPARED = ("summary.csv", "error_comparison.txt", "comparison.txt", "tables/ate.tex")


def run_grid(cfg: dict, out: Path) -> tuple[list[str], dict[str, str]]:
    """Discover the cases of ``cfg`` and run every stage but the report, then the tables, in this
    process as tests/test_golden.py does; returns the case keys and the compared outputs."""
    cfg = settings.resolve(cfg)
    _, cases = discovery.discover_config(cfg, say=lambda line: None)
    batch = []
    for c in cases:
        truth_source, estimate_source = discovery.sources_of(cfg, c)
        batch.append(
            {
                "key": c.key,
                "truth": str(c.truth),
                "estimate": str(c.estimate),
                "truth_source": truth_source,
                "estimate_source": estimate_source,
            }
        )
    run_stages(batch, out, cfg, chain.NAMES[:-1])
    assert tables.make(sorted(c.key for c in cases), out, cfg) == []
    return [c.key for c in cases], {n: (out / n).read_text() for n in COMPARED}


def write_sheet(path: Path, rows: list[tuple], extra: dict[str, list[str]] | None = None) -> Path:
    """A sheet of (algorithm, dataset, run, estimate, reference) rows, plus optional columns."""
    extra = extra or {}
    header = ["algorithm", "dataset", "run", "estimate", "reference", *extra]
    lines = ["\t".join(header)]
    for k, row in enumerate(rows):
        lines.append("\t".join([*map(str, row), *(values[k] for values in extra.values())]))
    path.write_text("\n".join(lines) + "\n")
    return path


def example_sheet(path: Path) -> Path:
    _, cases = discovery.discover(EXAMPLE / "truth", EXAMPLE / "algorithms")
    rows = [(c.algorithm, c.dataset, c.run, c.estimate, c.truth) for c in cases]
    return write_sheet(path, rows)


EXAMPLE_PATTERNS = {
    "reference": f"{EXAMPLE}/truth/{{dataset}}.txt",
    # any order: the run's folder first, the algorithm's name repeated in the file's
    "estimate": [
        f"{EXAMPLE}/algorithms/{{algorithm}}/{{dataset}}/{{run}}.txt",
        f"{EXAMPLE}/algorithms/{{algorithm}}/{{dataset}}/{{run}}.csv",
    ],
}


def test_the_three_forms_find_the_same_example_cases(tmp_path, capsys):
    layout = settings.resolve(
        {"truth_dir": str(EXAMPLE / "truth"), "algorithms_dir": str(EXAMPLE / "algorithms")}
    )
    _, by_layout = discovery.discover_config(layout)
    _, by_patterns = discovery.discover_config(settings.resolve({"inputs": EXAMPLE_PATTERNS}))
    said = capsys.readouterr().err
    assert "inputs.estimate.0 " in said and ": 12 run(s)" in said and ": 6 run(s)" in said
    sheet = {"inputs": {"sheet": str(example_sheet(tmp_path / "runs.tsv"))}}
    _, by_sheet = discovery.discover_config(settings.resolve(sheet))
    files = [(c.key, c.truth, c.estimate) for c in by_layout]
    assert len(files) == 18
    assert [(c.key, c.truth, c.estimate) for c in by_patterns] == files
    assert [(c.key, c.truth, c.estimate) for c in by_sheet] == files


def test_the_three_forms_give_the_same_example_tables(tmp_path):
    base = {"metrics": {"segments": [8, 16]}, "efficiency": {"sensor_rate_hz": 20}}
    layout = {
        "truth_dir": str(EXAMPLE / "truth"),
        "algorithms_dir": str(EXAMPLE / "algorithms"),
        **base,
    }
    keys, want = run_grid(layout, tmp_path / "layout")
    patterns = {"inputs": EXAMPLE_PATTERNS, **base}
    assert run_grid(patterns, tmp_path / "patterns") == (keys, want)
    sheet = {"inputs": {"sheet": str(example_sheet(tmp_path / "runs.tsv"))}, **base}
    assert run_grid(sheet, tmp_path / "sheet") == (keys, want)
    # a timing file in the example travels with its run, whichever way it was found
    assert "vio_camera,drone_figure8,run1,ok" in want["summary.csv"]


RPG = "uzh-rpg_rpg_trajectory_evaluation/results/euroc_mono_stereo/laptop"
EUROC = "rpng_open_vins/ov_data/euroc_mav"
NAMES = {"MH_01": "MH_01_easy", "MH_03": "MH_03_medium"}  # rpg's names -> the references'


def test_real_files_where_they_lie_give_the_symlinked_layouts_tables(data, tmp_path, caplog):
    """rpg's tree (<algorithm>/laptop_<algorithm>_<dataset>/stamped_traj_estimate.txt, its own
    dataset names) against OpenVINS's EuRoC references: by patterns with a dataset map, by a sheet,
    and by the OpenVINS layout of symlinks a user would otherwise make."""
    runs = [
        (alg, ds, data / RPG / alg / f"laptop_{alg}_{short}/stamped_traj_estimate.txt")
        for alg in ("vio_mono", "vio_stereo")
        for short, ds in NAMES.items()
    ]
    for alg, ds, estimate in runs:
        link = tmp_path / "layout/algorithms" / alg / ds / "stamped_traj_estimate.txt"
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(estimate)
    (tmp_path / "layout/truth").mkdir()
    for ds in NAMES.values():
        (tmp_path / "layout/truth" / f"{ds}.txt").symlink_to(data / EUROC / f"{ds}.txt")
    base = {"align": {"method": "posyaw"}, "metrics": {"segments": [8, 16]}}
    layout = {
        "truth_dir": str(tmp_path / "layout/truth"),
        "algorithms_dir": str(tmp_path / "layout/algorithms"),
        **base,
    }
    keys, want = run_grid(layout, tmp_path / "by_layout")
    assert keys == [f"{alg}/{ds}/stamped_traj_estimate" for alg, ds, _ in runs]
    patterns = {
        "inputs": {
            "reference": f"{data / EUROC}/{{dataset}}.txt",
            "estimate": f"{data / RPG}/{{algorithm}}/laptop_{{algorithm}}_{{dataset}}/stamped_traj_estimate.txt",
            "datasets": NAMES,
        },
        **base,
    }
    assert run_grid(patterns, tmp_path / "by_patterns") == (keys, want)
    # MH_05 has estimates but no entry in the map: skipped, and said why
    assert "no reference for dataset 'MH_05'" in caplog.text
    rows = [
        (alg, ds, "stamped_traj_estimate", est, data / EUROC / f"{ds}.txt") for alg, ds, est in runs
    ]
    sheet = {"inputs": {"sheet": str(write_sheet(tmp_path / "runs.tsv", rows))}, **base}
    assert run_grid(sheet, tmp_path / "by_sheet") == (keys, want)


def test_a_sheet_rows_settings_reach_its_case(tmp_path):
    """A row's format and time unit are its estimate's source settings (the others keep the
    config's), and its timing file becomes the run's."""
    truth = EXAMPLE / "truth/drone_figure8.txt"
    est = EXAMPLE / "algorithms/vio_camera/drone_figure8/run1.csv"
    timing = EXAMPLE / "algorithms/vio_camera/drone_figure8/run1_timing.txt"
    rows = [("a", "drone_figure8", "r1", est, truth), ("b", "drone_figure8", "r1", est, truth)]
    extra = {"format": ["csv", ""], "time_unit": ["s", ""], "timing": [str(timing), ""]}
    cfg = settings.resolve({"inputs": {"sheet": str(write_sheet(tmp_path / "s.tsv", rows, extra))}})
    _, cases = discovery.discover_config(cfg, say=lambda line: None)
    first, second = (discovery.sources_of(cfg, c)[1] for c in cases)
    assert (first["format"], first["time_unit"]) == ("csv", "s")
    assert first["timing"] == str(timing.resolve())
    assert (second["format"], second["time_unit"], second["timing"]) == ("auto", "auto", None)


@pytest.mark.parametrize(
    ("cfg", "says"),
    [
        (
            {"truth_dir": "t", "algorithms_dir": "a", "inputs": {"sheet": "s.tsv"}},
            "truth_dir/algorithms_dir and inputs.sheet both name the inputs: keep one way",
        ),
        (
            {"inputs": {"estimate": "x/{algorithm}/{dataset}.txt"}},
            "inputs.estimate without inputs.reference",
        ),
        ({}, "names no inputs: truth_dir and algorithms_dir,"),
        (
            {"truth_dir": "t", "algorithms_dir": "a", "inputs": {"datasets": {"a": "b"}}},
            "inputs.datasets maps the estimate patterns' {dataset}: it needs inputs.estimate",
        ),
    ],
)
def test_the_way_to_name_inputs_is_one(cfg, says):
    with pytest.raises(EpaError) as err:
        settings.resolve(cfg, source="my.yaml")
    assert err.value.one_line() == f"my.yaml: {says}" or says in err.value.one_line()


def test_a_user_config_with_inputs_drops_the_bundled_folders(tmp_path):
    mine = tmp_path / "my.yaml"
    mine.write_text("inputs: {sheet: runs.tsv}\n")
    named = settings.check_user_configs([mine], {})
    merged = {
        "truth_dir": "example/truth",
        "algorithms_dir": "example/algorithms",
        "inputs": {"sheet": "runs.tsv"},
    }
    assert settings.without_bundled_folders(merged, named) == {"inputs": {"sheet": "runs.tsv"}}
    # folders the user names are kept (and then clash with the sheet: an error, not a guess)
    assert settings.without_bundled_folders(merged, named | {"truth_dir"}) == merged


def test_relative_patterns_start_at_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(EXAMPLE.parent)
    cfg = settings.resolve(
        {
            "inputs": {
                "reference": "example/truth/{dataset}.txt",
                "estimate": {"mine": "example/algorithms/vio_body/{dataset}/{run}.txt"},
            }
        }
    )
    _, cases = discovery.discover_config(cfg, say=lambda line: None)
    assert [c.key for c in cases][:2] == ["mine/drone_figure8/run1", "mine/drone_figure8/run2"]
    assert len(cases) == 6 and os.fspath(cases[0].estimate).startswith("example/")


def test_snakemakes_validate_takes_the_sheet_schema(tmp_path):
    """The sheet's schema is the one a workflow's `validate(sheet, schema)` takes: a good sheet
    passes, a value outside it fails there as in epica's own check."""
    import pandas
    from snakemake.exceptions import WorkflowError
    from snakemake.utils import validate

    from epa.workflow import sheet

    path = write_sheet(
        tmp_path / "runs.tsv", [("a", "seq", "1", "x.txt", "t.txt")], {"format": ["tum"]}
    )
    frame = pandas.read_csv(path, sep="\t", dtype=str, keep_default_na=False)
    validate(frame, str(sheet.SCHEMA_PATH))
    with pytest.raises(WorkflowError, match="'tum2' is not one of"):
        validate(frame.assign(format="tum2"), str(sheet.SCHEMA_PATH))


def test_wildcards_in_any_order_and_depth_with_a_dataset_map(tmp_path, caplog, capsys):
    """`{dataset}/run_{run}/{algorithm}.txt` under estimates named by their own dataset names; a
    folder and a file of a dataset without a reference are skipped, each said with its reason."""
    truth = EXAMPLE / "truth/drone_figure8.txt"
    for run in ("0", "1"):
        for alg in ("vio", "vo"):
            link = tmp_path / "out/fig8/deep" / f"run_{run}" / f"{alg}.txt"
            link.parent.mkdir(parents=True, exist_ok=True)
            link.symlink_to(EXAMPLE / f"algorithms/vio_body/drone_figure8/run{int(run) + 1}.txt")
    (tmp_path / "out/fig8/deep/run_2/x.txt").mkdir(parents=True)  # a folder, not a bag
    (tmp_path / "out/office/deep/run_0").mkdir(parents=True)
    (tmp_path / "out/office/deep/run_0/vio.txt").symlink_to(truth)  # no reference for office
    cfg = settings.resolve(
        {
            "inputs": {
                "reference": f"{EXAMPLE}/truth/{{dataset}}.txt",
                "estimate": f"{tmp_path}/out/{{dataset}}/deep/run_{{run}}/{{algorithm}}.txt",
                "datasets": {"fig8": "drone_figure8"},
            }
        }
    )
    _, cases = discovery.discover_config(cfg)
    assert [c.key for c in cases] == [
        "vio/drone_figure8/0",
        "vio/drone_figure8/1",
        "vo/drone_figure8/0",
        "vo/drone_figure8/1",
    ]
    assert cases[0].truth == truth
    assert "inputs.estimate" in capsys.readouterr().err
    assert "skipped 1: inputs.estimate: a folder, not a ROS 2 bag" in caplog.text
    assert "skipped 1: inputs.estimate: no reference for dataset 'office'" in caplog.text


def test_pattern_roots_and_their_new_places():
    from epa.outputs import provenance
    from epa.workflow import relocate

    inputs = {
        "reference": "/data/euroc/{dataset}/mav0/gt.csv",
        "estimate": {"ov": "/data/runs/ov/{dataset}/traj.txt", "orb": "res/{dataset}/{run}.txt"},
        "datasets": {"MH01": "MH_01_easy"},
    }
    roots = provenance.pattern_roots(inputs)
    # each root is the folder of its pattern's first wildcard; none of these lies inside another
    assert roots == {"root0": "/data/euroc", "root1": "/data/runs/ov", "root2": "res"}
    new = {k: f"/new/{k}" for k in roots}
    moved = relocate.moved_patterns(inputs, roots, new)
    assert moved == {
        "reference": "/new/root0/{dataset}/mav0/gt.csv",
        "estimate": {
            "ov": "/new/root1/{dataset}/traj.txt",
            "orb": "/new/root2/{dataset}/{run}.txt",
        },
        "datasets": {"MH01": "MH_01_easy"},
    }
    nested = {"reference": "d/{dataset}.txt", "estimate": "d/algs/{algorithm}/{dataset}/{run}.txt"}
    assert provenance.pattern_roots(nested) == {"root0": "d"}


def test_a_patterns_grid_packed_with_its_inputs_verifies(tmp_path):
    """`epa pack --with-inputs` and `epa verify` of a grid named by patterns: the inputs are laid
    out again under their patterns' roots and the grid re-runs to the same results."""
    import subprocess
    import sys

    (tmp_path / "d/algs/a/seq").mkdir(parents=True)
    (tmp_path / "d/seq.txt").write_bytes((EXAMPLE / "truth/drone_figure8.txt").read_bytes())
    run = EXAMPLE / "algorithms/vio_body/drone_figure8/run1.txt"
    (tmp_path / "d/algs/a/seq/run1.txt").write_bytes(run.read_bytes())
    (tmp_path / "cfg.yaml").write_text(
        "inputs:\n  reference: d/{dataset}.txt\n  estimate: d/algs/{algorithm}/{dataset}/{run}.txt\n"
        "report: {per_case: false}\n"
    )
    smk = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--cores", "2"]
    done = subprocess.run(
        [*smk, "--configfile", "cfg.yaml", "-d", "."], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    epa = [sys.executable, "-m", "epa.cli.main"]
    pack = [*epa, "pack", "results", "-o", "pkg.tar.gz", "--with-inputs"]
    subprocess.run(pack, cwd=tmp_path, check=True, capture_output=True)
    elsewhere = tmp_path / "reviewer"
    elsewhere.mkdir()
    verify = subprocess.run(
        [*epa, "verify", str(tmp_path / "pkg.tar.gz")],
        cwd=elsewhere,
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0, verify.stdout[-2000:] + verify.stderr[-2000:]
    assert "REPRODUCED" in verify.stdout + verify.stderr
