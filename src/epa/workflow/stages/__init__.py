"""One module per stage, named as the stage: what it reads (from :class:`epa.artifacts.case.CaseData`),
computes and writes. Each declares itself once, ``STAGE = Stage(...)``
(:class:`epa.artifacts.stage.Stage`: its settings sections, records, arrays, the values it reads and
those it hands on, ``run(data, cfg, write_arrays)``). Their order is
:data:`epa.artifacts.stage.ORDER`; :mod:`epa.workflow.chain` derives the rest."""

from epa.artifacts.stage import ORDER

__all__ = list(ORDER)
