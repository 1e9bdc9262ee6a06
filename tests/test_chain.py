"""The stage chain and the grid runner: the fallback decision, batching, per-case failure isolation."""

import dataclasses
import json
import re
from concurrent.futures.process import BrokenProcessPool

import numpy as np
import pytest
from conftest import run_stages
from test_steps_sim import case as sim_case

from epa.artifacts import files
from epa.artifacts.case import CaseFolder, failure_of
from epa.core.errors import EpaError
from epa.outputs import tables
from epa.workflow import chain, settings
from epa.workflow import jobs as grid
from epa.workflow.stages import align


@pytest.fixture
def offset_case(tmp_path):
    """A camera-frame estimate 0.25 s late: Step 1 finds the offset, Step 2 the extrinsic."""
    ref, est, _, _ = sim_case("drone_figure8", offset=0.25, noise=0.002)
    files.write_tum(tmp_path / "ref.txt", ref.shifted(1e9))
    files.write_tum(tmp_path / "est.txt", est.shifted(1e9))
    return tmp_path / "ref.txt", tmp_path / "est.txt"


def resolved(**sections):
    return settings.resolve({"truth_dir": ".", "algorithms_dir": ".", **sections})


def test_trusted_steps_use_the_estimated_offset(offset_case, tmp_path):
    m = chain.run_case(*offset_case, tmp_path / "out", resolved())["metrics"]
    assert m["eval_source"] == "epa" and abs(m["time_offset_s"] - 0.25) < 0.002
    assert m["ate"]["trans_m"]["rmse"] < 0.01


def test_untrusted_step2_drops_the_step1_offset_and_reassociates(offset_case, tmp_path):
    # an impossible residual bound: Step 2 is not trusted, so the case is evaluated the ov_eval way,
    # which means no offset either (the configured sync.offset, 0), not the Step 1 one
    cfg = resolved(calibrate={"max_trans_residual_m": 1e-6})
    m = chain.run_case(*offset_case, tmp_path / "out", cfg, write_arrays=True)["metrics"]
    assert m["eval_source"] == "ov_eval" and m["calibrate"]["reason"].startswith(
        "Step 2 not trusted"
    )
    assert abs(m["sync"]["offset_s"] - 0.25) < 0.002  # what Step 1 found stays on record
    assert m["time_offset_s"] == 0.0 and m["calibrate"]["reassociated"]["offset_s"] == 0.0
    assert (
        m["extrinsic_rot_deg"] is None
        and m["alignment"]["method"] == "se3"
        and m["alignment"]["fallback"]
    )
    pairs = files.read_csv(tmp_path / "out/04_calibrate/pairs.csv")
    assert np.abs(pairs["t_ref"] - pairs["t_est"]).max() <= 0.02  # matched on raw stamps
    assert not (tmp_path / "out/04_calibrate/est.tum").exists()


def test_ov_eval_mode_sets_the_stage_settings_and_warns(caplog):
    cfg = resolved(mode="ov_eval", sync={"policy": "evo"})
    assert cfg["sync"] == {
        **cfg["sync"],
        "estimate_offset": False,
        "policy": "ov_eval",
        "max_diff": 0.02,
    }
    assert not cfg["calibrate"]["enabled"]
    assert "mode ov_eval overrides sync.policy: 'evo' -> 'ov_eval'" in caplog.text


def test_batches_are_cases_on_small_grids_and_stable_hashes_on_large_ones():
    keys = [f"a/d{k}/r" for k in range(10)]
    assert grid.batches(keys, 32) == {k: [k] for k in keys}
    many = [f"a{k % 7}/d{k % 13}/r{k}" for k in range(500)]
    b = grid.batches(many, 32)
    assert len(b) == 32 and sorted(sum(b.values(), [])) == sorted(many)
    # adding a case changes exactly one batch
    b2 = grid.batches(many + ["new/case/run"], 32)
    assert sum(b[k] != b2[k] for k in b) == 1


def write_case(root, name, ref, est_text):
    folder = root / "algs" / name / "seq"
    folder.mkdir(parents=True)
    (folder / "run1.txt").write_text(est_text)
    return {"key": f"{name}/seq/run1", "truth": str(ref), "estimate": str(folder / "run1.txt")}


@pytest.fixture
def three_cases(tmp_path, offset_case):
    ref, est = offset_case
    good = est.read_text()
    return [
        write_case(tmp_path, "good", ref, good),
        write_case(tmp_path, "bug", ref, good),
        write_case(tmp_path, "bad", ref, "1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n"),
    ]


def run_grid(tmp_path, cases, cfg):
    out = tmp_path / "results"
    return out, run_stages(cases, out, cfg)


