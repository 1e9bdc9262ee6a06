"""One module per stage, named as the stage: what it reads (from :class:`epa.artifacts.case.CaseData`),
computes and writes. Each declares ``NAME``, ``SETTINGS`` (the config sections it reads: a change
re-runs it onward), ``RECORDS`` and ``ARRAYS`` (its files), and ``run(data, cfg, write_arrays)``.
Their order is :data:`epa.workflow.chain.STAGES`."""

__all__ = [
    "align",
    "calibrate",
    "consistency",
    "crop",
    "drift",
    "efficiency",
    "load",
    "metrics",
    "report",
    "sync",
]
