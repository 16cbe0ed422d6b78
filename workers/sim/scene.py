"""The simulated scene of a cell's configuration: one known object on the table.

With ``[sim] look = "printed"`` (the default) the object wears a printed look (a sugar box,
a soup can, a random print) and stands on an oak table under one lamp that casts its shadow
(:func:`surroundings`); with ``"red"`` it is the classic red object on the pale table, unlit,
which costs a sixth of the rendering.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from robocell.core_cy.superquadric import Superquadric

from robocell.wire.config import SimConfig
from robocell.wire.errors import ConfigError
from .objects import CupStack, LumpyFigure, SimObject, SuperquadricObject
from .render import Light, TableScene
from .textures import PrintedObject, product_look

__all__ = ["scene_from_config", "surroundings", "truth_from_config", "target_from_config"]

#: The look each shape of ``[sim]`` wears when printed.
_LOOK_OF_SHAPE = {"box": "sugar-box", "cylinder": "soup-can"}


def scene_from_config(sim: SimConfig) -> list[SimObject]:
    """The simulated scene of the ``[sim]`` section: one object on the table.

    ``size`` means half-sizes for superquadrics, (bottom radius, rim radius,
    cup height) for a cup stack and the ellipsoid's radii for a lumpy figure,
    as in ``robocell sim``; ``yaw_deg`` turns superquadrics only.

    Raises
    ------
    ConfigError
        If the size does not make a valid object of that shape.
    """
    try:
        obj: SimObject
        if sim.grasp_scene is not None:
            from .grasp_set import grasp_object

            obj = grasp_object(sim.grasp_scene, sim.seed)
        elif sim.shape == "cup-stack":
            obj = CupStack(sim.position, *sim.size)
        elif sim.shape == "lumpy":
            obj = LumpyFigure(sim.position, sim.size, seed=sim.seed)
        else:
            obj = SuperquadricObject.on_table(sim.shape, sim.size, sim.position, sim.yaw_deg)
        if sim.look == "red":
            return [obj]
        look_name = "printed" if sim.grasp_scene is not None else _LOOK_OF_SHAPE.get(sim.shape, "printed")
        height = float(np.ptp(obj.mesh()[0][:, 2])) / 2
        return [PrintedObject(obj, product_look(look_name, np.random.default_rng([sim.seed, 41]), height))]
    except KeyError:
        raise ConfigError(f"sim: no grasp scene {sim.grasp_scene!r}") from None
    except ValueError as exc:
        raise ConfigError(f"sim: size {sim.size} does not make a {sim.shape}: {exc}") from exc


def surroundings(objects: Sequence[SimObject], seed: int) -> tuple[TableScene, Light | None]:
    """The table and the lamp round ``objects``: for printed objects, an oak table and a lamp whose
    direction follows ``seed``; for the classic red ones, their pale table (from ``seed``), unlit."""
    if not any(isinstance(obj, PrintedObject) for obj in objects):
        return TableScene.from_seed(seed), None
    rng = np.random.default_rng([seed, 43])
    elevation = float(rng.uniform(45, 65))
    ambient = 0.35
    light = Light.from_angles(float(rng.uniform(0, 360)), elevation, (0.95 - ambient) / np.sin(np.radians(elevation)),
                              ambient)
    return TableScene.of_kind("oak", seed), light


def truth_from_config(sim: SimConfig) -> dict[str, Any]:
    """The ground truth (``truth()``) of the ``[sim]`` section's object."""
    return scene_from_config(sim)[0].truth()


def target_from_config(sim: SimConfig) -> list[float]:
    """The centre of the ``[sim]`` section's object (base frame, metres): where a scan of it looks
    (for an object of several parts, the middle of its bounding box)."""
    truth = truth_from_config(sim)
    if "parts" not in truth:
        return Superquadric.from_dict(truth).T_world_object[:3, 3].tolist()
    vertices = scene_from_config(sim)[0].mesh()[0]
    return ((vertices.min(axis=0) + vertices.max(axis=0)) / 2).tolist()
