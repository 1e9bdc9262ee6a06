"""Paper results that regenerate (docs/reproducibility.md): provenance.json, `epa verify`, the lock
file, the paper bundle, the same bytes whatever --cores or batches.

The grid tests run Snakemake on a 4-case grid cut from the bundled example (2 algorithms x 1 dataset
x 2 runs): once with --cores 2, again by `epa verify` with --cores 1, once more in 3 batches.
"""

import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml
from packaging.requirements import Requirement
from packaging.version import Version

from epa.cli import main as cli
from epa.outputs import contract, paper, provenance
from epa.outputs.tables.latex import restyle
from epa.workflow import settings, verify

ROOT = Path(__file__).resolve().parents[1]
SRC = str(ROOT / "src")
PDFLATEX = shutil.which("pdflatex")


# ----------------------------------------------------------------------------- the lock file
def _lock() -> dict[str, tuple[str, list[str]]]:
    """requirements.lock as {name: (version, hashes)}."""
    text = (ROOT / "requirements.lock").read_text().replace("\\\n", " ")
    out = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        spec, *opts = line.split()
        name, version = spec.split("==")
        hashes = [o.split("=", 1)[1] for o in opts if o.startswith("--hash=")]
        out[name.lower().replace("_", "-")] = (version, hashes)
    return out


def test_the_lock_pins_every_runtime_dependency_within_pyproject_ranges_with_hashes():
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    lock = _lock()
    for dep in map(Requirement, deps):
        name = dep.name.lower().replace("_", "-")
        assert name in lock, f"{name} is not in requirements.lock"
        version, _ = lock[name]
        assert dep.specifier.contains(Version(version), prereleases=True), (dep, version)
    for name, (version, hashes) in lock.items():
        assert hashes and all(re.fullmatch(r"sha256:[0-9a-f]{64}", h) for h in hashes), name
        Version(version)  # an exact, valid version
    assert "--find-links" not in (ROOT / "requirements.lock").read_text()  # PyPI only


def test_the_conda_env_of_the_script_rules_has_the_lock_versions():
    env = yaml.safe_load((ROOT / "envs" / "epica.yaml").read_text())
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict))
    lock = _lock()
    pins = dict(p.split("==") for p in pip)
    assert set(pins) == set(provenance.RUNTIME_PACKAGES) - {"snakemake"}
    for name, version in pins.items():
        assert lock[name][0] == version, (name, version, lock[name][0])


# ----------------------------------------------------------------------------- provenance
def test_provenance_is_the_same_outside_its_volatile_fields(tmp_path):
    f = tmp_path / "in.txt"
    f.write_text("1 0 0 0 0 0 0 1\n")
    cfg = settings.resolve({"truth_dir": "t", "algorithms_dir": "a"})
    a = provenance.document("grid", cfg, [f, tmp_path / "gone.txt"], workflow_dir=ROOT)
    b = provenance.document("grid", cfg, [tmp_path / "gone.txt", f], workflow_dir=ROOT)
    assert provenance.stable(a) == provenance.stable(b)
    assert set(a["volatile"]) == set(provenance.VOLATILE)
    assert a["inputs"][0]["missing"] and a["inputs"][1]["size"] == f.stat().st_size
    assert set(a["packages"]) == set(provenance.RUNTIME_PACKAGES)
    assert all(a["packages"].values())
    provenance.write(tmp_path / "r", a)
    again = settings.resolve(settings.load_yaml(tmp_path / "r" / provenance.CONFIG))
    assert again == cfg  # the resolved config resolves to itself: every setting is there


