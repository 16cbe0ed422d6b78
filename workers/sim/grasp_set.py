"""Scenes for judging grasps: objects a parallel-jaw gripper can hold, and objects it cannot.

Every scene is one object on the table (z = 0, metres) near (0.6, 0), turned
at random about the vertical. The families:

- ``box``, ``cylinder``, ``ellipsoid``, ``rounded-box``: superquadrics with
  full dimensions of 2-15 cm, half of them lying on their side, with one
  horizontal dimension at most ``fit`` (so that a gripper of that opening
  can close across it);
- ``plate``: a thin box standing on its long edge (0.5-1.5 cm thick);
- ``lying-cylinder``: a cylinder on its side, diameter up to ``fit``;
- compounds (:data:`workers.sim.objects.COMPOUNDS`): stacked cups, a mug, a box
  with a ball on it, an L of two boxes; their truth is a union of parts;
- ``too-big``: boxes, cylinders and balls whose every horizontal dimension is
  at least ``too_big``, which no gripper of a smaller opening can close on.

Sizes follow the scene's seed, so the set is the same on every machine.
"""
from __future__ import annotations

import numpy as np

from .objects import COMPOUNDS, SimObject, SuperquadricObject, compound
from .scans import ScanSpec, make_spec

__all__ = ["GRASPABLE", "TOO_BIG", "grasp_object", "grasp_set"]

GRASPABLE = ("box", "cylinder", "ellipsoid", "rounded-box", "plate", "lying-cylinder", *COMPOUNDS)
TOO_BIG = "too-big"
_CM = 0.01


def _superquadric(family: str, rng: np.random.Generator, fit: float) -> SuperquadricObject:
    lying = bool(rng.integers(2))
    a = rng.uniform(1 * _CM, 7.5 * _CM, 3)
    if family == "cylinder":
        a[1] = a[0]
    # Upright the horizontal semi-axes are a1 and a2; lying (turned about x), a1 and a3.
    horizontal = [0, 2] if lying else [0, 1]
    if 2 * a[horizontal].min() > fit:
        narrow = horizontal[int(rng.integers(2))]
        a[narrow] = rng.uniform(1 * _CM, fit / 2)
        if family == "cylinder" and narrow != 2:  # the round section's two semi-axes stay equal
            a[0] = a[1] = a[narrow]
    return SuperquadricObject.on_table(family, a, _position(rng), rng.uniform(0, 180), lying=lying)


def _position(rng: np.random.Generator) -> tuple[float, float]:
    rho, phi = 0.06 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
    return 0.6 + rho * np.cos(phi), rho * np.sin(phi)


def grasp_object(family: str, seed: int, fit: float = 0.07, too_big: float = 0.102) -> SimObject:
    """One object of ``family`` drawn from ``seed`` (see the module docstring).

    Raises
    ------
    KeyError
        If the family is unknown.

    Examples
    --------
    >>> plate = grasp_object("plate", 3)
    >>> bool(0.005 <= 2 * min(plate.size) <= 0.015)
    True
    """
    rng = np.random.default_rng([seed, GRASPABLE.index(family) if family in GRASPABLE else 99])
    if family in ("box", "cylinder", "ellipsoid", "rounded-box"):
        return _superquadric(family, rng, fit)
    if family == "plate":
        a = (rng.uniform(3 * _CM, 7.5 * _CM), rng.uniform(0.25 * _CM, 0.75 * _CM), rng.uniform(2.5 * _CM, 6 * _CM))
        return SuperquadricObject.on_table((0.1, 0.1), a, _position(rng), rng.uniform(0, 180))
    if family == "lying-cylinder":
        radius = rng.uniform(1 * _CM, fit / 2)
        a = (radius, radius, rng.uniform(2 * _CM, 7.5 * _CM))
        return SuperquadricObject.on_table("cylinder", a, _position(rng), rng.uniform(0, 180), lying=True)
    if family in COMPOUNDS:
        return compound(family, _position(rng), rng.uniform(0, 180), seed=seed)
    if family == TOO_BIG:
        kind = ("box", "cylinder", "ellipsoid")[int(rng.integers(3))]
        a = rng.uniform(too_big / 2, 7.5 * _CM, 3)
        if kind == "cylinder":
            a[1] = a[0]
        if kind == "ellipsoid":
            a[:] = a[0]
        else:
            a[2] = rng.uniform(1 * _CM, 7.5 * _CM)  # any height: closing is horizontal
        return SuperquadricObject.on_table(kind, a, _position(rng), rng.uniform(0, 180))
    raise KeyError(f"unknown grasp family {family!r}")


def grasp_set(seed: int = 0, per_family: int = 10, n_views: int = 3, families=(*GRASPABLE, TOO_BIG)) -> list[ScanSpec]:
    """``per_family`` scans of each family, named ``{family}-{index:03d}``, with ``n_views`` views."""
    specs = []
    for family in families:
        for index in range(per_family):
            scene_seed = 1000 * seed + index
            obj = grasp_object(family, scene_seed)
            specs.append(make_spec(f"{family}-{index:03d}", obj, seed=scene_seed, n_views=n_views))
    return specs
