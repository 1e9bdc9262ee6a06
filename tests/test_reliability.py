"""Settings refuse every non-finite number and every negative length, rate and delta, whatever the
key; command-line overrides are coerced as YAML would read them; the TF search is the same under
every hash seed. A quantity without samples is None with a note in its record, never NaN, and the
JSON writer refuses a NaN. A killed write leaves a temporary that the next job removes, and nothing
else."""

import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import catalogue
import numpy as np
import pytest

from epa.artifacts import files
from epa.artifacts.case import CaseFolder
from epa.artifacts.stage import folder
from epa.core.errors import EpaError
from epa.metrics import accuracy
from epa.workflow import chain, settings
from epa.workflow import jobs as grid
from epa.workflow.stages import calibrate as calibrate_stage
from epa.workflow.stages import sync

ROOT = Path(__file__).resolve().parents[1]
BASE = {"truth_dir": "t", "algorithms_dir": "a"}
# numbers that may be negative, and why: a time offset has a sign; -1 is first_n's "all"
SIGNED = {
    "sync.offset": "a time offset has a sign",
    "align.first_n": "-1 = all (minimum -1)",
    "metrics.tum.offset": "a time offset has a sign",
    "metrics.hilti.lever_arm_m.0": "a lever arm's component has a sign",
    "metrics.hilti.year": "one of two years (an enum)",
}


def _numeric_keys(sch: dict, root: dict, prefix: str = ""):
    """(dotted key, schema) of every number in the schema ("*" for a free name, "0" for an item)."""
    if "$ref" in sch:
        sch = settings._pointer(root, sch["$ref"])
    for branch in sch.get("anyOf", ()):  # a list or a word (metrics.segments)
        yield from _numeric_keys(branch, root, prefix)
    types = sch.get("type")
    types = types if isinstance(types, list) else [types]
    if "number" in types or "integer" in types:
        yield prefix, sch
    for k, sub in sch.get("properties", {}).items():
        if not prefix and k == "overrides":  # the top-level sections again, by $ref
            continue
        yield from _numeric_keys(sub, root, f"{prefix}.{k}" if prefix else k)
    if isinstance(sch.get("additionalProperties"), dict):
        yield from _numeric_keys(sch["additionalProperties"], root, f"{prefix}.x")
    if isinstance(sch.get("items"), dict):
        yield from _numeric_keys(sch["items"], root, f"{prefix}.0")


def _config_with(key: str, value) -> dict:
    """A config setting ``key`` (dotted; "0" an item, "x" a free name) to ``value``."""

    def nest(parts: list[str]):
        if not parts:
            return value
        head, rest = parts[0], parts[1:]
        if head == "0":
            item = nest(rest)
            if key.startswith("metrics.rpe.") and isinstance(item, dict):
                item = {"delta": 1.0, "unit": "m", **item}  # what an rpe item requires
            return [item]
        return {head: nest(rest)}

    return {**BASE, **nest(key.split("."))}


NUMERIC = sorted(_numeric_keys(settings.schema(), settings.schema()))


def test_every_number_has_a_lower_bound_or_a_reason_to_be_signed():
    unbounded = [
        k
        for k, sch in NUMERIC
        if k not in SIGNED and "minimum" not in sch and "exclusiveMinimum" not in sch
    ]
    assert not unbounded, f"numbers without a lower bound: {unbounded}"


@pytest.mark.parametrize("key", [k for k, _ in NUMERIC])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_every_number_refuses_nan_and_inf(key, value):
    with pytest.raises(EpaError) as err:
        settings.resolve(_config_with(key, value))
    assert f"{key}: {value} is not a finite number" in err.value.one_line()


@pytest.mark.parametrize("key", [k for k, _ in NUMERIC if k not in SIGNED])
def test_every_length_rate_and_delta_refuses_a_negative(key):
    with pytest.raises(EpaError, match="minimum"):
        settings.resolve(_config_with(key, -5))


