import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REAL_DATA = SHARED / "data" / "real"


@pytest.fixture
def rng():
    """Every test's random numbers come from this seeded generator."""
    return np.random.default_rng(12345)


@pytest.fixture
def real_data() -> Path:
    if not REAL_DATA.is_dir():
        if os.environ.get("CI"):
            pytest.fail(f"real data folder missing under CI: {REAL_DATA}")
        pytest.skip(f"real data folder not present: {REAL_DATA}")
    return REAL_DATA
