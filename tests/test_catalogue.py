"""Every row of the bad-input catalogue (tests/catalogue.py, docs/bad-inputs.md) run as a user would:
a one-line error naming the file (and line), exit status 2, no traceback and no partial output; or a
correct result with a note saying what was inferred. In a grid the other cases finish."""

import csv
import json
import logging
import os
import subprocess
import sys
import warnings
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
    if b.stamps is not None:
        _write(tmp / "stamps.txt", b.stamps)
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
    if setup == "bag-tf-loop":  # world -> odom and odom -> world, and odom -> body
        from test_bags import _write_tf

        edges = {("world", "odom"): good, ("odom", "world"): good, ("odom", "body"): good}
        _write_tf(est, edges, static={})
        return est
    if setup in ("bag-damaged", "mcap-damaged"):  # a damaged compressed chunk (bz2, zstd)
        bag_fixture.write_bag(
            est,
            {
                "/pose": ("geometry_msgs/msg/PoseStamped", good),
                "/tf": ("tf2_msgs/msg/TFMessage", good),
            },
            storage="mcap" if setup == "mcap-damaged" else "ros1",
            compressed=True,
        )
        damaged = next(est.glob("*.mcap")) if est.is_dir() else est
        data = bytearray(damaged.read_bytes())
        at = len(data) // 2 if setup == "mcap-damaged" else len(data) // 3
        for k in range(at, at + 200):
            data[k] ^= 0xFF if setup == "mcap-damaged" else 0x5A
        damaged.write_bytes(bytes(data))
        return est
    if setup == "bag-amcl":  # PoseWithCovarianceStamped with a covariance
        import numpy as np

        c = np.tile(np.eye(3) * 0.01, (len(good), 1, 1))
        with_cov = _traj(good.t, good.p, good.q)
        with_cov = type(with_cov)(good.t, good.p, good.q, cov_pos=c, cov_rot=c)
        bag_fixture.write_bag(
            est, {"/amcl_pose": ("geometry_msgs/msg/PoseWithCovarianceStamped", with_cov)}
        )
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


def _refuse(token: str):
    raise ValueError(f"{token} is not JSON")


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
        for p in out.rglob("*.json"):  # JSON any parser takes: no NaN or Infinity token
            json.loads(p.read_text(), parse_constant=_refuse)
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
        "stamps": "stamps.txt",  # as metrics.eth3d.image_stamps names it (the test's folder)
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
    elif setup == "grid-backslash":
        _write(algs / "bad" / "seq" / "run1\\..\\..\\EPABI.txt", good)
        bad = "bad/seq/run1\\..\\..\\EPABI"
    elif setup == "grid-all-fail":  # both runs of the algorithm fail, in both datasets
        for ds in ("seq", "other"):
            _write(algs / "bad" / ds / "run1.txt", catalogue._replace_line(good, 4, "1 2 3"))
        bad = "bad/seq/run1"
    elif setup == "grid-timing-pattern":
        for ds in ("seq", "other"):
            _write(
                algs / "good" / ds / "run1.frames", "".join(f"{t:.9f} 12\n" for t in catalogue.T)
            )
        bad = None
    elif setup == "grid-empty-dataset":
        (algs / "empty" / "seq").mkdir(parents=True)
        bad = None
    elif setup == "grid-ea-overflow":
        _write(
            algs / "good" / "seq" / "run1_timing.txt",
            "".join(f"{t:.9f} {100000 if k == 100 else 20}\n" for k, t in enumerate(catalogue.T)),
        )
        bad = None
    elif setup == "grid-killed-write":  # a kill mid-write, as a previous run would have left it
        sync = tmp / "results" / "cases" / "good" / "seq" / "run1" / "03_sync"
        _write(sync / ".xcorr.csv.k1ll3d_x", "lag_s,corr\n-0.5,0.12")
        for name in KEPT_BESIDE_A_TEMPORARY:  # not epica's temporaries: left alone
            _write(sync / name, "the user's")
        bad = None
    elif setup is None:
        bad = None
    return truth, algs, bad


