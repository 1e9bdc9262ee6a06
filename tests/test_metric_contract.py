"""The metric contract in code: a wrong declaration fails when it is built or when the registry
loads, a record is placed by its ``after`` wherever its anchor is in the list and never dropped, and
a stage and the tables rule read every section their metrics declare."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from epa.core.trajectory import Trajectory
from epa.metrics import registry
from epa.metrics.spec import Metric, Table
from epa.workflow import chain
from epa.workflow.stages import metrics as metrics_stage

ROOT = Path(__file__).resolve().parents[1]


def metric(key="extra", **fields) -> Metric:
    base = dict(
        key=key,
        stage="metrics",
        enabled=lambda cfg: True,
        summary=lambda record: {},
        compute=lambda ref, est, cfg: ({"value": 1.0}, {}, []),
        after="ate",
    )
    return Metric(**(base | fields))


def test_the_registry_is_valid_and_lists_declarations():
    assert all(isinstance(m, Metric) for m in registry.REGISTRY)
    assert registry.validate(registry.REGISTRY) == registry.REGISTRY


@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(compute=None), "needs compute"),
        (dict(enabled=None), "enabled must be callable"),
        (dict(summary="none"), "summary must be callable"),
        (dict(arrays="a.csv"), "arrays must be a tuple"),
        (dict(settings=("metrics..x",)), "settings"),
        (dict(inputs="everything"), "inputs must be a tuple"),
        (dict(tables=("ate",)), "tables must be a tuple of Table"),
        (dict(stage="drift", after="ate"), "belong to metrics of the metrics stage"),
        (dict(key=""), "key must be a non-empty string"),
    ],
)
def test_a_wrong_field_fails_when_the_metric_is_built(fields, message):
    with pytest.raises((TypeError, ValueError), match=message):
        metric(**fields)


def test_an_input_the_metrics_stage_does_not_give_fails_when_it_loads():
    from epa.workflow.stages import metrics as stage

    stage.check_inputs(registry.computed_in("metrics"))  # the registered ones: all given
    with pytest.raises(ValueError, match=r"metric 'extra': inputs \['everything'\]"):
        stage.check_inputs([metric(inputs=("everything",))])
    # every name the stage lists is given: by PROVIDED, or by compute on its way
    assert set(stage.INPUTS) - set(stage.PROVIDED) == {"pair_rows", "accuracy"}


def test_a_missing_field_fails_when_the_metric_is_built():
    with pytest.raises(TypeError, match="summary"):
        Metric(key="extra", stage="metrics", enabled=lambda cfg: True)


def test_a_declaration_is_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        registry.REGISTRY[0].after = "nothing"


def test_an_unknown_after_fails_when_the_registry_loads():
    with pytest.raises(ValueError, match=r"metric 'extra': after 'ate2d'"):
        registry.validate(registry.REGISTRY + (metric(after="ate2d"),))


def test_after_a_metric_of_another_stage_fails():
    with pytest.raises(ValueError, match="after 'consistency'"):
        registry.validate(registry.REGISTRY + (metric(after="consistency"),))


def test_a_cycle_of_anchors_fails():
    a, b = metric("a", after="b"), metric("b", after="a")
    with pytest.raises(ValueError, match="cycle"):
        registry.validate((a, b))
    with pytest.raises(ValueError, match="cycle"):
        registry.validate((metric("a", after="a"),))


@pytest.mark.parametrize(
    "extra, field",
    [
        (metric("kitti"), "key"),
        (metric(arrays=("kitti_segments.csv",)), "arrays"),
        (metric(summary_columns=("kitti_trans_pct",)), "summary_columns"),
        (metric(tables=(Table("kitti", "AGAIN"),)), "tables"),
        (metric(summary_columns=("x", "x")), "summary_columns"),
    ],
)
def test_a_name_registered_twice_fails(extra, field):
    with pytest.raises(ValueError, match=f"metric 'extra'.*{field}|metric 'kitti': key"):
        registry.validate(registry.REGISTRY + (extra,))


def test_a_table_after_an_unknown_table_fails():
    bad = metric(tables=(Table("extra", "EXTRA", after="ate_3d"),))
    with pytest.raises(ValueError, match="table 'extra' follows 'ate_3d'"):
        registry.validate(registry.REGISTRY + (bad,))
    # a base table or another metric's table is fine
    ok = metric(tables=(Table("extra", "EXTRA", after="ate_2d"),))
    registry.validate(registry.REGISTRY + (ok,))


def test_a_module_without_a_declaration_fails():
    with pytest.raises(TypeError, match="not a Metric"):
        registry.validate(registry.REGISTRY + (object(),))


def _poses(n=200):
    t = np.arange(n, dtype=float)
    p = np.column_stack([0.1 * t, np.sin(0.05 * t), np.zeros(n)])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    return Trajectory(t, p, q)


def _cfg():
    from epa.workflow import settings

    return settings.resolve({"truth_dir": "t", "algorithms_dir": "a", "results_dir": "r"})


def test_a_record_follows_an_anchor_listed_after_it(monkeypatch):
    """A metric listed before the metric it follows still lands right after it in metrics.json
    (before this was checked, its record vanished)."""
    first = metric("first", after="second")
    second = metric("second", after="ate")
    monkeypatch.setattr(registry, "REGISTRY", registry.validate((first, second)))
    ref = _poses()
    summary, _ = metrics_stage.compute(ref, ref, _cfg(), {})
    keys = list(summary)
    assert keys[keys.index("ate") + 1 : keys.index("ate") + 3] == ["second", "first"]


def test_a_record_whose_anchor_is_off_follows_the_anchors_anchor(monkeypatch):
    off = metric("off", after="ate", enabled=lambda cfg: False)
    on = metric("on", after="off")
    monkeypatch.setattr(registry, "REGISTRY", registry.validate((off, on)))
    ref = _poses()
    summary, _ = metrics_stage.compute(ref, ref, _cfg(), {})
    keys = list(summary)
    assert "off" not in keys and keys[keys.index("ate") + 1] == "on"


def test_insert_never_drops_a_record():
    assert list(metrics_stage._insert({"a": 1}, "b", 2, after="missing")) == ["a", "b"]


def test_a_stage_and_the_tables_rule_read_every_section_their_metrics_declare(monkeypatch):
    cfg = {**_cfg(), "tables": {"decimals": 3}, "drift": {"x": 1}}
    assert "drift" not in chain.settings_for("metrics", cfg)
    reads_drift = metric("reads_drift", settings=("drift.x", "metrics.segments"))
    monkeypatch.setattr(registry, "REGISTRY", registry.validate(registry.REGISTRY + (reads_drift,)))
    assert chain.settings_for("metrics", cfg)["drift"] == {"x": 1}
    assert chain.tables_settings(cfg)["drift"] == {"x": 1}
    # what the registered metrics read today: efficiency's section (sim3_check reads the
    # alignment Step 3 fitted from transform.json, not align)
    assert {"efficiency", "tables", "metrics", "mode"} <= set(chain.tables_settings(cfg))


def test_the_tables_rule_takes_its_settings_from_the_registry():
    """rules/tables.smk passes the derived subset, not a hand-built dict."""
    rule = (ROOT / "rules/tables.smk").read_text()
    assert re.search(r"settings=epa_chain\.tables_settings\(EPA\)", rule)


def test_every_metric_module_is_registered_once_and_listed():
    """The registry names each module once (MODULES), every module declaring a METRIC is in it, and
    the package's __all__ is its modules as they are."""
    import importlib
    import pkgutil

    import epa.metrics

    names = sorted(m.name for m in pkgutil.iter_modules(epa.metrics.__path__))
    assert epa.metrics.__all__ == names and {"accuracy", "tum", "registry"} <= set(names)
    declaring = [n for n in names if hasattr(importlib.import_module(f"epa.metrics.{n}"), "METRIC")]
    assert sorted(registry.MODULES) == declaring
    assert [m.key for m in registry.REGISTRY][:3] == ["ate_2d", "consistency", "efficiency"]
