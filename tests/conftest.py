import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("EPA_SHARED_DATA", ROOT.parent / "shared" / "data"))


def smooth_path(n: int = 600):
    """A 30 s helix-like path at 20 Hz that rotates about every axis (for metric tests)."""
    from epa.core import geometry
    from epa.core.trajectory import Trajectory

    t = np.arange(n) * 0.05
    p = np.column_stack([4 * np.cos(0.3 * t), 3 * np.sin(0.5 * t), 0.2 * t])
    q = geometry.rot_to_quat(
        geometry.so3_exp(np.column_stack([0.1 * np.sin(t), 0.05 * t, 0.3 * t]))
    )
    return Trajectory(t, p, q)


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