# files beside a killed write's temporary that are not epica's temporaries: an unknown artifact name,
# a suffix mkstemp never makes, a name without the leading dot
KEPT_BESIDE_A_TEMPORARY = (".notes.txt.k1ll3d_x", ".xcorr.csv.bak", "xcorr.csv.k1ll3d_x")


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
    from epa import readers

    batch = [  # as rules/common.smk's load_case
        {
            "key": c.key,
            "truth": str(c.truth),
            "estimate": str(c.estimate),
            "truth_source": readers.options(cfg, "reference", dataset=c.dataset),
            "estimate_source": readers.options(cfg, "estimate", algorithm=c.algorithm),
        }
        for c in found
    ]
    upstream = None
    for st in chain.STAGES:
        manifest = results / "batches" / "all" / f"{st.name}.json"
        grid.run_job(st.name, batch, results, cfg, manifest, upstream)
        upstream = manifest
    tables.make([c.key for c in found], results, cfg)
    with open(results / "summary.csv", encoding="utf-8") as fh:
        return {
            f"{r['algorithm']}/{r['dataset']}/{r['run']}": r["status"] for r in csv.DictReader(fh)
        }


GRID_ROWS = [b for b in catalogue.CATALOGUE if b.where == "grid"]


@pytest.mark.parametrize("b", GRID_ROWS, ids=[b.id for b in GRID_ROWS])
def test_grid(tmp_path, caplog, b):
    import yaml

    truth, algs, bad = _grid_folders(tmp_path, b.setup)
    config = yaml.safe_load(b.config) if b.config else None
    with caplog.at_level(logging.WARNING, logger="epa"), warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy's warnings never reach the user
        try:
            status = run_grid(truth, algs, tmp_path / "results", config)
        except EpaError as exc:  # a mistake in the grid as a whole: one line at parse time
            assert not b.ok and b.expect in exc.one_line() and "\n" not in exc.one_line()
            return
        if b.setup == "grid-all-fail":
            from epa.outputs import report

            report.write_grid_figures(tmp_path / "results", [8, 16])
    assert "inf" not in (tmp_path / "results" / "summary.csv").read_text().split()
    for tex in (tmp_path / "results" / "tables").glob("*.tex"):
        assert " inf " not in tex.read_text(), tex
    if b.ok:
        notes = caplog.text + "".join(
            p.read_text()
            for p in (tmp_path / "results" / "cases").rglob("*")
            if p.suffix in (".json", ".log")  # a record's notes, a stage's case log
        )
        assert b.expect in notes or (b.expect == "ok" and all(s == "ok" for s in status.values()))
        assert all(s == "ok" for s in status.values()), status
        if b.setup == "grid-ea-overflow":
            rows = list(csv.DictReader(open(tmp_path / "results" / "summary.csv")))
            row = next(r for r in rows if r["dataset"] == "seq")
            assert row["ea_drift"] == "" and row["frame_time_mean_ms"] != ""
        if b.setup == "grid-timing-pattern":
            eff = json.loads(
                (tmp_path / "results/cases/good/seq/run1/09_efficiency/efficiency.json").read_text()
            )
            assert eff["available"] and eff["frame_time_mean_ms"] == 12
        if b.setup == "grid-killed-write":
            sync = tmp_path / "results/cases/good/seq/run1/03_sync"
            assert sorted(p.name for p in sync.iterdir() if not p.name[0].isalpha()) == sorted(
                KEPT_BESIDE_A_TEMPORARY[:2]
            )
            assert (sync / KEPT_BESIDE_A_TEMPORARY[2]).read_text() == "the user's"
            xcorr = (sync / "xcorr.csv").read_text().splitlines()  # the real one, whole
            assert xcorr[0] == "lag_s,corr" and len(xcorr) > 100
        if b.setup == "grid-names":
            assert len(status) == 10
            assert all(
                (tmp_path / "results" / "cases" / k).resolve().is_relative_to(tmp_path / "results")
                for k in status
            )
        return
    assert b.expect in status.pop(bad) and "\n" not in b.expect
    status = {k: v for k, v in status.items() if not k.startswith("bad/")}  # its other runs
    assert status and all(s == "ok" for s in status.values()), status  # every other case finished
    _no_partial_output(tmp_path / "results" / "cases" / bad)
    outside = [p for p in tmp_path.rglob("*EPABI*") if not p.is_relative_to(algs)]
    assert all(p.is_relative_to(tmp_path / "results") for p in outside), outside


# ----------------------------------------------------------------------------- commands
COMMAND_ROWS = [b for b in catalogue.CATALOGUE if b.where == "command"]


