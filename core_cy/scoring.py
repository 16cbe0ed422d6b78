"""Scores that compare two superquadrics by the space they fill, not by their parameters.

A superquadric has several equivalent parameterisations (axis swaps, angle
wraps, e1/e2 exchanges for some shapes), so results are compared by volume
overlap and by the distance between centres.
"""

from __future__ import annotations

import numpy as np

from .errors import CoreError
from .superquadric import Superquadric, inside_outside

__all__ = ["centre_error", "volumetric_iou"]


def _bounding_sphere(sq: Superquadric) -> tuple[np.ndarray, float]:
    # For any exponents the superquadric lies in the box |x_k| <= a_k, hence
    # in the ball of radius |a| around its centre.
    return sq.T_world_object[:3, 3], float(np.linalg.norm(sq.size))


def volumetric_iou(a: Superquadric, b: Superquadric, n: int = 200_000, seed: int = 0) -> float:
    """Monte Carlo estimate of the volume of ``a & b`` over the volume of ``a | b``.

    Samples are drawn uniformly in the union of the two bounding spheres (each
    sphere in proportion to its volume, a sample lying in both spheres counting
    half), and classified with the inside-outside function. The standard error
    is about ``sqrt(IoU (1 - IoU) / n')`` with ``n'`` the samples in the union
    of the two superquadrics.

    Parameters
    ----------
    a, b : Superquadric
        In the same world frame and units.
    n : int
        Number of samples, >= 1.
    seed : int
        Seed of the random generator: the same call gives the same estimate.

    Returns
    -------
    float
        In [0, 1].

    Raises
    ------
    CoreError
        If ``n`` is not a positive integer.

    Examples
    --------
    >>> sq = Superquadric([1.0, 2.0, 3.0], [0.5, 1.0], np.eye(4))
    >>> volumetric_iou(sq, sq, n=1000)
    1.0
    """
    if int(n) != n or n < 1:
        raise CoreError(f"n must be a positive integer, got {n!r}")
    rng = np.random.default_rng(seed)
    (centre_a, radius_a), (centre_b, radius_b) = _bounding_sphere(a), _bounding_sphere(b)
    share_a = radius_a**3 / (radius_a**3 + radius_b**3)
    from_a = rng.random(int(n)) < share_a
    direction = rng.normal(size=(int(n), 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = np.where(from_a, radius_a, radius_b) * rng.random(int(n)) ** (1 / 3)
    samples = np.where(from_a[:, None], centre_a, centre_b) + direction * radius[:, None]
    in_both_spheres = ((np.linalg.norm(samples - centre_a, axis=1) <= radius_a)
                       & (np.linalg.norm(samples - centre_b, axis=1) <= radius_b))
    weight = np.where(in_both_spheres, 0.5, 1.0)
    inside_a, inside_b = inside_outside(samples, a) <= 1, inside_outside(samples, b) <= 1
    union = float(weight[inside_a | inside_b].sum())
    return float(weight[inside_a & inside_b].sum()) / union if union > 0 else 0.0


def centre_error(a: Superquadric, b: Superquadric) -> float:
    """Distance between the two superquadrics' centres, in their units.

    Examples
    --------
    >>> T = np.eye(4)
    >>> T[:3, 3] = [3.0, 4.0, 0.0]
    >>> centre_error(Superquadric([1, 1, 1], [1, 1], np.eye(4)), Superquadric([1, 1, 1], [1, 1], T))
    5.0
    """
    return float(np.linalg.norm(a.T_world_object[:3, 3] - b.T_world_object[:3, 3]))
