"""Every row of the bad-input catalogue (tests/catalogue.py, docs/bad-inputs.md) run as a user would:
a one-line error naming the file (and line), exit status 2, no traceback and no partial output; or a
correct result with a note saying what was inferred. In a grid the other cases finish."""

import csv
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import bag_fixture
import catalogue
import pytest

from epa.artifacts.case import Case, CaseFolder
from epa.cli import main as cli
from epa.core.errors import EpaError
from epa.outputs import tables
from epa.workflow import chain, settings
from epa.workflow import discovery as cases
from epa.workflow import jobs as grid

ROOT = Path(__file__).resolve().parents[1]


def _write(path: Path, content) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content if isinstance(content, bytes) else content.encode())


def _no_partial_output(out: Path, metrics_stand: bool = False) -> None:
    for p in out.rglob("*"):
        assert not p.name.startswith("."), f"temporary file left behind: {p}"
    metrics = out / "06_metrics" / "metrics.json"
    if metrics_stand:  # a later stage's error: the accuracy is complete and stays
        assert "ate" in json.loads(metrics.read_text())
    elif metrics.exists():
        assert json.loads(metrics.read_text()).get("status") == "failed", (
            "a failed case has a metrics result"
        )


def _eval_paths(tmp: Path, b: catalogue.Bad) -> tuple[Path, Path, list[str]]:
    ref, est, extra = tmp / b.ref_name, tmp / b.est_name, []
    if b.setup != "missing-ref":
        _write(ref, b.ref)
    if b.setup == "kitti-times":
        est = tmp / "run" / b.est_name
        _write(tmp / "run" / "times.txt", "0\n0.1\n0.2\n0.3\n0.4\n")
    if b.est is not None:
        _write(est, b.est)
    if b.timing is not None:
        _write(est.with_name(est.stem + "_timing.txt"), b.timing)
    if b.setup and b.setup.startswith("bag"):
        est = _bag(tmp, est, b.setup)
        if b.setup == "bag-same":
            ref = est
    if b.setup == "missing-ref":
        _write(est, catalogue.GOOD)
    elif b.setup == "directory":
        est.mkdir()
    elif b.setup == "device":
        est.symlink_to("/dev/zero")
    elif b.setup == "dangling":
        est.symlink_to(tmp / "deleted.txt")
    elif b.setup == "through-file":
        _write(tmp / "est.txt", catalogue.GOOD)
        est = tmp / "est.txt" / "x.txt"
    elif b.setup == "long-name":
        est = tmp / ("a" * 300 + ".txt")
    if b.config is not None:
        _write(tmp / "cfg.yaml", b.config)
        extra = ["--config", str(tmp / "cfg.yaml")]
    elif b.setup == "missing-config":
        extra = ["--config", str(tmp / "cfg.yaml")]
    return ref, est, extra


def _traj(t, p, q):
    from epa.core.trajectory import Trajectory

    return Trajectory(t, p, q)