def test_a_bug_in_one_case_is_recorded_and_the_others_finish(tmp_path, three_cases, monkeypatch):
    real = align.STAGE.run

    def buggy(data, *args):
        if "/bug/" in str(data.folder.root):
            raise KeyError("injected")
        return real(data, *args)

    monkeypatch.setattr(align, "STAGE", dataclasses.replace(align.STAGE, run=buggy))
    out, manifests = run_grid(tmp_path, three_cases, resolved())
    status = grid.read_manifest(manifests["drift"])
    assert status["good/seq/run1"] == {"status": "ok"}
    assert status["bug/seq/run1"]["reason"] == "internal error: KeyError: 'injected'"
    assert (
        status["bad/seq/run1"]["reason"].startswith("load: ")
        and "run1.txt:2: not a number: 'x'" in status["bad/seq/run1"]["reason"]
    )
    assert "Traceback" in (out / "cases/bug/seq/run1/logs/align.log").read_text()
    assert (
        json.loads((out / "cases/bug/seq/run1/07_drift/drift.json").read_text())["status"]
        == "failed"
    )
    failed = tables.make([c["key"] for c in three_cases], out, resolved())
    assert dict(failed) == {
        "bad/seq/run1": "failed: " + status["bad/seq/run1"]["reason"],
        "bug/seq/run1": "internal error: KeyError: 'injected'",
    }
    assert "(see" in tables.failure_report(out / "summary.csv")


def test_a_dead_worker_costs_only_its_case(tmp_path, three_cases, monkeypatch):
    calls = []

    def flaky(workers, fn, *args):
        calls.append(len(args[1]))
        if len(args[1]) > 1 or args[1][0]["key"].startswith("bug"):
            raise BrokenProcessPool("worker died")
        return fn(*args)

    monkeypatch.setattr(grid, "call", flaky)
    status = grid.run_job(
        "load", three_cases, tmp_path / "r", resolved(), tmp_path / "m.json", workers=2
    )
    assert calls == [3, 1, 1, 1]
    assert status["good/seq/run1"] == {"status": "ok"}
    assert "worker process died" in status["bug/seq/run1"]["reason"]