def test_command_line_overrides_are_read_as_yaml_would():
    given = {
        "report": {"per_case": "false", "pdf": "True"},
        "grid": {"max_batches": "4"},
        "sync": {"max_diff": "null", "window": "2.5"},
        "metrics": {"segments": ["8", "16.5"]},
        "sources": {"algorithms": {"a": {"topic": "123"}}},
    }
    cfg = settings.coerce_overrides({**BASE, **given}, given)
    assert cfg["report"] == {"per_case": False, "pdf": True}
    assert cfg["grid"]["max_batches"] == 4 and cfg["sync"] == {"max_diff": None, "window": 2.5}
    assert cfg["metrics"]["segments"] == [8, 16.5]
    assert cfg["sources"]["algorithms"]["a"]["topic"] == "123"  # a string key stays a string
    settings.resolve(cfg)
    # a config file's own quoted "false" is not coerced: only what the command line gave
    with pytest.raises(EpaError, match="'false' is not of type 'boolean'"):
        settings.resolve(settings.coerce_overrides({**BASE, "report": {"per_case": "false"}}, {}))


def test_a_tf_loop_is_the_same_error_under_every_hash_seed(tmp_path):
    import catalogue
    from test_bags import _write_tf

    from epa.core.trajectory import Trajectory

    good = Trajectory(catalogue.T[:50], catalogue.P[:50], catalogue.Q[:50])
    _write_tf(
        tmp_path / "loop.bag",
        {("world", "odom"): good, ("odom", "world"): good, ("odom", "body"): good},
        static={},
    )
    _write_tf(
        tmp_path / "tree.bag",
        {("world", "odom"): good, ("odom", "body"): good, ("world", "map"): good},
        static={},
    )
    outs = set()
    for seed in ("0", "1", "2", "3"):
        lines = []
        for bag in ("loop.bag", "tree.bag"):
            run = subprocess.run(
                [sys.executable, "-m", "epa.cli.main", "traj", bag, "--topic", "/tf"]
                + ["--frames", "world", "body", "--export", f"{seed}.txt"],
                cwd=tmp_path,
                capture_output=True,
                text=True,
                env={**os.environ, "PYTHONHASHSEED": seed},
            )
            lines.append((run.returncode, run.stderr.strip()))
        outs.add(tuple(lines) + ((tmp_path / f"{seed}.txt").read_bytes(),))
    assert len(outs) == 1, outs
    (loop, tree, _) = outs.pop()
    assert loop[0] == 2 and "the TF frames form a loop (odom -> world and world -> odom" in loop[1]
    assert tree[0] == 0


# ----------------------------------------------------------------------------- None, never NaN
EMPTY = {"n": 0, **dict.fromkeys(("rmse", "mean", "median", "std", "min", "max"))}


def _nan_keys(obj, where: str = "") -> list[str]:
    """Every NaN in a record as it is in memory (dicts, lists, arrays, floats)."""
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _nan_keys(v, f"{where}.{k}")]
    if isinstance(obj, (list, tuple)):
        return [p for k, v in enumerate(obj) for p in _nan_keys(v, f"{where}[{k}]")]
    if isinstance(obj, np.ndarray):
        return [where] if obj.dtype.kind == "f" and np.isnan(obj).any() else []
    return [where] if isinstance(obj, float) and math.isnan(obj) else []


def _strict_json(path: Path) -> dict:
    def refuse(token):
        raise ValueError(f"{path}: {token} is not JSON")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def _case(tmp_path, row_id: str, cfg: dict):
    """A catalogue row's reference and estimate run through every stage as ``epa eval`` runs them."""
    row = next(b for b in catalogue.CATALOGUE if b.id == row_id)
    (tmp_path / "ref.txt").write_text(row.ref)
    (tmp_path / "est.txt").write_text(row.est)
    cfg = settings.resolve({**BASE, **cfg})
    return chain.run_case(tmp_path / "ref.txt", tmp_path / "est.txt", tmp_path / "out", cfg)


def test_an_empty_sample_has_none_statistics_not_nan():
    assert accuracy.stats(np.zeros(0)) == EMPTY
    assert accuracy.drift_rate(np.zeros(0), 8.0) is None
    assert accuracy.stats([3.0, 4.0])["rmse"] == pytest.approx(math.sqrt(12.5), rel=1e-15)