def _command_setup(tmp: Path, b: catalogue.Bad) -> dict[str, str]:
    ref, est = tmp / b.ref_name, tmp / b.est_name
    _write(ref, b.ref)
    if b.setup and b.setup.startswith(("bag", "mcap")):
        est = _bag(tmp, est, b.setup)
    else:
        _write(est, b.est if b.est is not None else catalogue.GOOD)
    result = {"format": "epica-result/1", "title": "APE", "stats": {"rmse": 1.0}}
    if b.setup == "file-X":
        _write(tmp / "X", "a file")
    elif b.setup == "result-no-title":
        _write(tmp / "r.json", json.dumps({k: v for k, v in result.items() if k != "title"}))
    elif b.setup == "result-no-stats":
        _write(tmp / "r.json", json.dumps({k: v for k, v in result.items() if k != "stats"}))
    elif b.setup == "metrics-ate-null":
        _write(tmp / "metrics.json", json.dumps({"ate": None}))
    elif b.setup == "bundle-no-data":
        _write(tmp / "b.json", json.dumps({"format": "epica-plot-bundle/1", "kind": "ape_time"}))
    elif b.setup == "bundle-partial":
        _write(
            tmp / "b.json",
            json.dumps(
                {
                    "format": "epica-plot-bundle/1",
                    "kind": "ape_time",
                    "title": "x",
                    "data": {"ape": [1.0, 2.0]},
                }
            ),
        )
    return {"ref": str(ref), "est": str(est), "tmp": str(tmp)}


@pytest.mark.parametrize("b", COMMAND_ROWS, ids=[b.id for b in COMMAND_ROWS])
def test_command(tmp_path, capsys, caplog, b):
    names = _command_setup(tmp_path, b)
    argv = [a.format(**names) for a in b.args]
    with caplog.at_level(logging.WARNING, logger="epa"), warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rc = cli.main(argv)
    captured = capsys.readouterr()
    err = captured.err
    assert "Traceback" not in err
    if b.ok:
        assert rc == 0, err
        assert b.expect in captured.out + err + caplog.text, captured.out
        if b.setup == "bag-amcl":
            rows = [
                line.split()
                for line in (tmp_path / "poses.tum").read_text().splitlines()
                if not line.startswith("#")
            ]
            assert {len(r) for r in rows} == {20 if "--covariance" in argv else 8}
        if b.setup == "eval-document":
            from epa.artifacts.case import CaseFolder

            doc = json.loads((tmp_path / "out" / "metrics.json").read_text())
            assert list(doc) == ["metrics", "drift", "consistency", "efficiency"]
            assert doc == CaseFolder(tmp_path / "out").document(chain.DOCUMENT)
        return
    lines = [line for line in err.splitlines() if line.startswith("epa: error: ")]
    assert rc == 2 and len(lines) == 1, err
    assert b.expect.format(**names) in lines[0], lines[0]
    assert lines[0].startswith("epa: error: " + b.blamed.format(**names)), lines[0]
    for p in tmp_path.rglob("*"):
        assert not p.name.startswith("."), f"temporary file left behind: {p}"
    assert not (tmp_path / "fig.png").exists() and not (tmp_path / "poses.tum").exists()


# ----------------------------------------------------------------------------- snakemake, parse time
WORKFLOW_ROWS = [b for b in catalogue.CATALOGUE if b.where == "workflow"]


@pytest.mark.parametrize("b", WORKFLOW_ROWS, ids=[b.id for b in WORKFLOW_ROWS])
def test_snakemake(tmp_path, b):
    _write(tmp_path / "cfg.yaml", b.config)
    if b.setup in ("wf-folders", "wf-inputs"):
        _write(tmp_path / "truth" / "seq.txt", catalogue.GOOD)
        _write(tmp_path / "algorithms" / "a" / "seq" / "run1.txt", catalogue.GOOD)
    if b.setup == "wf-inputs":
        _write(tmp_path / "other" / "a" / "seq" / "run1.txt", catalogue.GOOD)
    if b.sheet is not None:
        _write(tmp_path / "runs.tsv", b.sheet)
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
            *b.args,
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    text = run.stdout + run.stderr
    if b.ok:
        assert run.returncode == 0 and b.expect in text, text
        return
    assert run.returncode != 0 and "Traceback" not in text and not (tmp_path / "HACKED").exists()
    line = next(line for line in text.splitlines() if b.expect in line)
    if b.blamed is not None:  # a file the config names: the sheet's line, a matched file
        assert line.startswith("epa: error: " + b.blamed), line
    elif b.blame != "none":
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
