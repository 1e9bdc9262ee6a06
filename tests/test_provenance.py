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


def _safe_dump(data) -> str:
    import yaml

    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)


def test_the_resolved_config_is_written_as_pyyaml_writes_it():
    """config.resolved.yaml without PyYAML (provenance._plain_yaml) is PyYAML's text, on the defaults,
    the example's and the test configs, and configs with names, paths, lists and numbers changed."""
    from epa.workflow import settings

    configs = [settings.defaults()]
    for path in [ROOT / "config" / "config.yaml", *sorted((ROOT / ".test").glob("*.yaml"))]:
        if path.is_file():
            configs.append(settings.from_configfile(path))
    edited = settings.defaults()
    edited.update(truth_dir="../data/truth", algorithms_dir="/data/runs_2024/v1.2", mode="rpg")
    edited["metrics"]["segments"] = [0.5, 1e-05, 1e17, -0.0, 3, 2.5e300]
    edited["sources"]["algorithms"]["ov-vio_stereo"] = {"topic": "/ov_msckf/poseimu"}
    configs.append(edited)
    for cfg in configs:
        data = json.loads(json.dumps(cfg))
        plain = provenance._plain_yaml(data)
        # a key PyYAML quotes (an override's glob, `vo_*/urban_drive`) is left to PyYAML
        quoted = any("*" in k for k in _keys(data.get("overrides") or {}))
        assert (plain is None) is quoted and (quoted or plain == _safe_dump(data))
        assert provenance.config_yaml(cfg).endswith(_safe_dump(data))


def _keys(tree: dict):
    for k, v in tree.items():
        yield k
        if isinstance(v, dict):
            yield from _keys(v)


def test_plain_yaml_writes_pyyaml_text_or_leaves_it_to_pyyaml():
    """On random documents: where _plain_yaml writes a text it is PyYAML's (strings that PyYAML
    quotes or folds, numbers that look like strings, nested lists are left to PyYAML)."""
    rng = np.random.default_rng(5)
    pool = list("abyYnN_./-0:1 #'\"e~é") + [
        "yes", "No", "on", "null", "true", ".inf", ".5", "1e3", "0x1f", "2024-01-02", "./a", "..",
        "a" * 120, "x y", "-a", "_", "12:30", "=", "<<", "", "/ov/pose", "E5", "nan", ".", ".a/b",
        ".INF", ".Nan", "._x", ".1", ".e5",
    ]  # fmt: skip

    def value(depth):
        kind = rng.integers(0, 9 if depth < 3 else 6)
        if kind == 0:
            return "".join(rng.choice(pool, rng.integers(1, 4)))
        if kind == 1:
            return float(rng.choice([0.1, 1e-5, 1e16, 1e17, -0.0, 2.0, 1 / 3, 123456789.0]))
        if kind == 2:
            return int(rng.integers(-5, 10**6))
        if kind in (3, 4):
            return [None, True, False][kind - 3 + int(rng.integers(0, 2))]
        if kind == 5:
            return str(rng.choice(pool))
        if kind in (6, 7):
            return {
                str(rng.choice(pool)) + str(k): value(depth + 1) for k in range(rng.integers(0, 4))
            }
        return [value(depth + 2) for _ in range(rng.integers(0, 4))]

    written = 0
    for _ in range(3000):
        doc = {str(rng.choice(pool)) + str(k): value(0) for k in range(rng.integers(1, 5))}
        text = provenance._plain_yaml(doc)
        if text is not None:
            assert text == _safe_dump(doc), doc
            written += 1
    assert written > 150  # the plain forms were met


def test_package_versions_are_importlib_metadata_s():
    """provenance.versions reads the plain dist-info folders itself: the same versions (or None)
    as importlib.metadata, also for names spelled otherwise and for one not installed."""
    import importlib.metadata

    names = (*provenance.RUNTIME_PACKAGES, "PyYAML", "Snakemake", "epica", "pip", "not-installed-x")

    def meta(name):
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return None

    assert provenance.versions(names) == {name: meta(name) for name in names}
    fast = provenance._dist_info_versions(names)
    assert {"numpy", "pyyaml"} <= fast.keys() and "not-installed-x" not in fast