def test_three_matched_poses_give_null_rpe_with_a_note_never_nan(tmp_path):
    records = _case(tmp_path, "three-matched", {"sync": {"min_pairs": 3}})
    assert _nan_keys(records) == []
    m, d = records["metrics"], records["drift"]
    assert m["n_matched"] == 3 and m["ate"]["trans_m"]["n"] == 3
    for key in ("8", "16", "24", "32", "40", "48"):
        assert m["rpe_distance"][key] == {"trans_m": EMPTY, "rot_deg": EMPTY}
        assert m["drift_rate_pct"][key] is None
        assert d["drift_valid"]["rpe_distance"][key] == {"trans_m": EMPTY, "rot_deg": EMPTY}
        assert f"no {key} m segment fits in the 2.118 m matched path" in " ".join(m["notes"])
        assert f"no {key} m segment fits in the matched path: its drift-valid" in " ".join(
            d["notes"]
        )
    assert (
        m["rpe_time_1s"]["trans_m"] == EMPTY and d["drift_valid"]["rpe_time_1s"]["rot_deg"] == EMPTY
    )
    assert (
        "no two matched poses are 1 s (±10 %) apart in 0.100 s: the 1 s RPE is empty" in m["notes"]
    )
    assert "no time-RPE pair in the matched poses: the drift-valid time RPE is empty" in d["notes"]
    # Step 1 could not run on 3 poses: what it did not measure is None, its reason says why
    step1 = m["sync"]["step1"]
    assert step1["peak_corr"] is None and step1["dt"] is None
    assert step1["reason"] == "too few poses for a correlation"
    # the files hold null where the record holds None, and parse with any JSON reader
    written = _strict_json(tmp_path / "out/06_metrics/metrics.json")
    assert written["rpe_time_1s"]["trans_m"] == EMPTY and written["notes"] == m["notes"]
    assert _strict_json(tmp_path / "out/07_drift/drift.json")["notes"] == d["notes"]


def test_pure_translation_without_rotation_has_a_null_drift_valid_ate_with_a_note(tmp_path):
    off = {"sync": {"estimate_offset": False}, "calibrate": {"enabled": False}}
    records = _case(tmp_path, "pure-translation-drifting", {**off, "align": {"method": "posyaw"}})
    assert _nan_keys(records) == []
    d = records["drift"]
    assert d["success_rate_distance_pct"] == 0 and not d["global_failed"] and "status" not in d
    assert d["drift_valid"]["ate"] == {"trans_m": EMPTY, "rot_deg": EMPTY}
    assert d["drift_valid"]["drift_rate_pct"] == dict.fromkeys(("8", "16", "24", "32", "40", "48"))
    assert d["notes"] == [
        "no drift-valid interval (distance success rate 0 %): every drift-valid metric is empty"
    ]
    assert records["metrics"]["ate"]["trans_m"]["n"] == 600  # the ATE itself stands
    assert (
        _strict_json(tmp_path / "out/07_drift/drift.json")["drift_valid"]["ate"]["rot_deg"] == EMPTY
    )


def test_step2_on_one_time_block_has_null_uncertainty_with_a_note_never_nan(tmp_path):
    """2.2 s of motion: every motion pair in one 2 s block, so the uncertainty is undefined: every
    entry of both covariances NaN, written as null with a note (never NaN, never a mix of inf and
    null that rounding-level zeros decided), and the status uncertain."""
    t, p, q = catalogue.motion(45)
    (tmp_path / "ref.txt").write_text(catalogue._rows(t, p, q))
    (tmp_path / "est.txt").write_text(catalogue._rows(t, p, q))
    cfg = settings.resolve(BASE)
    records = chain.run_case(tmp_path / "ref.txt", tmp_path / "est.txt", tmp_path / "out", cfg)
    assert _nan_keys(records) == []
    ext = records["metrics"]["calibrate"]["extrinsic"]
    assert ext["status"] == "uncertain" and "rotation std undefined" in ext["reason"]
    assert ext["rotation_std_deg"] == [None] * 3 and ext["translation_std_m"] == [None] * 3
    for key in ("rotation_covariance_rad2", "translation_covariance"):
        assert ext[key] == [[None] * 3] * 3
    assert ext["notes"] == [calibrate_stage.UNDEFINED_UNCERTAINTY]
    written = _strict_json(tmp_path / "out/04_calibrate/calibrate.json")["extrinsic"]
    assert written["translation_std_m"] == [None] * 3
    assert written["rotation_covariance_rad2"] == [[None] * 3] * 3


def test_write_json_refuses_nan_naming_its_key_and_writes_nothing(tmp_path):
    record = {"rpe_distance": {"8": {"trans_m": {"n": 0, "rmse": np.float64("nan")}}}}
    with pytest.raises(ValueError, match=r"metrics\.json: NaN at rpe_distance\.8\.trans_m\.rmse"):
        files.write_json(tmp_path / "metrics.json", record)
    assert list(tmp_path.iterdir()) == []  # neither the file nor a temporary
    with pytest.raises(ValueError, match=r"NaN at curve\[1\]"):
        files.write_json(tmp_path / "d.json", {"curve": np.array([1.0, np.nan])})


