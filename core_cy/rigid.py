"""The one check of a rigid transform, with one tolerance, used wherever a pose comes in.

Plain Python, not NumPy: every message that carries a pose is checked, and on
sixteen numbers NumPy's per-call overhead is ten times the arithmetic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

__all__ = ["RIGID_TOLERANCE", "rigid_error"]

#: How far a pose's rotation block may be from orthonormal (largest entry of |R^T R - I|), and its
#: last row from 0 0 0 1.
RIGID_TOLERANCE = 1e-5


def rigid_error(matrix: Sequence[Sequence[float]] | Any) -> str | None:
    """Why ``matrix`` is not a rigid 4x4 transform (orthonormal rotation with determinant +1, last
    row 0 0 0 1, finite), or None if it is one. Takes nested sequences or an array.

    Examples
    --------
    >>> rigid_error([[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) is None
    True
    >>> rigid_error([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    'is not a rigid transform: its rotation is a reflection (determinant < 0)'
    >>> rigid_error([[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    'is not a rigid transform: its rotation is not orthonormal (max |R^T R - I| = 3 > 1e-05)'
    """
    rows = matrix.tolist() if hasattr(matrix, "tolist") else matrix
    try:
        if len(rows) != 4 or any(len(row) != 4 for row in rows):
            return "must be a 4x4 matrix"
        (a, b, c, x), (d, e, f, y), (g, h, k, z), last = ([float(v) for v in row] for row in rows)
    except (TypeError, ValueError):
        return "must be a 4x4 matrix of numbers"
    if not all(map(math.isfinite, (a, b, c, x, d, e, f, y, g, h, k, z, *last))):
        return "contains NaN or infinity"
    if (abs(last[0]) > RIGID_TOLERANCE or abs(last[1]) > RIGID_TOLERANCE or abs(last[2]) > RIGID_TOLERANCE
            or abs(last[3] - 1.0) > RIGID_TOLERANCE):
        return "is not a rigid transform: its last row is not 0 0 0 1"
    # Written out: a pose comes with every message, and generators cost more than the arithmetic.
    gram_error = max(abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0),
                     abs(c * c + f * f + k * k - 1.0), abs(a * b + d * e + g * h), abs(a * c + d * f + g * k),
                     abs(b * c + e * f + h * k))
    if gram_error > RIGID_TOLERANCE:
        return (f"is not a rigid transform: its rotation is not orthonormal "
                f"(max |R^T R - I| = {gram_error:.2g} > {RIGID_TOLERANCE:g})")
    if a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g) < 0:
        return "is not a rigid transform: its rotation is a reflection (determinant < 0)"
    return None
