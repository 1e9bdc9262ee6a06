"""The real snakemake on a tiny grid in a temporary folder."""

import csv
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import bag_fixture
import pytest

from epa import simulate

ROOT = Path(__file__).resolve().parents[1]
# tests about execution, not figures: per-case reports are tested on the main grid and in test_figures
NO_REPORTS = "report: {per_case: false}\n"
CMD = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--cores", "2"]


def smk(cwd, *args, config="cfg.yaml", snakefile=None):
    cmd = CMD if snakefile is None else [*CMD[:3], "-s", str(snakefile), *CMD[5:]]
    out = subprocess.run(
        cmd + ["--directory", str(cwd), "--configfile", str(cwd / config), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout + out.stderr


def artifacts(results: Path) -> dict[str, bytes]:
    """Every per-case artifact and table (not logs or Snakemake's bookkeeping), by relative path."""
    files = [
        p
        for p in results.rglob("*")
        if p.is_file()
        and "logs" not in p.parts
        and "batches" not in p.parts
        and "benchmarks" not in p.parts
        and p.name not in ("provenance.json", "config.resolved.yaml")  # name their results_dir
    ]
    return {str(p.relative_to(results)): p.read_bytes() for p in files}


def planned_jobs(cwd):
    text = smk(cwd, "-n", "--quiet", "rules")
    return {
        m.group(1): int(m.group(2))
        for m in re.finditer(r"^(\w+)\s+(\d+)$", text, re.M)
        if m.group(1) not in ("total", "all")
    }


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("grid")
    simulate.simulate(cwd / "sim")
    (cwd / "truth").mkdir()
    shutil.copy(cwd / "sim/truth/handheld_office.txt", cwd / "truth")
    for alg in ("vio_body", "vio_camera"):
        shutil.copytree(
            cwd / f"sim/algorithms/{alg}/handheld_office", cwd / f"algs/{alg}/handheld_office"
        )
    (cwd / "algs/broken/handheld_office").mkdir(parents=True)
    (cwd / "algs/broken/handheld_office/run1.txt").write_text("1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n")
    (cwd / "algs/broken/handheld_office/run2.txt").write_text(
        "5 0 0 0 0 0 0 1\n6 1 0 0 0 0 0 1\n7 2 0 0 0 0 0 1\n"
    )
    (cwd / "cfg.yaml").write_text("truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\n")
    smk(cwd)
    return cwd


def test_outputs_exist_and_parse(grid):
    res = grid / "results"
    rows = list(csv.DictReader(open(res / "summary.csv")))
    assert len(rows) == 6
    required = {
        "algorithm",
        "dataset",
        "run",
        "status",
        "n_matched",
        "ate_trans_rmse_m",
        "ate_rot_rmse_deg",
        "rpe_8m_trans_mean_m",
        "rpe_8m_rot_mean_deg",
        "time_rpe_1s_trans_mean_m",
        "drift_rate_8m_pct",
        "eval_source",
        "time_offset_s",
        "extrinsic_rot_deg",
        "extrinsic_trans_m",
        "success_rate_distance_pct",
        "success_rate_time_pct",
        "global_failed",
        "knee_threshold_m",
        "fail_segments",
    }
    assert required <= set(rows[0])
    ok = [r for r in rows if r["status"] == "ok"]
    assert len(ok) == 4 and all(float(r["ate_trans_rmse_m"]) < 0.2 for r in ok)
    cam = [r for r in ok if r["algorithm"] == "vio_camera"]
    assert all(r["eval_source"] == "epa" and 110 < float(r["extrinsic_rot_deg"]) < 130 for r in cam)
    bad = {r["run"]: r["status"] for r in rows if r["algorithm"] == "broken"}
    assert "run1.txt:2: not a number: 'x'" in bad["run1"]
    assert "poses matched" in bad["run2"] or "pose" in bad["run2"]
    text = (res / "error_comparison.txt").read_text()
    assert "TOOL SOURCE: epa=4, ov_eval=0" in text and "broken & - / - & - / -" in text
    # the failed case's log ends with its reason in one line
    log = (res / "cases/broken/handheld_office/run1/logs/load.log").read_text().strip().splitlines()
    assert log[-1].startswith("ERROR case failed: load: ") and "not a number" in log[-1]
    m = json.load(open(res / "cases/vio_body/handheld_office/run1/06_metrics/metrics.json"))
    assert {
        "n_matched",
        "alignment",
        "ate",
        "rpe_distance",
        "rpe_time_1s",
        "drift_rate_pct",
    } <= set(m)


def strict_parse_tex(text):
    """Every token must be a known LaTeX construct; rows must have the column count of the spec."""
    lines = text.strip().splitlines()
    assert lines[0].startswith("% ") and lines[-1] == r"\end{tabular}"
    spec = re.fullmatch(r"\\begin\{tabular\}\{(l[c]+)\}", lines[1]).group(1)
    assert lines[2].endswith(r"\\ \hline")
    for row in lines[2:-1]:
        body = row[: -len(r"\\ \hline")] if row.endswith(r"\hline") else row[:-2]
        assert row.endswith("\\\\") or row.endswith(r"\\ \hline")
        cells = body.split(" & ")
        assert len(cells) == len(spec), row
        residue = re.sub(
            r"\\textbf\{[^{}\\]*(?:\\[_&%$#{}][^{}\\]*)*\}|\\[_&%$#{}]|\\textbackslash\{\}|"
            r"\\textasciitilde\{\}|\\textasciicircum\{\}",
            "",
            body,
        )
        assert "\\" not in residue and "{" not in residue and "}" not in residue, row
        assert (
            "&" not in residue.replace(" & ", "")
            and "%" not in residue
            and "_" not in residue
            and "$" not in residue
        )


def test_grid_figures_and_case_reports_are_written(grid):
    res = grid / "results"
    for name in ("ate", "success_rate", "drift_rate", "rmse_time"):
        assert (res / "figures" / f"{name}.png").stat().st_size > 5000
        assert (res / "figures" / f"{name}.pdf").read_bytes()[:5] == b"%PDF-"
    report = res / "cases/vio_body/handheld_office/run1/10_report"
    # a clean case: its bundles and documents, its figures one command away (report.figures: flagged)
    assert (report / "bundles/trajectory.json").exists() and (report / "report_en.md").exists()
    assert "epa fig --case" in (report / "report_en.md").read_text()
    # a broken case has no report, only the reason
    assert "failed" in (res / "cases/broken/handheld_office/run1/10_report/report.json").read_text()


def test_every_tex_table_parses_strictly(grid):
    from epa.outputs import tables
    from epa.workflow import settings

    files = sorted((grid / "results/tables").glob("*.tex"))
    assert [f.stem for f in files] == sorted(tables.table_names(settings.defaults()))  # no kitti
    for f in files:
        strict_parse_tex(f.read_text())


def test_latex_escaping_of_names():
    from epa.outputs.tables import latex_escape

    assert (
        latex_escape("a_b&c%d$e#f{g}h~i^j\\")
        == r"a\_b\&c\%d\$e\#f\{g\}h\textasciitilde{}i\textasciicircum{}j\textbackslash{}"
    )
    strict_parse_tex(
        "% t\n\\begin{tabular}{lc}\n & \\textbf{"
        + latex_escape("x_1 & {y}")
        + "} \\\\ \\hline\n"
        + latex_escape("a%b")
        + " & 1.000 / 2.000 \\\\\n\\end{tabular}\n"
    )


def test_rerun_behaviour(grid):
    assert planned_jobs(grid) == {}  # second run does nothing
    time.sleep(1.1)
    # Snakemake 9 ignores an mtime-only touch of unchanged content; an edit re-runs the case
    with open(grid / "algs/vio_body/handheld_office/run2.txt", "a") as fh:
        fh.write("# edited\n")
    jobs = planned_jobs(grid)
    assert jobs == {
        "load": 1,
        "crop": 1,
        "sync": 1,
        "calibrate": 1,
        "align": 1,
        "metrics": 1,
        "drift": 1,
        "consistency": 1,
        "efficiency": 1,
        "report": 1,
        "tables": 1,
        "provenance": 1,
        "figures": 1,
        "paper": 1,
    }
    smk(grid)
    # a changed stage setting re-runs that stage onward, for every case
    (grid / "cfg.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\nalign: {method: posyaw}\n"
    )
    jobs = planned_jobs(grid)
    assert jobs == {
        "align": 6,
        "metrics": 6,
        "drift": 6,
        "consistency": 6,
        "efficiency": 6,
        "report": 6,
        "tables": 1,
        "provenance": 1,
        "figures": 1,
        "paper": 1,
    }


def test_batched_execution_writes_the_same_artifacts_and_tables(grid):
    # 6 cases in 2 batches per stage instead of one case per job
    (grid / "batched.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: batched\ngrid: {max_batches: 2}\n"
    )
    smk(grid, config="batched.yaml")
    assert len(list((grid / "batched/batches").iterdir())) <= 2  # 6 cases, at most 2 jobs per stage
    per_case, batched = artifacts(grid / "results"), artifacts(grid / "batched")
    assert len(per_case) > 60 and per_case.keys() == batched.keys()
    assert [k for k in per_case if per_case[k] != batched[k]] == []


def test_epa_eval_writes_the_workflow_metrics_json(grid, tmp_path):
    from epa.cli import main as cli

    case = "vio_camera/handheld_office/run1"
    assert (
        cli.main(
            [
                "eval",
                str(grid / "truth/handheld_office.txt"),
                str(grid / f"algs/{case}.csv"),
                "--out",
                str(tmp_path / "eval"),
            ]
        )
        == 0
    )
    for stage_file in (
        "06_metrics/metrics.json",
        "07_drift/drift.json",
        "04_calibrate/calibrate.json",
    ):
        assert (tmp_path / "eval" / stage_file).read_bytes() == (
            grid / "results/cases" / case / stage_file
        ).read_bytes()


def test_a_bug_in_one_case_is_only_that_cases_failure(grid):
    # a Snakefile that includes the real one and breaks the sync stage of one case (in-thread: --cores 1)
    wrapper = grid / "Snakefile.bug"
    wrapper.write_text(
        f"include: {str(ROOT / 'Snakefile')!r}\n"
        + """
import dataclasses
import epa.workflow.stages.sync as _sync
def _buggy(data, *args, _run=_sync.STAGE.run):
    if "vio_body/handheld_office/run2" in str(data.folder.root):
        raise ZeroDivisionError("injected bug")
    return _run(data, *args)
_sync.STAGE = dataclasses.replace(_sync.STAGE, run=_buggy)
"""
    )
    (grid / "bug.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: bug\n" + NO_REPORTS
    )
    # the profile is found next to the Snakefile only: name it, so jobs run in threads as usual
    out = smk(
        grid,
        "--cores",
        "1",
        "--profile",
        str(ROOT / "profiles/default"),
        "all",
        config="bug.yaml",
        snakefile=wrapper,
    )
    rows = {
        r["algorithm"] + "/" + r["run"]: r for r in csv.DictReader(open(grid / "bug/summary.csv"))
    }
    assert rows["vio_body/run2"]["status"] == "internal error: ZeroDivisionError: injected bug"
    assert [r["status"] for k, r in rows.items() if k.startswith("vio_")].count("ok") == 3
    assert "vio_body/handheld_office/run2: internal error: ZeroDivisionError: injected bug" in out
    log = (grid / "bug/cases/vio_body/handheld_office/run2/logs/sync.log").read_text()
    assert "Traceback" in log and "ZeroDivisionError" in log
    downstream = (grid / "bug/cases/vio_body/handheld_office/run2/logs/metrics.log").read_text()
    assert "failed upstream: internal error: ZeroDivisionError" in downstream


@pytest.mark.skipif(
    shutil.which("sbatch") is not None, reason="runs a stand-in cluster, not a real one"
)
def test_cluster_generic_executor_gives_the_local_tables(tmp_path):
    pytest.importorskip("snakemake_executor_plugin_cluster_generic")
    cwd = tmp_path
    simulate.simulate(cwd / "sim")
    (cwd / "local.yaml").write_text(
        "truth_dir: sim/truth\nalgorithms_dir: sim/algorithms\nresults_dir: local\n"
        "grid: {max_batches: 3}\n" + NO_REPORTS
    )
    (cwd / "cluster.yaml").write_text(
        (cwd / "local.yaml").read_text().replace("results_dir: local", "results_dir: cluster")
    )
    # a stand-in for sbatch: run the job script in the background, print a job id
    (cwd / "submit.sh").write_text('#!/bin/bash\nnohup bash "$1" > "$1.out" 2>&1 &\necho $!\n')
    (cwd / "submit.sh").chmod(0o755)
    smk(cwd, config="local.yaml")
    smk(
        cwd,
        "--executor",
        "cluster-generic",
        "--cluster-generic-submit-cmd",
        str(cwd / "submit.sh"),
        "--jobs",
        "2",
        "--seconds-between-status-checks",
        "1",
        "--latency-wait",
        "5",
        config="cluster.yaml",
    )
    for name in ("error_comparison.txt", "summary.csv"):
        assert (cwd / "cluster" / name).read_bytes() == (cwd / "local" / name).read_bytes()


def test_a_killed_run_resumes_to_the_same_tables(grid):
    import os
    import signal

    (grid / "kill.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: killed\n" + NO_REPORTS
    )
    cmd = CMD + ["--directory", str(grid), "--configfile", str(grid / "kill.yaml"), "--quiet"]
    proc = subprocess.Popen(
        cmd, cwd=grid, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.time() + 120
    while len(list((grid / "killed").glob("batches/**/sync.json"))) < 2 and time.time() < deadline:
        time.sleep(0.05)
    try:
        os.killpg(proc.pid, signal.SIGKILL)  # Snakemake, its forkserver and workers, mid-run
    except ProcessLookupError:
        pass
    proc.wait()
    assert not (grid / "killed/summary.csv").exists()
    # no half-written artifact: atomic writes leave only whole files or hidden temporaries
    for p in (grid / "killed").rglob("*.json"):
        if not p.name.startswith("."):
            json.loads(p.read_text())
    smk(grid, "--unlock", config="kill.yaml")  # the killed run's lock stays behind
    smk(grid, config="kill.yaml")
    for name in ("error_comparison.txt", "summary.csv"):
        assert (grid / "killed" / name).read_bytes() == (grid / "results" / name).read_bytes()


def test_names_with_spaces_unicode_and_symbols_run(tmp_path):
    alg, ds, run = "alg %&{x}", "dä ta", "run 1"
    (tmp_path / "truth").mkdir()
    simulate.simulate(tmp_path / "sim")
    shutil.copy(tmp_path / "sim/truth/handheld_office.txt", tmp_path / "truth" / f"{ds}.txt")
    (tmp_path / "algs" / alg / ds).mkdir(parents=True)
    shutil.copy(
        tmp_path / "sim/algorithms/vio_body/handheld_office/run1.txt",
        tmp_path / "algs" / alg / ds / f"{run}.txt",
    )
    (tmp_path / "cfg.yaml").write_text(
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\n"
    )
    smk(tmp_path)
    row = next(csv.DictReader(open(tmp_path / "results/summary.csv", encoding="utf-8")))
    assert (row["algorithm"], row["dataset"], row["run"], row["status"]) == (alg, ds, run, "ok")
    assert (tmp_path / "results/cases" / alg / ds / run / "06_metrics/metrics.json").is_file()
    assert r"alg \%\&\{x\} & " in (tmp_path / "results/tables/ate.tex").read_text()


def test_bag_grid_with_per_source_settings(tmp_path):
    """References in bags (a ROS 2 folder; a ROS 1 bag whose second topic is an estimate), text
    estimates of another algorithm, settings per source; changing one algorithm's settings re-runs
    only its cases."""
    from epa.artifacts import files
    from epa.readers import text as text_reader

    simulate.simulate(tmp_path / "sim")
    sim = tmp_path / "sim"
    ref = text_reader.read_trajectory(sim / "truth/handheld_office.txt")
    est = text_reader.read_trajectory(sim / "algorithms/vio_body/handheld_office/run1.txt")
    (tmp_path / "truth").mkdir()
    bag_fixture.write_bag(
        tmp_path / "truth/office_ros2",
        {"/vicon": ("geometry_msgs/msg/PoseStamped", ref)},
        storage="sqlite3",
    )
    # one ROS 1 bag holding ground truth and an estimate: the reference of one dataset and a run
    (tmp_path / "algs/bagged/office_ros1").mkdir(parents=True)
    both = tmp_path / "algs/bagged/office_ros1/run1.bag"
    bag_fixture.write_bag(
        both,
        {"/gt": ("geometry_msgs/msg/PoseStamped", ref), "/odom": ("nav_msgs/msg/Odometry", est)},
    )
    (tmp_path / "truth/office_ros1.bag").symlink_to(both)
    for ds in ("office_ros1", "office_ros2"):
        (tmp_path / f"algs/text/{ds}").mkdir(parents=True)
        files.write_trajectory(tmp_path / f"algs/text/{ds}/run1.csv", est, "euroc")
    base = (
        "truth_dir: truth\nalgorithms_dir: algs\nresults_dir: results\n" + NO_REPORTS + "sources:\n"
        "  datasets:\n    office_ros2: {topic: /vicon}\n    office_ros1: {topic: /gt}\n"
        "  algorithms:\n    text: {format: euroc}\n    bagged: {topic: %s}\n"
    )
    (tmp_path / "cfg.yaml").write_text(base % "/odom")
    smk(tmp_path)
    rows = {
        f"{r['algorithm']}/{r['dataset']}": r
        for r in csv.DictReader(open(tmp_path / "results/summary.csv"))
    }
    assert set(rows) == {"bagged/office_ros1", "text/office_ros1", "text/office_ros2"}
    assert all(r["status"] == "ok" for r in rows.values()), rows
    # the same estimate through three routes gives the same number
    ates = {k: float(r["ate_trans_rmse_m"]) for k, r in rows.items()}
    assert max(ates.values()) - min(ates.values()) < 1e-6, ates
    load = json.loads(
        (tmp_path / "results/cases/bagged/office_ros1/run1/01_load/load.json").read_text()
    )
    assert (
        load["sources"]["estimate"]["topic"] == "/odom"
        and "bag topic /odom (Odometry, header stamps)" in load["est_notes"]
    )
    assert "bag topic /gt (PoseStamped, header stamps)" in load["ref_notes"]
    # another topic for one algorithm: only its case re-runs
    (tmp_path / "cfg2.yaml").write_text(base % "/gt")
    plan = smk(tmp_path, "-n", config="cfg2.yaml")
    loads = re.findall(r"rule load:.*?wildcards: batch=(\S+)", plan, re.S)
    assert loads == ["bagged_office_ros1_run1"] or (loads and all("bagged" in b for b in loads)), (
        loads
    )


def test_commands_without_cores_parse_the_workflow(tmp_path):
    """`snakemake --unlock` and `--report` give no --cores, and Snakemake refuses `workflow.cores`
    then: the Snakefile's parse-time code (the worker pool's warm-up) must take that as one core,
    not stop the command (CI's `snakemake --report` found it)."""
    (tmp_path / "cfg.yaml").write_text(
        f"truth_dir: {ROOT / 'example/truth'}\nalgorithms_dir: {ROOT / 'example/algorithms'}\n"
        f"results_dir: {tmp_path / 'results'}\n"
    )
    out = subprocess.run(
        [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--unlock"]
        + ["--directory", str(tmp_path), "--configfile", str(tmp_path / "cfg.yaml")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 0 and "Unlocked" in out.stdout + out.stderr, out.stdout + out.stderr
