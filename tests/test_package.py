"""A reviewer's path (docs/reproducibility.md): results whose inputs moved are verified with
`epa verify --data NEWROOT`; `epa pack` writes one archive that `epa verify ARCHIVE` unpacks,
regenerates and compares, with the inputs inside (`--with-inputs`) or found under `--data`; bad
archives and wrong inputs are one line naming them.

One 4-case grid (2 algorithms x 2 runs of drone_figure8) made with absolute folders, then moved with
its data to another folder, as a copy to another machine does."""

import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import catalogue
import pytest
import yaml

from epa.cli import main as cli
from epa.workflow import package

ROOT = Path(__file__).resolve().parents[1]
EXPECT = {key: expect for key, _, expect in catalogue.PACKAGE_ROWS}  # docs/bad-inputs.md's rows
RUN_HERE = {  # each row of the catalogue's package section is run by a test below
    "not-an-archive",
    "cut-archive",
    "newer-package",
    "manifest-not-a-file",
    "escaping-member",
    "wrong-hash-input",
    "input-not-found",
    "tampered-package",
    "unlisted-member",
}
CASES = [
    ("vio_body", "drone_figure8", "run1.txt"),
    ("vio_body", "drone_figure8", "run1_timing.txt"),
    ("vio_body", "drone_figure8", "run2.txt"),
    ("vo_drifty", "drone_figure8", "run1.txt"),
    ("vo_drifty", "drone_figure8", "run2.txt"),
]


