"""The ``auto`` segmentation's kernel against plain NumPy on random inputs."""

from __future__ import annotations

import numpy as np
import pytest

from robocell.core_cy._auto_segment_cy import median_and_spread


def _reference(values: np.ndarray) -> tuple[float, float] | None:
    finite = values[np.isfinite(values)]
    if not len(finite):
        return None
    median = float(np.median(finite))
    return median, float(np.median(np.abs(finite - median)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_and_spread_is_numpys_median_of_the_finite_values(dtype):
    rng = np.random.default_rng(0)
    for trial in range(2000):
        values = rng.normal(size=int(rng.integers(1, 60))).astype(dtype)
        # Ties (the many exact zeros of an evidence map), and values that carry no evidence.
        values[rng.random(len(values)) < 0.3 * (trial % 2)] = 0.0
        values[rng.random(len(values)) < 0.1 * (trial % 3)] = np.nan
        values[rng.random(len(values)) < 0.1 * (trial % 5 == 0)] = np.inf
        assert median_and_spread(values) == _reference(values)


def test_median_and_spread_of_nothing_finite_is_none():
    assert median_and_spread(np.array([np.nan, np.inf, -np.inf], np.float32)) is None
    assert median_and_spread(np.zeros(0)) is None


def test_median_and_spread_by_hand():
    # Sorted: 0, 1, 2, 4 -> median 1.5; distances 1.5, 0.5, 0.5, 2.5 -> median 1.0.
    assert median_and_spread(np.array([4.0, np.nan, 0.0, 2.0, 1.0])) == (1.5, 1.0)
