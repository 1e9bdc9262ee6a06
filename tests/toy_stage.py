"""A stage added by a test, as a new stage module would be: it reads Step 2's calibrated estimate
(which has no file in `epa eval` without --artifacts) and records its length. ``register()`` appends
it to the stage list (tests/test_stage_contract.py; a wrapper Snakefile calls it before the
workflow's rules are made)."""

import sys

from epa.artifacts import stage as stage_list
from epa.artifacts.case import CaseData, Record
from epa.artifacts.stage import Stage, Value

NAME = "toy"


def run(data: CaseData, cfg: dict, write_arrays: bool) -> None:
    ref, est = data.calibrated
    record = {"n": len(est), "est_length_m": est.length(), "align": cfg["align"]["method"]}
    data.toy_record = record
    data.folder.write_record(NAME, "toy.json", record)


STAGE = Stage(
    name=NAME,
    run=run,
    settings=("align",),
    records=("toy.json",),
    reads=("calibrated",),
    values=(Value("toy_record", Record, lambda s: s.f.record(NAME, "toy.json")),),
    result="toy_record",
)
MODULE = f"epa.workflow.stages.{NAME}"


def register(setattr=setattr, setitem=None) -> None:
    """Append the stage to the list (``setattr``/``setitem``: a monkeypatch's, to undo it after)."""
    setattr(stage_list, "ORDER", (*stage_list.ORDER, NAME))
    if setitem is None:
        sys.modules[MODULE] = sys.modules[__name__]
    else:
        setitem(sys.modules, MODULE, sys.modules[__name__])