def test_epa_eval_failure_writes_markers_not_results(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2 3\n")
    with pytest.raises(EpaError):
        chain.run_case(bad, bad, tmp_path / "out", resolved())
    assert failure_of(tmp_path / "out/01_load/load.json").startswith("load: ")
    assert not (tmp_path / "out/06_metrics").exists()


def test_the_library_imports_no_workflow_glue():
    import subprocess
    import sys

    code = (
        "import pkgutil, importlib, sys, epa\n"
        "for m in pkgutil.iter_modules(epa.__path__): importlib.import_module('epa.' + m.name)\n"
        "print(sorted(n for n in sys.modules if n.split('.')[0] in ('snakemake', 'matplotlib', 'scipy', 'pandas')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_every_rule_declares_log_threads_resources_and_its_timing():
    from pathlib import Path

    rules = Path(__file__).resolve().parents[1] / "rules"
    for smk in sorted(rules.glob("*.smk")):
        text = smk.read_text()
        if "rule " not in text and "rule:" not in text:
            continue
        rules_here = text.count("\nrule ") + text.startswith("rule ") + text.count("\n    rule:")
        for directive in ("log:", "benchmark:", "threads:", "resources:", "params:"):
            declared = text.count(directive)
            if directive == "benchmark:" and smk.name == "stages.smk":
                # the stage jobs write their own (Snakemake's sampler costs more than the job)
                common = (rules / "common.smk").read_text()
                assert declared == 0 and "stage_job(" in text
                assert "timing_path=batch_timing(" in common
                continue
            if directive == "benchmark:":
                # every rule writes its own wall and CPU seconds: the once-per-grid scripts' through
                # grid_script, provenance's through write_provenance (a job in Snakemake's threads
                # would sample the whole process)
                common = (rules / "common.smk").read_text()
                own = len(re.findall(r"^ +(?:grid_script|write_provenance)\(", text, re.M))
                assert declared == 0 and own == rules_here, (smk.name, own, rules_here)
                assert 'timing_path=f"{RESULTS}/benchmarks/{script}.tsv"' in common
                assert 'epa_jobs.timed(f"{RESULTS}/benchmarks/provenance.tsv")' in common
                continue
            assert declared == rules_here, (smk.name, directive)


def let_go_after(monkeypatch, *args, **options) -> dict[str, str]:
    """Value -> the stage after which run_case_data let it go (from its CaseData.forget calls)."""
    from epa.artifacts import case as case_module

    ran: dict = {"last": None}
    after: dict[str, str] = {}
    run_stage, forget = chain.run_stage, case_module.CaseData.forget

    def running(stage, *a, **k):
        run_stage(stage, *a, **k)
        ran["last"] = stage

    def recording(self, *names):
        for name in names:
            after.setdefault(name, ran["last"])
        forget(self, *names)

    monkeypatch.setattr(chain, "run_stage", running)
    monkeypatch.setattr(case_module.CaseData, "forget", recording)
    chain.run_case_data(*args, **options)
    return after


def test_values_let_go_are_read_by_no_later_stage(offset_case, tmp_path, monkeypatch):
    """run_case lets a value go once no stage from there on reads it under the settings; a stage
    may read only what it declares (tests/test_stage_contract.py), so no stage reads a value let go.
    The offset case applies Step 2 (the calibrated estimate has no file without --artifacts): the
    cropped trajectories go after Step 2 (the matched poses are in memory; no metric asks for
    them), the calibrated estimate after Step 3, and the records stay."""
    after = let_go_after(monkeypatch, *offset_case, tmp_path / "out", resolved())
    assert after["loaded"] == "crop" and after["sync_matched"] == "calibrate"
    assert after["cropped"] == "calibrate" and after["calibrated"] == "align"
    assert after["matched"] == "efficiency" and after["rpe_segments"] == "drift"
    assert not {st.result for st in chain.STAGES} & set(after)
    records = chain.run_case(*offset_case, tmp_path / "out", resolved())
    assert records["metrics"]["extrinsic_rot_deg"] is not None  # Step 2 applied
    assert not (tmp_path / "out/04_calibrate/est.tum").exists()
    rpg = let_go_after(monkeypatch, *offset_case, tmp_path / "rpg", resolved(mode="rpg"))
    assert rpg["cropped"] == rpg["calibrated"] == "metrics"  # its metric reads both


def test_the_metrics_stage_reads_the_cropped_and_calibrated_poses_only_where_a_metric_asks():
    """Under the defaults no metric asks for the cropped trajectories or the calibrated estimate:
    epa eval lets them go before the metrics stage (at 1M poses 120 MB, and the stage's
    temporaries then reuse freed memory); a metric that asks keeps them."""
    cfg = resolved()
    assert chain.reads_under("metrics", cfg) == frozenset(chain.BY_NAME["metrics"].reads) - {
        "cropped",
        "calibrated",
    }
    rpg = resolved(mode="rpg")  # its metric asks for the unaligned (calibrated) estimate
    assert {"cropped", "calibrated"} <= chain.reads_under("metrics", rpg)
    tum = resolved(metrics={"tum": {"enabled": True}})  # its own association: the cropped
    assert "cropped" in chain.reads_under("metrics", tum)
    assert "calibrated" not in chain.reads_under("metrics", tum)
    auto = resolved(metrics={"segments": "auto"})  # lengths of the whole cropped reference
    assert "cropped" in chain.reads_under("metrics", auto)
    assert chain.reads_under("drift", cfg) == frozenset(chain.BY_NAME["drift"].reads)


def test_a_value_in_memory_keeps_nothing_it_would_be_read_again_from(offset_case, tmp_path):
    """What a value is read again from (its needs: the matched poses' cropped trajectories and
    pairs) is kept only while that value is not in memory."""
    data = chain.CaseData(CaseFolder(tmp_path))
    data.cropped, data.calibrate_pairs = ("ref", "est"), ("i", "j")
    assert chain.unread(data, {"matched"}) == []  # matched would be read from them
    data.matched = ("ref m", "est m")
    assert chain.unread(data, {"matched"}) == ["cropped", "calibrate_pairs"]
    assert chain.unread(data, set()) == ["cropped", "calibrate_pairs", "matched"]
    records = chain.run_case(*offset_case, tmp_path / "out", resolved())
    assert records["consistency"] and records["efficiency"]


def test_pool_workers_do_not_import_the_main_scripts_imports_again(tmp_path):
    """multiprocessing re-runs the parent's main script in every new worker; under Snakemake's
    console script that imports its whole command line before the first job's work. The fork
    server imports the script's imports once (jobs._main_imports); the workers, forked from it,
    find them imported. Nothing of multiprocessing is patched."""
    import subprocess
    import sys

    marker = tmp_path / "imported"
    (tmp_path / "heavy.py").write_text(
        f"import os\nopen({str(marker)!r}, 'a').write(f'{{os.getpid()}}\\n')\n"
    )
    script = tmp_path / "main_script.py"
    script.write_text(
        "import os\n"
        "import heavy  # noqa: F401\n"
        "if __name__ == '__main__':\n"
        "    from epa.workflow import jobs\n"
        "    pool = jobs._pool(2)\n"
        "    pids = {f.result() for f in [pool.submit(os.getpid) for _ in range(8)]}\n"
        "    jobs.close_pool()\n"
        "    print(' '.join(map(str, pids)))\n"
    )
    out = subprocess.run(
        [sys.executable, str(script)], check=True, capture_output=True, text=True, cwd=tmp_path
    )
    workers = set(map(int, out.stdout.split()))
    importers = set(map(int, marker.read_text().split()))
    assert workers and not workers & importers  # no worker imported it
    assert len(importers) == 2  # the script itself and the fork server
