import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("EPA_SHARED_DATA", ROOT.parent / "shared" / "data"))


def run_stages(cases: list[dict], out: Path, cfg: dict, stages=None) -> dict:
    """Run stages (default: all) over a grid of cases in this process, as the stage jobs do; returns
    each stage's manifest path."""
    from epa.workflow import chain
    from epa.workflow import jobs as grid

    manifests = {}
    for stage in stages or chain.NAMES:
        manifests[stage] = out / "batches/all" / f"{stage}.json"
        grid.run_job(
            stage,
            cases,
            out,
            cfg,
            manifests[stage],
            manifests.get(chain.previous(stage)),
            out / f"logs/{stage}.log",
        )
    return manifests


@pytest.fixture(scope="session")
def data():
    if not DATA.is_dir():
        pytest.skip(f"real data not found at {DATA} (CI keeps ../shared/data beside the checkout)")
    return DATA


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
