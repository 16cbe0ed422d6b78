# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
# distutils: language = c++
"""Kernel of the ``auto`` segmentation's noise level: the median of an evidence map's finite values and the
median of their distances from it, each found by selection in one copy of the values, not by sorting."""

from cython cimport floating
from libc.math cimport isfinite, fabs
from libcpp.algorithm cimport nth_element

import numpy as np


cdef floating _median_in_place(floating* values, Py_ssize_t count) noexcept nogil:
    """The median of ``values[:count]`` (count >= 1), reordering them; of an even count, the mean of the two
    middle values, summed and halved in the values' own precision as NumPy's median does."""
    cdef Py_ssize_t middle = count // 2, k
    cdef floating upper, lower
    nth_element(values, values + middle, values + count)
    upper = values[middle]
    if count % 2:
        return upper
    # After the selection every value below the middle one is no greater: the largest of them is the other.
    lower = values[0]
    for k in range(1, middle):
        if values[k] > lower:
            lower = values[k]
    return (lower + upper) / 2


def median_and_spread(floating[::1] evidence not None):
    """(median, median absolute deviation) of the finite values of ``evidence`` (1-D, contiguous), or None
    when none is finite. Equal to NumPy's ``np.median`` of the finite values and of their absolute
    differences from that median, computed in the values' precision."""
    cdef Py_ssize_t n = evidence.shape[0], count = 0, k
    buffer = np.empty(n, dtype=np.float32 if floating is float else np.float64)
    cdef floating[::1] values = buffer
    cdef floating median, spread
    with nogil:
        for k in range(n):
            if isfinite(evidence[k]):
                values[count] = evidence[k]
                count += 1
        if count == 0:
            median = 0
        else:
            median = _median_in_place(&values[0], count)
            for k in range(count):
                values[k] = fabs(values[k] - median)
            spread = _median_in_place(&values[0], count)
    if count == 0:
        return None
    return float(median), float(spread)