# ----------------------------------------------------------------------------- paper bundle
def _compile(folder: Path) -> None:
    run = subprocess.run(
        [PDFLATEX, "-interaction=nonstopmode", "-halt-on-error", "paper.tex"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-3000:]
    assert (folder / "paper.pdf").stat().st_size > 1000


def test_booktabs_style_keeps_the_rows_and_changes_only_the_rules():
    tex = "% T\n\\begin{tabular}{lc}\n & \\textbf{a} \\\\ \\hline\nx & 1 \\\\\n\\end{tabular}\n"
    assert restyle(tex, "hline") == tex
    b = restyle(tex, "booktabs")
    assert b.split("\n") == [
        "% T",
        "\\begin{tabular}{lc}",
        "\\toprule",
        " & \\textbf{a} \\\\ \\midrule",
        "x & 1 \\\\",
        "\\bottomrule",
        "\\end{tabular}",
        "",
    ]


@pytest.mark.skipif(PDFLATEX is None, reason="pdflatex is not installed (texlive-latex-base)")
def test_a_paper_with_booktabs_and_spread_cells_compiles(tmp_path):
    (tmp_path / "tables").mkdir()
    (tmp_path / "figures").mkdir()
    tex = (
        "% FULL TRAJECTORY ATE [± SAMPLE STD OVER RUNS, n = RUNS]\n\\begin{tabular}{lcc}\n"
        " & \\textbf{drone\\_figure8} & \\textbf{Average} \\\\ \\hline\n"
        "vio\\_body & 0.254 ± 0.01 (n=2) / 0.070 & - / - \\\\\n\\end{tabular}\n"
    )
    (tmp_path / "tables" / "ate.tex").write_text(restyle(tex, "booktabs"), encoding="utf-8")
    written = paper.write_paper(tmp_path, {"ate": "ATE_of every run"})
    assert (tmp_path / "paper" / "tables" / "ate.tex") in written
    _compile(tmp_path / "paper")


# ----------------------------------------------------------------------------- the grid
CASES = [
    ("vio_body", "drone_figure8", "run1.txt"),
    ("vio_body", "drone_figure8", "run1_timing.txt"),
    ("vio_body", "drone_figure8", "run2.txt"),
    ("vio_body", "drone_figure8", "run2_timing.txt"),
    ("vo_drifty", "drone_figure8", "run1.txt"),
    ("vo_drifty", "drone_figure8", "run2.txt"),
]


def _snakemake(workdir: Path, configfile: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile")]
    cmd += ["--configfile", str(configfile), *args]
    run = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, (run.stdout + run.stderr)[-4000:]
    return run


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """A 4-case grid (relative paths, as a user's config gives them), run with --cores 2."""
    work = tmp_path_factory.mktemp("grid")
    (work / "truth").mkdir()
    shutil.copy(ROOT / "example/truth/drone_figure8.txt", work / "truth")
    for alg, ds, name in CASES:
        (work / "algorithms" / alg / ds).mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / "example/algorithms" / alg / ds / name, work / "algorithms" / alg / ds)
    cfg = {
        "truth_dir": "truth",
        "algorithms_dir": "algorithms",
        "results_dir": "results",
        "report": {"per_case": False},
        "efficiency": {"sensor_rate_hz": 20},
    }
    (work / "config.yaml").write_text(yaml.safe_dump(cfg))
    run = _snakemake(work, work / "config.yaml", "--cores", "2")
    return work, run.stdout + run.stderr


def test_the_end_of_a_run_says_where_the_results_are(grid):
    _, log = grid
    assert "epica: results in results/" in log
    for what in ("tables:", "comparison:", "figures:", "paper:", "snakemake --report"):
        assert what in log, what
    assert "every case has a result (4 cases)" in log


def test_provenance_json_records_the_grid(grid):
    work, _ = grid
    doc = provenance.read(work / "results")
    assert doc["kind"] == "grid" and doc["config"]["results_dir"] == "results"
    assert doc["config"]["sync"]["window"] == 2.0  # a default: every setting is resolved
    paths = [r["path"] for r in doc["inputs"]]
    assert paths == sorted(paths) and len(paths) == 7  # 1 reference, 4 runs, 2 timing files
    assert "algorithms/vio_body/drone_figure8/run1_timing.txt" in paths
    assert doc["epica"].get("git_commit") or not (ROOT / ".git").exists()
    assert "snakemake" in doc["volatile"]["command_line"]
    # no volatile field leaks into the tables
    for name in ("error_comparison.txt", "summary.csv", "comparison.txt"):
        text = (work / "results" / name).read_text()
        assert doc["volatile"]["created_utc"][:10] not in text
        assert str(work) not in text


def test_epa_verify_regenerates_every_table_byte_for_byte_with_one_core(grid, capsys):
    """On the machine that made them, --exact: the same bytes whatever --cores."""
    work, _ = grid
    assert verify.verify(work / "results", cores=1, exact=True) == 0
    out = capsys.readouterr().out
    assert "7 inputs have their recorded sha256" in out
    assert "epa verify: REPRODUCED byte for byte" in out
    assert "records: identical " in out and "differs" not in out


def test_epa_verify_names_a_tampered_record_and_a_tampered_table(grid, capsys):
    """A sixth significant digit in one metrics.json and one printed digit in a table: NOT
    VERIFIED, each named with its place; every other file passes the contract."""
    work, _ = grid
    tampered = work / "results_tampered"
    shutil.copytree(work / "results", tampered)
    metrics = tampered / "cases/vio_body/drone_figure8/run1/06_metrics/metrics.json"
    doc = json.loads(metrics.read_text())
    rmse = doc["ate"]["trans_m"]["rmse"]
    metrics.write_text(metrics.read_text().replace(repr(rmse), repr(rmse * (1 + 1e-5)), 1))
    table = tampered / "tables/ate.tex"
    text = table.read_text()
    number = re.search(r"\d\.\d{3}", text)
    last = number.end() - 1
    table.write_text(text[:last] + str((int(text[last]) + 3) % 10) + text[last + 1 :])
    assert cli.main(["verify", str(tampered)]) == 1
    out = capsys.readouterr().out
    assert (
        "differs: cases/vio_body/drone_figure8/run1/06_metrics/metrics.json: "
        "first $.ate.trans_m.rmse: " in out
    )
    assert "differs: tables/ate.tex: first line " in out
    assert out.count("differs: ") == 2 and "NOT VERIFIED" in out


def test_three_batches_write_the_same_bytes(grid):
    work, _ = grid
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg.update(results_dir="results_batched", grid={"max_batches": 3})
    (work / "batched.yaml").write_text(yaml.safe_dump(cfg))
    _snakemake(work, work / "batched.yaml", "--cores", "2", "tables")
    jobs = [
        len(list((work / r / "batches").rglob("efficiency.json")))
        for r in ("results", "results_batched")
    ]
    assert jobs[0] == 4 and 1 < jobs[1] <= 3  # one case per job, then 2-3 batches
    names = verify.compared_files(work / "results")
    assert len(names) > 20 and "cases/vo_drifty/drone_figure8/run2/06_metrics/metrics.json" in names
    compared = verify.compare(work / "results", work / "results_batched", exact=True)
    assert len(compared) == len(names)
    assert all(c.verdict == contract.Verdict.IDENTICAL for c in compared)


@pytest.mark.skipif(PDFLATEX is None, reason="pdflatex is not installed (texlive-latex-base)")
def test_the_paper_bundle_compiles(grid):
    work, _ = grid
    folder = work / "results" / "paper"
    tex = (folder / "paper.tex").read_text()
    assert "\\input{tables/ate.tex}" in tex and "figures/ate.pdf" in tex
    assert len(list((folder / "figures").glob("*.pdf"))) == 5
    _compile(folder)


def test_epa_verify_names_an_input_that_changed_or_is_missing(grid, capsys):
    work, _ = grid  # the last grid test: it edits the inputs
    run = work / "algorithms/vo_drifty/drone_figure8/run2.txt"
    with open(run, "a") as fh:
        fh.write("\n")
    (work / "algorithms/vio_body/drone_figure8/run1_timing.txt").unlink()
    assert cli.main(["verify", str(work / "results")]) == 1
    out = capsys.readouterr().out
    assert "changed: algorithms/vo_drifty/drone_figure8/run2.txt" in out
    assert "missing: algorithms/vio_body/drone_figure8/run1_timing.txt" in out
    assert "NOT VERIFIED" in out


def test_epa_eval_writes_and_verifies_its_case(tmp_path, capsys):
    out = tmp_path / "case"
    ref = ROOT / "example/truth/drone_figure8.txt"
    est = ROOT / "example/algorithms/vo_drifty/drone_figure8/run1.txt"
    assert cli.main(["eval", str(ref), str(est), "--out", str(out)]) == 0
    doc = provenance.read(out)
    assert doc["kind"] == "case" and len(doc["inputs"]) == 2
    assert (out / provenance.CONFIG).is_file()
    assert verify.verify(out, exact=True) == 0
    assert "REPRODUCED byte for byte" in capsys.readouterr().out


def test_epa_verify_names_the_version_that_made_results_that_differ(tmp_path, capsys):
    """Results recorded by another epica version whose numbers differ: the verdict says which
    versions (results made by epica X, this is Y), not only that they differ; with the same numbers
    they verify whatever the recorded version."""
    from epa import __version__
    from epa.artifacts import files

    out = tmp_path / "case"
    ref = ROOT / "example/truth/drone_figure8.txt"
    est = ROOT / "example/algorithms/vo_drifty/drone_figure8/run1.txt"
    assert cli.main(["eval", str(ref), str(est), "--out", str(out)]) == 0
    doc = provenance.read(out)
    doc["epica"]["version"] = "0.0.1"
    files.write_json(out / provenance.PROVENANCE, doc)
    assert verify.verify(out) == 0  # the same numbers: no word about versions
    said = capsys.readouterr().out
    assert "REPRODUCED within the numeric contract" in said and "made by epica" not in said
    metrics = files.read_json(out / "06_metrics/metrics.json")
    metrics["ate"]["trans_m"]["rmse"] *= 1.001
    files.write_json(out / "06_metrics/metrics.json", metrics)
    assert verify.verify(out, json_path=tmp_path / "verify.json") == 1
    said = capsys.readouterr().out
    versions = f"results made by epica 0.0.1, this is epica {__version__}"
    assert f"epa verify: NOT VERIFIED: {versions} (the verdicts:" in said
    assert "differs: 06_metrics/metrics.json: first $.ate.trans_m.rmse" in said
    assert files.read_json(tmp_path / "verify.json")["verdict"] == f"NOT VERIFIED: {versions}"