def test_write_json_keeps_its_bytes_for_every_other_value(tmp_path):
    record = {
        "a": np.float64(0.1),
        "ratio": float("inf"),  # Step 1's peak_ratio with no second peak: the string "inf"
        "neg": -np.inf,
        "xs": np.array([np.float32(0.25), 2.0]),
        "n": np.int64(3),
        "ok": np.bool_(True),
        "none": None,
        1: "key",
    }
    files.write_json(tmp_path / "r.json", record)
    assert (tmp_path / "r.json").read_text() == (
        '{\n  "a": 0.1,\n  "ratio": "inf",\n  "neg": "-inf",\n  "xs": [\n    0.25,\n    2.0\n  ],\n'
        '  "n": 3,\n  "ok": true,\n  "none": null,\n  "1": "key"\n}'
    )


def test_write_json_writes_json_dumps_text_for_every_kind_of_value(tmp_path):
    """The fast indented writer against json.dumps(indent=2) of the plain values, on the values
    stage records hold (and on those it hands back to json.dumps)."""
    values = [
        {},
        [],
        (),
        {"a": {}, "b": [], "c": [[], {}], "d": ()},
        {"x": [1, 2.5, -0.0, 1e300, 5e-324, True, False, None, 'é\n"', np.float32(0.1)]},
        {"nested": {"deeper": [{"k": np.arange(3)}, np.zeros((2, 2)), np.array([True, False])]}},
        {"ints": [np.int32(-4), np.uint8(7), 10**30], "f16": np.float16(1.5), "s": np.str_("x")},
        {"inf": [np.inf, -np.float32(np.inf)], "scalar0d": np.array(2.0), "tuple": (1, (2, 3))},
        {1: "int key", None: "none key", 2.5: "float key"},  # keys json.dumps turns into strings
        {"path": Path("a/b")},  # no JSON value: json.dumps' TypeError either way
    ]
    for k, value in enumerate(values):
        try:
            expected = json.dumps(files._jsonable(value), indent=2, allow_nan=False)
        except TypeError:
            with pytest.raises(TypeError):
                files.write_json(tmp_path / f"{k}.json", value)
            continue
        files.write_json(tmp_path / f"{k}.json", value)
        assert (tmp_path / f"{k}.json").read_text() == expected, value