@pytest.fixture(scope="module")
def moved(tmp_path_factory):
    """The grid made under ``before/`` with absolute folders, then ``before/`` moved to ``after/``."""
    top = tmp_path_factory.mktemp("reviewer")
    before = top / "before"
    data = before / "data"
    (data / "truth").mkdir(parents=True)
    shutil.copy(ROOT / "example/truth/drone_figure8.txt", data / "truth")
    for alg, ds, name in CASES:
        (data / "algorithms" / alg / ds).mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / "example/algorithms" / alg / ds / name, data / "algorithms" / alg / ds)
    cfg = {
        "truth_dir": str(data / "truth"),
        "algorithms_dir": str(data / "algorithms"),
        "results_dir": str(before / "results"),
        "efficiency": {"sensor_rate_hz": 20},
    }
    (before / "config.yaml").write_text(yaml.safe_dump(cfg))
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile")]
    cmd += ["tables", "provenance"]  # the tables and provenance.json, without figures and paper
    cmd += ["--configfile", str(before / "config.yaml"), "--cores", "2"]
    run = subprocess.run(cmd, cwd=before, env=env, capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, (run.stdout + run.stderr)[-3000:]
    after = top / "after"
    shutil.move(before, after)
    return after


def test_provenance_records_each_input_relative_to_its_folder(moved):
    doc = json.loads((moved / "results/provenance.json").read_text())
    run1 = next(r for r in doc["inputs"] if r["path"].endswith("vio_body/drone_figure8/run1.txt"))
    assert run1["folder"] == "algorithms_dir"
    assert run1["relative"] == "vio_body/drone_figure8/run1.txt"
    truth = next(r for r in doc["inputs"] if r["folder"] == "truth_dir")
    assert truth["relative"] == "drone_figure8.txt"


def test_moved_results_verify_with_the_new_root(moved, capsys):
    assert cli.main(["verify", str(moved / "results")]) == 1
    out = capsys.readouterr().out
    assert "missing: " in out and "not re-run" in out
    report = moved / "verify.json"
    args = ["verify", str(moved / "results"), "--data", str(moved), "--json", str(report)]
    assert cli.main(args) == 0
    out = capsys.readouterr().out
    assert "6 of 6 inputs found by sha256" in out
    assert f"at {moved / 'data/algorithms/vio_body/drone_figure8/run1.txt'}" in out
    assert "REPRODUCED within the numeric contract" in out
    doc = json.loads(report.read_text())
    assert doc["verdict"] == "REPRODUCED within the numeric contract"
    # the estimate's path in load.json reads as recorded, though it was read from elsewhere
    load = next(f for f in doc["files"] if f["file"].endswith("run1/01_load/load.json"))
    assert load["verdict"] == "identical"
    assert {row["file"] for row in doc["table"]} >= {"summary.csv", "error_comparison.txt"}


def test_a_package_verifies_elsewhere_with_data_and_with_its_inputs(
    moved, tmp_path, capsys, monkeypatch
):
    bare = tmp_path / "paper-results.tar.gz"
    assert cli.main(["pack", str(moved / "results"), "-o", str(bare)]) == 0
    full = tmp_path / "full.tar.gz"
    args = ["pack", str(moved / "results"), "-o", str(full), "--with-inputs", "--data", str(moved)]
    assert cli.main(args) == 0
    said = capsys.readouterr().out
    assert "and 6 inputs (" in said and "MB, once per content) into" in said
    with tarfile.open(bare) as tar:
        names = tar.getnames()
        readme = tar.extractfile("REPRODUCE.md").read().decode()
    assert {"package.json", "REPRODUCE.md", "requirements.lock"} <= set(names)
    assert "results/summary.csv" in names and "results/provenance.json" in names
    assert not any(n.startswith("inputs/") for n in names)
    assert "epa verify paper-results.tar.gz --data" in readme
    assert "pip install --require-hashes -r requirements.lock" in readme
    elsewhere = tmp_path / "reviewer"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert cli.main(["verify", str(bare), "--data", str(moved / "data")]) == 0
    assert "REPRODUCED" in capsys.readouterr().out
    assert cli.main(["verify", str(full)]) == 0
    out = capsys.readouterr().out
    assert "6 of 6 inputs found by sha256" in out and "REPRODUCED" in out
    assert (elsewhere / "full.verify.json").is_file()


def _rewrite_archive(src: Path, dst: Path, change) -> Path:
    with tarfile.open(src) as tar, tarfile.open(dst, "w:gz") as out:
        for m in tar.getmembers():
            data = tar.extractfile(m).read() if m.isfile() else None
            if data is not None:
                data = change(m.name, data)
                m.size = len(data)
            out.addfile(m, io.BytesIO(data) if data is not None else None)
    return dst


def test_a_tampered_package_is_not_verified(moved, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # where its verify.json goes
    good = package.pack(moved / "results", tmp_path / "p.tar.gz")

    def one_digit(name, data):
        if name != "results/tables/ate.tex":
            return data
        text = data.decode()
        k = text.index(".") + 3
        return (text[:k] + str((int(text[k]) + 5) % 10) + text[k + 1 :]).encode()

    bad = _rewrite_archive(good, tmp_path / "tampered.tar.gz", one_digit)
    assert cli.main(["verify", str(bad), "--data", str(moved / "data")]) == 1
    out = capsys.readouterr().out
    assert "unpacked" in out and f"({EXPECT['tampered-package']})" in out
    assert "differs: tables/ate.tex: first line " in out and "NOT VERIFIED" in out


def test_a_member_the_package_does_not_list_is_named_and_never_extracted(
    moved, tmp_path, capsys, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    good = package.pack(moved / "results", tmp_path / "p.tar.gz")
    added = tmp_path / "added.tar.gz"
    with tarfile.open(good) as tar, tarfile.open(added, "w:gz") as out:
        for m in tar.getmembers():
            out.addfile(m, tar.extractfile(m) if m.isfile() else None)
        huge = tarfile.TarInfo("results/huge.bin")
        huge.size = 1 << 20
        out.addfile(huge, io.BytesIO(b"\0" * huge.size))
    extracted = []
    real = tarfile.TarFile.extractall

    def spy(self, path=".", members=None, **kw):
        members = list(members if members is not None else self.getmembers())
        extracted.extend(m.name for m in members)
        return real(self, path, members, **kw)

    monkeypatch.setattr(tarfile.TarFile, "extractall", spy)
    assert cli.main(["verify", str(added), "--data", str(moved / "data")]) == 1
    out = capsys.readouterr().out
    assert "1 archive members not listed in package.json, not extracted" in out
    assert "\n  results/huge.bin\n" in out
    assert f"epa verify: {EXPECT['unlisted-member']} (the verdicts: " in out
    assert "REPRODUCED" not in out
    assert "results/summary.csv" in extracted and "results/huge.bin" not in extracted
    doc = json.loads((tmp_path / "added.verify.json").read_text())
    assert doc["unlisted_members"] == ["results/huge.bin"]
    assert doc["verdict"] == EXPECT["unlisted-member"]
    # the same package without the member: reproduced, nothing unlisted
    assert cli.main(["verify", str(good), "--data", str(moved / "data")]) == 0
    assert "not listed" not in capsys.readouterr().out
    assert json.loads((tmp_path / "p.verify.json").read_text())["unlisted_members"] == []


def test_bad_packages_and_inputs_are_one_line(moved, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    good = package.pack(moved / "results", tmp_path / "p.tar.gz")
    not_one = tmp_path / "notes.tar.gz"
    not_one.write_text("not an archive\n")
    cut = tmp_path / "cut.tar.gz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])

    def newer(name, data):
        if name != "package.json":
            return data
        return json.dumps({**json.loads(data), "epica": "99.0.0"}).encode()

    future = _rewrite_archive(good, tmp_path / "future.tar.gz", newer)
    folder = tmp_path / "folder.tar.gz"
    with tarfile.open(folder, "w:gz") as tar:
        member = tarfile.TarInfo("package.json")
        member.type = tarfile.DIRTYPE
        tar.addfile(member)
    capsys.readouterr()
    for archive, key in (
        (not_one, "not-an-archive"),
        (cut, "cut-archive"),
        (future, "newer-package"),
        (folder, "manifest-not-a-file"),
    ):
        said = EXPECT[key]
        assert cli.main(["verify", str(archive), "--data", str(moved / "data")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and str(archive) in err and said in err, err
    assert not (tmp_path.parent / "x").exists()
    # an input with the right name and other bytes
    wrong = tmp_path / "wrong_data"
    shutil.copytree(moved / "data", wrong)
    run2 = wrong / "algorithms/vo_drifty/drone_figure8/run2.txt"
    run2.write_text(run2.read_text() + "\n")
    args = ["verify", str(moved / "results"), "--data", str(wrong), "--json", "v.json"]
    assert cli.main(args) == 1
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if "wrong hash" in line]
    assert len(lines) == 1 and f"{EXPECT['wrong-hash-input']}{run2}" in lines[0]
    assert "NOT VERIFIED" in out
    # an input that is nowhere under --data
    run2.unlink()
    assert cli.main(args) == 1
    out = capsys.readouterr().out
    recorded = "/before/data/algorithms/vo_drifty/drone_figure8/run2.txt ("
    lines = [line for line in out.splitlines() if EXPECT["input-not-found"] in line]
    assert len(lines) == 1 and recorded in lines[0] and "NOT VERIFIED" in out


def test_every_package_row_of_the_catalogue_is_run_here():
    assert set(EXPECT) == RUN_HERE
