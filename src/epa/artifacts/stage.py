"""The stage contract in code: the stage list (:data:`ORDER`), which also lays out a case folder
(``01_load`` ... ``10_report``: a stage's position, then its name), and the declaration each stage
module makes of itself (:class:`Stage`, with the values it hands on: :class:`Value`).

A stage module (:mod:`epa.workflow.stages`) declares ``STAGE = Stage(...)``; the chain
(:mod:`epa.workflow.chain`) derives the rest from the declarations: the stage rules, ``CaseData``'s
fields (:func:`epa.artifacts.case.data_class`), after which stage ``epa eval`` lets each value go,
and the records ``epa eval`` returns. Adding a stage is its module and one name here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

# The stages in the order they run: each reads only what the stages before it hand on.
ORDER: tuple[str, ...] = (
    "load",
    "crop",
    "sync",
    "calibrate",
    "align",
    "metrics",
    "drift",
    "consistency",
    "efficiency",
    "report",
)


def folder(stage: str) -> str:
    """A stage's folder in a case folder: its position in :data:`ORDER` (from 01), then its name."""
    if stage not in ORDER:
        raise KeyError(f"no stage {stage!r}; the stages are {', '.join(ORDER)}")
    return f"{ORDER.index(stage) + 1:02d}_{stage}"


@dataclass(frozen=True, eq=False)
class Value:
    """A value a stage hands on to later stages: a field of ``CaseData``.

    ``type`` is its annotation (``Trajectory``, ``tuple[Trajectory, Trajectory]``, ``dict[str,
    Any]``, ...). ``read(data)`` gives it back from the stage's artifacts where it is not in memory
    (a workflow job runs one stage); ``needs`` names the other values ``read`` uses (a stage reading
    this value may read those too)."""

    name: str
    type: Any
    read: Callable[[Any], Any]
    needs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.name.isidentifier() or self.name.startswith("_"):
            raise ValueError(f"value {self.name!r}: not a public attribute name")


@dataclass(frozen=True, eq=False)
class Stage:
    """What a stage is: ``run(data, cfg, write_arrays)`` with what it reads and writes.

    - ``settings``: the config sections it reads (a change re-runs it onward; the chain adds those
      its registered metrics declare);
    - ``records``, ``arrays``: the JSON records it always writes and the files it writes only where
      arrays are written (their failure markers and killed-write temporaries are handled from these);
      a stage may also write a folder of documents of its own (metrics, report);
    - ``reads``: the ``CaseData`` values of earlier stages ``run`` reads (only these are readable
      while it runs);
    - ``values``: the values it hands on;
    - ``result``: the value ``epa eval`` returns under the stage's name (None: none);
    - ``reads_for(settings)``: those of ``reads`` it reads under its settings (the chain's subset,
      :func:`epa.workflow.chain.settings_for`), where some are read only under some settings;
      ``epa eval`` lets the others go before it runs (None: every one of ``reads``)."""

    name: str
    run: Callable[[Any, dict, bool], None]
    records: tuple[str, ...]
    settings: tuple[str, ...] = ()
    arrays: tuple[str, ...] = ()
    reads: tuple[str, ...] = ()
    values: tuple[Value, ...] = ()
    result: str | None = None
    reads_for: Callable[[dict], tuple[str, ...]] | None = None

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"stage {self.name!r}: not a plain name")
        if not self.records or not all(n.endswith(".json") for n in self.records):
            raise ValueError(f"stage {self.name}: records must be one or more .json files")
        names = [v.name for v in self.values]
        if len(set(names)) != len(names):
            raise ValueError(f"stage {self.name}: a value handed on twice in {names}")
        if self.result is not None and self.result not in names:
            raise ValueError(
                f"stage {self.name}: result {self.result!r} is not a value it hands on"
            )

    @property
    def artifacts(self) -> tuple[str, ...]:
        return self.records + self.arrays
