"""The typed records (epa.core.records) are what the files hold: every sync.json, calibrate.json,
transform.json and metrics.json of the bundled example's golden copies, and of a case in mode
ov_eval and mode rpg, has each required key, no key the declaration does not know (metrics.json:
beyond the time RPE's and the registered metrics'), and values of the declared kinds."""

import json
import types
import typing
from pathlib import Path

import pytest

from epa import simulate
from epa.cli import main as cli
from epa.core import records
from epa.metrics import accuracy, registry

GOLDEN = Path(__file__).parent / "golden/example/records/cases"
FILES = {
    "03_sync/sync.json": records.SyncRecord,
    "04_calibrate/calibrate.json": records.CalibrateRecord,
    "05_align/transform.json": records.TransformRecord,
    "06_metrics/metrics.json": records.MetricsRecord,
}
# a written non-finite number is text (the numeric contract's "inf", "nan")
NON_FINITE = {"inf", "-inf", "nan"}


def problems(value, hint, where: str) -> list[str]:
    """Where ``value`` (read from JSON) is not of the declared ``hint``."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.NotRequired:
        return problems(value, args[0], where)
    if origin in (types.UnionType, typing.Union):
        found = [problems(value, h, where) for h in args]
        return [] if any(not f for f in found) else found[0]
    if typing.is_typeddict(hint):
        return typed_dict_problems(value, hint, where)
    if hint is type(None):
        return [] if value is None else [f"{where}: {value!r} is not null"]
    if origin is dict:
        if not isinstance(value, dict):
            return [f"{where}: not an object"]
        return [p for k, v in value.items() for p in problems(v, args[1], f"{where}.{k}")]
    if origin is list:
        if not isinstance(value, list):
            return [f"{where}: not a list"]
        return [p for k, v in enumerate(value) for p in problems(v, args[0], f"{where}[{k}]")]
    if hint is dict:
        return [] if isinstance(value, dict) else [f"{where}: not an object"]
    if hint is float:
        ok = (isinstance(value, int | float) and not isinstance(value, bool)) or value in NON_FINITE
        return [] if ok else [f"{where}: {value!r} is not a number"]
    if hint is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
        return [] if ok else [f"{where}: {value!r} is not an integer"]
    return [] if isinstance(value, hint) else [f"{where}: {value!r} is not {hint.__name__}"]


def typed_dict_problems(value, td, where: str, extra=frozenset()) -> list[str]:
    if not isinstance(value, dict):
        return [f"{where}: not an object"]
    hints = typing.get_type_hints(td, include_extras=True)
    out = [f"{where}: no {k!r}" for k in td.__required_keys__ if k not in value]
    out += [f"{where}: unknown key {k!r}" for k in value if k not in hints and k not in extra]
    for k, hint in hints.items():
        if k in value:
            out += problems(value[k], hint, f"{where}.{k}")
    return out


def record_problems(path: Path, td) -> list[str]:
    doc = json.loads(path.read_text())
    extra = set()
    if td is records.MetricsRecord:
        # beyond the declaration: the time RPE, under its time_delta's key, and the metrics' records
        time_rpe = accuracy.time_rpe_in(doc)
        assert time_rpe is not None, f"{path}: no time RPE"
        key = "rpe_time_" + time_rpe[0]
        extra = {key} | {m.key for m in registry.computed_in("metrics")}
        found = problems(doc[key], records.TimeRpe, f"{path}:{key}")
        return found + typed_dict_problems(doc, td, str(path), frozenset(extra))
    return typed_dict_problems(doc, td, str(path))


@pytest.mark.parametrize("name", sorted(FILES))
def test_the_golden_records_are_their_declarations(name):
    paths = sorted(GOLDEN.glob(f"*/*/*/{name}"))
    assert len(paths) == 18  # 3 algorithms x 3 datasets x 2 runs
    assert [p for path in paths for p in record_problems(path, FILES[name])] == []


def test_the_golden_records_take_the_optional_paths():
    """The golden copies hold both sides of the optional keys the test above checks: a case without
    Step 2's extrinsic and one re-associated after the plan dropped Step 1's offset."""
    docs = [json.loads(p.read_text()) for p in GOLDEN.glob("*/*/*/04_calibrate/calibrate.json")]
    assert any(d["extrinsic"] is None for d in docs) and any(d["extrinsic"] for d in docs)
    assert any("reassociated" in d for d in docs) and any("reassociated" not in d for d in docs)


@pytest.mark.parametrize("mode", ["ov_eval", "rpg"])
def test_the_records_of_the_other_modes_are_their_declarations(mode, tmp_path):
    """Step 1 disabled (its short record), no extrinsic, rpg's fit."""
    simulate.simulate(tmp_path / "sim")
    ref = tmp_path / "sim/truth/drone_figure8.txt"
    est = tmp_path / "sim/algorithms/vio_camera/drone_figure8/run1.csv"
    out = tmp_path / "out"
    assert cli.main(["eval", str(ref), str(est), "--out", str(out), "--mode", mode]) == 0
    sync = json.loads((out / "03_sync/sync.json").read_text())
    assert set(sync["step1"]) == records.Step1Record.__required_keys__  # disabled: the short form
    assert [p for name, td in FILES.items() for p in record_problems(out / name, td)] == []
