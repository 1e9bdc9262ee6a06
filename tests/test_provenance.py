"""provenance.json says what the numbers ran on (its ``numerics`` section) and records a commit as
epica's only from epica's own checkout (docs/reproducibility.md)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from epa.cli import main as cli
from epa.outputs import provenance
from epa.workflow import verify

ROOT = Path(__file__).resolve().parents[1]
GIT = shutil.which("git")
# the second CPU path of STYLE.md: numpy's dispatched SIMD off, OpenBLAS's Sandybridge kernels
RESTRICTED = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Sandybridge",
}
NUMERICS = "import json, numpy; from epa.outputs import provenance; print(json.dumps(provenance.numerics()))"


def _numerics_in_subprocess(extra_env: dict, code: str = NUMERICS) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in provenance.NUMERIC_ENV}
    env.update(extra_env)
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
    )
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def _git(folder, *args) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}
    identity = ["-c", "user.name=epica test", "-c", "user.email=test@example.org"]
    run = subprocess.run(
        [GIT, "-C", str(folder), *identity, *args], capture_output=True, text=True, env=env
    )
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


def _repository(folder: Path) -> str:
    """A git repository at ``folder`` with one commit of its files; returns that commit."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "README.md").write_text("a project that is not epica\n")
    _git(folder, "init", "-q")
    _git(folder, "add", "-A")
    _git(folder, "commit", "-q", "-m", "the user's commit")
    return _git(folder, "rev-parse", "HEAD")


def _lay_out_checkout(folder: Path) -> None:
    """The files that make a folder epica's checkout (the Snakefile, pyproject.toml, src/epa)."""
    (folder / "src/epa").mkdir(parents=True)
    (folder / "src/epa/__init__.py").write_text("")
    (folder / "Snakefile").write_text("")
    (folder / "pyproject.toml").write_text('[project]\nname = "epica"\n')


# ----------------------------------------------------------------------------- numerics
def test_the_numerics_section_says_what_the_numbers_ran_on():
    from numpy._core._multiarray_umath import __cpu_dispatch__

    doc = provenance.document("case", {}, [])
    num = doc["numerics"]
    assert set(num) == {"cpu", "simd", "blas", "lapack", "fft", "scipy_blas", "env"}
    assert num["cpu"]["model"] and num["cpu"]["machine"] == doc["platform"]["machine"]
    simd = num["simd"]
    assert simd["dispatched"] + simd["not_found"] == list(__cpu_dispatch__)  # a partition
    assert simd["baseline"] == np.show_config(mode="dicts")["SIMD Extensions"]["baseline"]
    built = np.show_config(mode="dicts")["Build Dependencies"]
    for key in ("blas", "lapack"):
        assert num[key]["name"] == built[key]["name"]
        assert num[key]["version"] == built[key]["version"]
    assert num["fft"] == {"library": "numpy.fft", "backend": "pocketfft", "numpy": np.__version__}
    assert num["env"] == {k: os.environ.get(k) for k in provenance.NUMERIC_ENV}
    if "openblas" in built["blas"]["name"] and Path("/proc/self/maps").is_file():
        blas = num["blas"]
        assert blas["core"] != provenance.UNKNOWN and blas["core"] in blas["config"]
        assert isinstance(blas["threads"], int) and blas["threads"] >= 1


def test_the_numerics_section_is_the_same_bytes_twice_and_whether_scipy_is_loaded_or_not():
    a, b = provenance.numerics(), provenance.numerics()
    assert json.dumps(a) == json.dumps(b)
    # scipy.special loads scipy's own OpenBLAS and scipy.__config__: neither may change the record
    loaded = _numerics_in_subprocess({}, "from scipy import special; " + NUMERICS)
    fresh = _numerics_in_subprocess({})
    assert loaded == fresh
    assert fresh["scipy_blas"]["name"]  # read without importing scipy


