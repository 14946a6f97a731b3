import os
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# the independent closed-form references live in tests/reference
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def rng():
    """One seeded generator per test: the same seed gives the same numbers."""
    return np.random.default_rng(20070461)
