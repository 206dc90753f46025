"""Shared by the synthetic-driver tests (pytest puts tests/ on sys.path)."""

from __future__ import annotations

import numpy as np


def random_info(
    rng: np.random.Generator, n: int, k: int, *, bias: bool = False
) -> dict[str, np.ndarray]:
    """Plausible true states of n cars at step k (they need not come from one trajectory);
    ``bias``: with the true camera bias (0 m), which a driver reads where given."""
    info = {
        "time": np.full(n, 0.01 * k),
        "station": 15.0 * 0.01 * k + rng.uniform(0.0, 5.0, n),
        "lateral_offset": rng.normal(0.0, 0.4, n),
        "heading": rng.normal(0.0, 0.01, n),
        "speed": rng.uniform(12.0, 18.0, n),
        "steering": rng.normal(0.0, 0.005, n),
    }
    if bias:
        info["bias"] = np.zeros(n)
    return info
