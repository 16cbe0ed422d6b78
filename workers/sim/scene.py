"""The simulated scene of a cell's configuration: one known object on the table."""

from __future__ import annotations

from typing import Any

from core_cy.superquadric import Superquadric

from wire.config import SimConfig
from wire.errors import ConfigError
from .objects import CupStack, LumpyFigure, SimObject, SuperquadricObject

__all__ = ["scene_from_config", "truth_from_config", "target_from_config"]


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
        if sim.grasp_scene is not None:
            from .grasp_set import grasp_object

            return [grasp_object(sim.grasp_scene, sim.seed)]
        if sim.shape == "cup-stack":
            return [CupStack(sim.position, *sim.size)]
        if sim.shape == "lumpy":
            return [LumpyFigure(sim.position, sim.size, seed=sim.seed)]
        return [SuperquadricObject.on_table(sim.shape, sim.size, sim.position, sim.yaw_deg)]
    except KeyError:
        raise ConfigError(f"sim: no grasp scene {sim.grasp_scene!r}") from None
    except ValueError as exc:
        raise ConfigError(f"sim: size {sim.size} does not make a {sim.shape}: {exc}") from exc


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
