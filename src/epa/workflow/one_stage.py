"""``epa stage NAME CASE_DIR``: one stage of one grid case, from the previous stage's artifacts, with
the grid's settings, in this process (a stage in a debugger: ``python -m pdb -m epa.cli.main stage
...``). It is what a workflow job does for that case, without Snakemake."""

from __future__ import annotations

import logging
import time
from pathlib import Path

from epa.artifacts.case import Case, CaseFolder
from epa.core.errors import EpaError
from epa.workflow import chain, discovery, settings

log = logging.getLogger(__name__)


def grid_case(case_dir, cfg: dict, source: str) -> Case:
    """The case a case folder ``<results>/cases/<algorithm>/<dataset>/<run>`` belongs to, with its
    files and each side's source settings as the grid's load job has them."""
    key = "/".join(Path(case_dir).resolve().parts[-3:])
    _, cases = discovery.discover_config(cfg, source=source)
    found = next((c for c in cases if c.key == key), None)
    if found is None:
        raise EpaError(f"{case_dir}: no case {key!r} in the grid of {source}")
    return Case(
        found.algorithm,
        found.dataset,
        found.run,
        found.truth,
        found.estimate,
        *discovery.sources_of(cfg, found),
    )


def run(stage: str, case_dir, configfile) -> tuple[float, list[Path]]:
    """Run ``stage`` for the case in ``case_dir``; returns its time and the files it wrote."""
    if stage not in chain.BY_NAME:
        raise EpaError(f"no stage {stage!r}; the stages are {', '.join(chain.NAMES)}")
    source = str(configfile)
    cfg = settings.from_configfile(configfile)
    folder = CaseFolder(case_dir, grid_case(case_dir, cfg, source))
    before = chain.previous(stage)
    if before and not folder.has(before, chain.BY_NAME[before].records[0]):
        raise EpaError(f"{case_dir}: stage {before} has not run for this case (run it first)")
    t0 = time.perf_counter()
    chain.run_stage(stage, chain.CaseData(folder), cfg)
    elapsed = time.perf_counter() - t0
    st = chain.BY_NAME[stage]
    written = [folder.path(stage, n) for n in st.artifacts if folder.has(stage, n)]
    return elapsed, written
