import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("EPA_SHARED_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def data():
    if not DATA.is_dir():
        pytest.skip(f"real data not found at {DATA} (CI keeps ../shared/data beside the checkout)")
    return DATA


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