def test_write_json_of_a_numpy_infinity_warns_nothing(tmp_path):
    """np.float64(inf) - itself warns in numpy: a warning would land in a case's log as new text."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        files.write_json(tmp_path / "r.json", {"peak_ratio": np.float64("inf")})
    assert (tmp_path / "r.json").read_text() == '{\n  "peak_ratio": "inf"\n}'


# ----------------------------------------------------------------------------- killed writes
def test_a_sigkilled_write_leaves_only_a_temporary_which_the_cleanup_removes(tmp_path):
    """A real SIGKILL in the middle of an atomic write: no xcorr.csv, a `.xcorr.csv.<random>`."""
    folder = tmp_path / "03_sync"
    code = (
        "import sys, time\n"
        "from epa.artifacts import files\n"
        "def write(fh):\n"
        "    fh.write('lag_s,corr\\n-0.5,0.1')\n"
        "    fh.flush()\n"
        "    time.sleep(60)\n"
        f"files.write_text({str(folder / 'xcorr.csv')!r}, '')\n"
        f"files._atomic_write({str(folder / 'xcorr.csv')!r}, write)\n"
    )
    (folder / "sync.json").parent.mkdir()
    (folder / "sync.json").write_text("{}")
    proc = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.time() + 60
    while time.time() < deadline and not any(p.stat().st_size for p in folder.glob(".xcorr.csv.*")):
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    left = [p.name for p in folder.glob(".xcorr.csv.*")]
    assert len(left) == 1 and (folder / "xcorr.csv").read_text() == ""  # the old one stands
    removed = CaseFolder(tmp_path).remove_temporaries("sync", sync.STAGE.artifacts)
    assert removed == left
    assert sorted(p.name for p in folder.iterdir()) == ["sync.json", "xcorr.csv"]


def test_the_cleanup_matches_every_name_mkstemp_makes_and_nothing_else(tmp_path):
    made = [Path(tempfile.mkstemp(prefix=".xcorr.csv.", dir=tmp_path)[1]).name for _ in range(200)]
    kept = [
        ".xcorr.csv",
        ".xcorr.csv.bak",
        ".xcorr.csv.ABCDEFGH",
        ".notes.csv.abcdefgh",
        "xcorr.csv.abcdefgh",
        ".xcorr.csv.abcdefghi",
        "xcorr.csv",
        ".pairs.csv.lnk",
    ]
    for name in kept:
        (tmp_path / name).write_text("the user's")
    (tmp_path / ".pairs.csv.link").write_text("")  # case.link's temporary
    (tmp_path / ".sync.json.abcd1234").mkdir()  # a folder is no temporary of a file
    removed = files.remove_temporaries(tmp_path, ["xcorr.csv", "pairs.csv"])
    assert sorted(removed) == sorted(made + [".pairs.csv.link"])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept + [".sync.json.abcd1234"])
    assert files.remove_temporaries(tmp_path / "missing", ["xcorr.csv"]) == []


def test_the_next_job_removes_a_killed_runs_temporaries_and_keeps_the_artifacts(tmp_path):
    """Every stage's folder of a case, and the batch manifest's folder, after a killed run."""
    (tmp_path / "truth").mkdir()
    (tmp_path / "truth/seq.txt").write_text(catalogue.GOOD)
    (tmp_path / "algs/a/seq").mkdir(parents=True)
    (tmp_path / "algs/a/seq/run1.txt").write_text(catalogue.GOOD)
    results = tmp_path / "results"
    cfg = settings.resolve(
        {
            "truth_dir": str(tmp_path / "truth"),
            "algorithms_dir": str(tmp_path / "algs"),
            "results_dir": str(results),
            "report": {"per_case": False},
        }
    )
    batch = [
        {
            "key": "a/seq/run1",
            "truth": str(tmp_path / "truth/seq.txt"),
            "estimate": str(tmp_path / "algs/a/seq/run1.txt"),
        }
    ]

    def run_all():
        upstream = None
        for st in chain.STAGES:
            manifest = results / "batches" / "all" / f"{st.name}.json"
            assert grid.run_job(st.name, batch, results, cfg, manifest, upstream) == {
                "a/seq/run1": {"status": "ok"}
            }
            upstream = manifest

    run_all()
    case = results / "cases/a/seq/run1"
    before = {p: p.read_bytes() for p in case.rglob("*") if p.is_file() and "logs" not in p.parts}
    stale = []
    for st in chain.STAGES:
        for name in st.artifacts:
            stale.append(case / folder(st.name) / f".{name}.x7_q2k9z")
    stale.append(results / "batches/all/.sync.json.abc_1234")
    for p in stale:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text('{"half": ')
    user = case / "03_sync" / "my notes.txt"
    user.write_text("mine")
    run_all()
    assert [p for p in stale if p.exists()] == []
    assert user.read_text() == "mine"
    after = {p: p.read_bytes() for p in case.rglob("*") if p.is_file() and "logs" not in p.parts}
    assert after == {**before, user: b"mine"}  # every artifact whole and the same
    assert (case / "logs/sync.log").read_text() == (
        "INFO removed what a killed run left: .pairs.csv.x7_q2k9z, .sync.json.x7_q2k9z,"
        " .xcorr.csv.x7_q2k9z\n"
    )


def test_epa_eval_into_a_folder_a_killed_run_left_removes_its_temporaries(tmp_path):
    """``epa eval --out`` runs every stage in one process: each stage first removes what a killed
    write left in its folder, as a workflow job does."""
    from epa.cli import main as cli

    (tmp_path / "ref.txt").write_text(catalogue.GOOD)
    (tmp_path / "est.txt").write_text(catalogue.GOOD)
    out = tmp_path / "out"
    left = [
        out / folder("sync") / ".sync.json.abcd1234",
        out / folder("metrics") / ".ape.csv.x1y2z3w4",
    ]
    for path in left:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("half a file")
    users = out / folder("sync") / ".sync.json.notes"  # not a temporary's name: kept
    users.write_text("the user's")
    args = ["eval", str(tmp_path / "ref.txt"), str(tmp_path / "est.txt"), "--out", str(out)]
    assert cli.main(args) == 0
    assert not any(p.exists() for p in left) and users.exists()
    assert json.loads((out / folder("metrics") / "metrics.json").read_text())["n_matched"] > 0