def test_the_numerics_section_records_a_restricted_cpu_path():
    default = _numerics_in_subprocess({})
    if "X86_V3" not in default["simd"]["dispatched"]:
        pytest.skip("this CPU has no X86_V3 (AVX2/FMA3) target for numpy to dispatch to")
    if default["blas"]["core"] == provenance.UNKNOWN:
        pytest.skip("numpy's BLAS is not an OpenBLAS loaded from a file /proc/self/maps lists")
    restricted = _numerics_in_subprocess(RESTRICTED)
    assert restricted["simd"]["dispatched"] == []
    assert restricted["simd"]["baseline"] == default["simd"]["baseline"]
    assert restricted["blas"]["core"] == "Sandybridge"
    assert restricted["lapack"]["core"] == "Sandybridge"
    assert restricted["env"]["OPENBLAS_CORETYPE"] == "Sandybridge"
    assert restricted["env"]["NPY_DISABLE_CPU_FEATURES"] == RESTRICTED["NPY_DISABLE_CPU_FEATURES"]
    assert default["env"]["NPY_DISABLE_CPU_FEATURES"] is None


# ----------------------------------------------------------------------------- epica's commit
@pytest.mark.skipif(GIT is None, reason="git is not installed")
def test_an_installed_package_inside_a_git_repository_records_no_commit(tmp_path):
    project = tmp_path / "project"
    commit = _repository(project)
    site = project / ".venv/lib/python3.11/site-packages"
    shutil.copytree(ROOT / "src/epa", site / "epa", ignore=shutil.ignore_patterns("__pycache__"))
    _lay_out_checkout(project)  # even an epica-looking project around it is not the package's
    out = tmp_path / "case"
    code = (
        "import sys, epa; from epa.cli import main as cli; print(epa.__file__);"
        " sys.exit(cli.main(sys.argv[1:]))"
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}
    env["PYTHONPATH"] = str(site)
    run = subprocess.run(
        [
            sys.executable,
            "-c",
            code,
            "eval",
            str(ROOT / "example/truth/drone_figure8.txt"),
            str(ROOT / "example/algorithms/vo_drifty/drone_figure8/run1.txt"),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        cwd=project,
        env=env,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines()[0].startswith(str(site))  # the copy ran, not this checkout
    doc = provenance.read(out)
    assert "git_commit" not in doc["epica"] and "git_dirty" not in doc["epica"], (commit, doc)
    assert doc["volatile"]["workflow_dir"] is None


@pytest.mark.skipif(GIT is None, reason="git is not installed")
def test_a_checkout_inside_another_repository_records_no_commit(tmp_path):
    outer = tmp_path / "outer"
    _lay_out_checkout(outer / "epica")
    _repository(outer)
    assert provenance.is_checkout(outer / "epica")
    assert provenance.checkout(outer / "epica") == {}  # the enclosing repository's is not epica's
    own = _repository(outer / "epica")
    assert provenance.checkout(outer / "epica") == {"git_commit": own, "git_dirty": False}
    (outer / "epica/Snakefile").write_text("# edited\n")
    assert provenance.checkout(outer / "epica")["git_dirty"] is True
    assert provenance.checkout(outer) == {}  # a repository, but not laid out as epica's checkout


def test_this_checkout_records_its_head(tmp_path):
    if provenance.source_checkout() != ROOT:
        pytest.skip("epica is not running from this checkout's src/ (an installed package)")
    assert verify.default_snakefile() == ROOT / "Snakefile"
    if GIT is None or not (ROOT / ".git").exists():
        pytest.skip("this checkout is not a git repository (or git is not installed)")
    head = _git(ROOT, "rev-parse", "HEAD")
    out = tmp_path / "case"
    ref = ROOT / "example/truth/drone_figure8.txt"
    est = ROOT / "example/algorithms/vo_drifty/drone_figure8/run1.txt"
    assert cli.main(["eval", str(ref), str(est), "--out", str(out)]) == 0
    doc = provenance.read(out)
    assert doc["epica"]["git_commit"] == head
    assert doc["volatile"]["workflow_dir"] == str(ROOT)