def _bag(tmp: Path, est: Path, setup: str) -> Path:
    """The catalogue's bag: /pose and /gt (PoseStamped), /tf (world -> body), /chatter (String), /empty."""

    good = _traj(catalogue.T, catalogue.P, catalogue.Q)
    storage = {"bag-sqlite3": "sqlite3", "bag-mcap": "mcap", "bag-no-db": "sqlite3"}.get(
        setup, "ros1"
    )
    if setup == "bag-one":
        bag_fixture.write_bag(est, {"/pose": ("geometry_msgs/msg/PoseStamped", good)})
        return est
    if setup == "bag-repeated":
        t = catalogue.T.copy()
        t[10] = t[9]
        bag_fixture.write_bag(
            est, {"/pose": ("geometry_msgs/msg/PoseStamped", _traj(t, catalogue.P, catalogue.Q))}
        )
        return est
    from rosbags.typesys import Stores, get_typestore

    string = get_typestore(Stores.ROS1_NOETIC if storage == "ros1" else Stores.ROS2_HUMBLE).types[
        "std_msgs/msg/String"
    ]
    bag_fixture.write_bag(
        est,
        {
            "/pose": ("geometry_msgs/msg/PoseStamped", good),
            "/gt": ("geometry_msgs/msg/PoseStamped", good),
            "/tf": ("tf2_msgs/msg/TFMessage", good),
            "/empty": ("geometry_msgs/msg/PoseStamped", _traj(good.t[:0], good.p[:0], good.q[:0])),
        },
        storage=storage,
        extra={"/chatter": ("std_msgs/msg/String", [(1, string(data="hello"))])},
    )
    if setup == "bag-truncated":
        data = est.read_bytes()
        est.write_bytes(data[: len(data) // 2])
    elif setup == "bag-no-db":
        for f in est.glob("*.db3"):
            f.unlink()
    return est


EVAL_ROWS = [b for b in catalogue.CATALOGUE if b.where in ("eval", "stage", "config")]


@pytest.mark.parametrize("b", EVAL_ROWS, ids=[b.id for b in EVAL_ROWS])
def test_epa_eval(tmp_path, capsys, caplog, monkeypatch, b):
    monkeypatch.chdir(tmp_path)  # where a config's code would leave its mark, were it run
    ref, est, extra = _eval_paths(tmp_path, b)
    out = tmp_path / "out"
    with caplog.at_level(logging.WARNING, logger="epa"):
        rc = cli.main(["eval", str(ref), str(est), "--out", str(out), *b.args, *extra])
    captured = capsys.readouterr()
    err = captured.err
    assert "Traceback" not in err and not (tmp_path / "HACKED").exists()
    if b.ok:
        assert rc == 0, err
        notes = [caplog.text, err, captured.out] + [p.read_text() for p in out.rglob("*.json")]
        assert any(b.expect in n for n in notes), f"{b.expect!r} not noted"
        return
    lines = [line for line in err.splitlines() if line.startswith("epa: error: ")]
    assert rc == 2 and len(lines) == 1, err
    assert b.expect in lines[0]
    blamed = {
        "est": est,
        "ref": ref,
        "config": tmp_path / "cfg.yaml",
        "none": "command line",
        "timing": est.with_name(est.stem + "_timing.txt"),
        "timing-arg": tmp_path / "nowhere_timing.txt",
    }
    who = "config" if b.where == "config" else b.blame
    assert lines[0].startswith(f"epa: error: {blamed[who]}"), lines[0]
    if out.exists():
        _no_partial_output(out, metrics_stand=b.keeps_accuracy)


# ----------------------------------------------------------------------------- grids
def _grid_folders(tmp: Path, setup: str) -> tuple[Path, Path, str | None]:
    """Two datasets with a good run each, plus the situation. Returns the folders and the bad case's key."""
    truth, algs = tmp / "truth", tmp / "algorithms"
    good = catalogue.GOOD
    _write(truth / "seq.txt", good)
    _write(truth / "other.txt", good)
    _write(algs / "good" / "seq" / "run1.txt", good)
    _write(algs / "good" / "other" / "run1.txt", good)
    bad = "bad/seq/run1"
    if setup == "grid-bad-run":
        _write(algs / "bad" / "seq" / "run1.txt", catalogue._replace_line(good, 4, "1 2 3"))
    elif setup == "grid-bad-truth":
        _write(truth / "seq.txt", catalogue._replace_line(good, 2, "oops"))
        bad = "good/seq/run1"
    elif setup == "grid-dangling":
        (algs / "bad" / "seq").mkdir(parents=True)
        (algs / "bad" / "seq" / "run1.txt").symlink_to(tmp / "deleted.txt")
    elif setup == "grid-static":
        _write(
            algs / "bad" / "seq" / "run1.txt",
            catalogue._rows(catalogue.T, 0 * catalogue.P, catalogue.Q),
        )
    elif setup == "grid-names":
        for name in ("run 1", "rün_ü", "50%", "a&b", "x..y", "x..", "{r}", "r$HOME"):
            _write(algs / "we ird&%" / "seq" / f"{name}.txt", good)
        bad = None
    elif setup in ("grid-bag-ref", "grid-bag-truncated"):
        good_traj = _traj(catalogue.T, catalogue.P, catalogue.Q)
        if setup == "grid-bag-ref":
            for ds in ("seq", "other"):
                (truth / f"{ds}.txt").unlink()
                bag_fixture.write_bag(
                    truth / ds,
                    {"/gt": ("geometry_msgs/msg/PoseStamped", good_traj)},
                    storage="sqlite3",
                )
            bad = None
        else:
            (algs / "bad" / "seq").mkdir(parents=True)
            bag_fixture.write_bag(
                algs / "bad" / "seq" / "run1.bag",
                {"/pose": ("geometry_msgs/msg/PoseStamped", good_traj)},
            )
            data = (algs / "bad" / "seq" / "run1.bag").read_bytes()
            (algs / "bad" / "seq" / "run1.bag").write_bytes(data[: len(data) // 2])
    elif setup == "grid-two-runs":
        _write(algs / "bad" / "seq" / "run1.txt", good)
        _write(algs / "bad" / "seq" / "run1.csv", good)
    elif setup == "grid-two-refs":
        _write(truth / "seq.csv", good)
    elif setup == "grid-no-cases":
        algs = tmp / "other_algorithms"
        _write(algs / "a" / "unknown" / "run1.txt", good)
    elif setup == "grid-stray":
        _write(algs / "notes.txt", "x")
        _write(algs / "good" / "seq.txt", good)
        (algs / "good" / "seq" / "subfolder").mkdir()
        bad = None
    elif setup == "grid-no-truth":
        _write(algs / "good" / "unknown" / "run1.txt", good)
        bad = None
    return truth, algs, bad


def run_grid(truth: Path, algs: Path, results: Path, config: dict | None = None) -> dict[str, str]:
    """Every stage as the workflow's jobs run it (one batch), then the tables; key -> status."""
    cfg = settings.resolve(
        {
            "truth_dir": str(truth),
            "algorithms_dir": str(algs),
            "results_dir": str(results),
            **(config or {}),
        }
    )
    _, found = cases.discover(truth, algs, cfg=cfg)
    batch = [{"key": c.key, "truth": str(c.truth), "estimate": str(c.estimate)} for c in found]
    upstream = None
    for st in chain.STAGES:
        manifest = results / "batches" / "all" / f"{st.NAME}.json"
        grid.run_job(st.NAME, batch, results, cfg, manifest, upstream)
        upstream = manifest
    tables.make([c.key for c in found], results, cfg)
    with open(results / "summary.csv", encoding="utf-8") as fh:
        return {
            f"{r['algorithm']}/{r['dataset']}/{r['run']}": r["status"] for r in csv.DictReader(fh)
        }


GRID_ROWS = [b for b in catalogue.CATALOGUE if b.where == "grid"]


@pytest.mark.parametrize("b", GRID_ROWS, ids=[b.id for b in GRID_ROWS])
def test_grid(tmp_path, caplog, b):
    truth, algs, bad = _grid_folders(tmp_path, b.setup)
    with caplog.at_level(logging.WARNING, logger="epa"):
        try:
            status = run_grid(truth, algs, tmp_path / "results")
        except EpaError as exc:  # a mistake in the grid as a whole: one line at parse time
            assert not b.ok and b.expect in exc.one_line() and "\n" not in exc.one_line()
            return
    if b.ok:
        assert b.expect in caplog.text or all(s == "ok" for s in status.values())
        assert all(s == "ok" for s in status.values()), status
        if b.setup == "grid-names":
            assert len(status) == 10
            assert all(
                (tmp_path / "results" / "cases" / k).resolve().is_relative_to(tmp_path / "results")
                for k in status
            )
        return
    assert b.expect in status.pop(bad) and "\n" not in b.expect
    assert status and all(s == "ok" for s in status.values()), status  # every other case finished
    _no_partial_output(tmp_path / "results" / "cases" / bad)


# ----------------------------------------------------------------------------- snakemake, parse time
WORKFLOW_ROWS = [b for b in catalogue.CATALOGUE if b.where == "workflow"]


@pytest.mark.parametrize("b", WORKFLOW_ROWS, ids=[b.id for b in WORKFLOW_ROWS])
def test_snakemake(tmp_path, b):
    _write(tmp_path / "cfg.yaml", b.config)
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-s",
            str(ROOT / "Snakefile"),
            "-n",
            "--configfile",
            str(tmp_path / "cfg.yaml"),
            "-d",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    text = run.stdout + run.stderr
    assert run.returncode != 0 and "Traceback" not in text and not (tmp_path / "HACKED").exists()
    line = next(line for line in text.splitlines() if b.expect in line)
    if b.blame != "none":
        assert line.startswith("epa: error: ") and str(tmp_path / "cfg.yaml") in line


def test_case_names_cannot_leave_the_results_folder(tmp_path):
    for key in ("a/../..", "a/b/..", "../b/c", "a/b", "a/b/c/d", "a/./c"):
        with pytest.raises(EpaError, match="plain names"):
            Case.from_key(key)
    case = Case.from_key("a b/ü&%/x..y")
    assert CaseFolder.of(tmp_path, case).root == tmp_path / "cases" / "a b/ü&%/x..y"


def test_the_catalogue_page_is_current():
    assert (ROOT / "docs" / "bad-inputs.md").read_text(encoding="utf-8") == catalogue.markdown()
    assert len(catalogue.CATALOGUE) >= 60 and len({b.id for b in catalogue.CATALOGUE}) == len(
        catalogue.CATALOGUE
    )
