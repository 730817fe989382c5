from pathlib import Path
import sys

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from hmlvs.models.params import TABLE2_LOWER, TABLE2_UPPER  # noqa: E402


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def random_params(rng: np.random.Generator) -> np.ndarray:
    """Parameters drawn inside the Table 2 bounds, with theta kept away from 0 so rays hit."""
    q = rng.uniform(TABLE2_LOWER, TABLE2_UPPER)
    q[7] = rng.uniform(0.3, 0.7)
    q[5] = rng.uniform(0.0, 0.02)
    return q
