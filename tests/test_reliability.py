"""Settings refuse every non-finite number and every negative length, rate and delta, whatever the
key; command-line overrides are coerced as YAML would read them; the TF search is the same under
every hash seed."""

import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from epa.core.errors import EpaError
from epa.workflow import settings

ROOT = Path(__file__).resolve().parents[1]
BASE = {"truth_dir": "t", "algorithms_dir": "a"}
# numbers that may be negative, and why: a time offset has a sign; -1 is first_n's "all"
SIGNED = {"sync.offset": "a time offset has a sign", "align.first_n": "-1 = all (minimum -1)"}


def _numeric_keys(sch: dict, root: dict, prefix: str = ""):
    """(dotted key, schema) of every number in the schema ("*" for a free name, "0" for an item)."""
    if "$ref" in sch:
        sch = root["$defs"][sch["$ref"].rsplit("/", 1)[-1]]
    types = sch.get("type")
    types = types if isinstance(types, list) else [types]
    if "number" in types or "integer" in types:
        yield prefix, sch
    for k, sub in sch.get("properties", {}).items():
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
