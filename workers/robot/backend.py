"""What the robot worker needs of a robot: :class:`RobotBackend`.

The KUKA bridges (``workers.robot.kuka``) and the simulated robot
(``workers.sim.robot``) implement it, so the worker cannot tell which one it
drives. A new robot is a new backend beside them, with its configuration model
in ``wire.backends``, and a line in its ``BACKENDS``.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from robocell.core_cy.plan import Workspace, workspace_violation
from robocell.wire.errors import MoveRefused

__all__ = ["RobotBackend", "ProgressCallback", "Grip", "refuse_outside"]

#: Called while a move runs: the flange's pose now (4x4, base frame), and whether it still moves.
ProgressCallback = Callable[[np.ndarray, bool], None]


@dataclass(frozen=True)
class Grip:
    """The parallel-jaw gripper after a command: closed or open, and what the backend can tell."""

    closed: bool
    #: Whether the fingers stopped on something; None where the gripper cannot tell.
    holding: bool | None = None
    #: The opening between the pads now, metres; None where the gripper cannot tell.
    width: float | None = None
    #: Why it holds or not, where the backend knows (the simulator judges against its truth).
    reason: str = ""


def refuse_outside(target: np.ndarray, workspace: Workspace, *, prefix: str = "move refused") -> None:
    """Raise :class:`~wire.errors.MoveRefused` if ``target`` (flange-to-base) leaves the
    workspace: ``limit`` is ``"workspace"`` outside the box, ``"orientation"`` for the tilt."""
    violation = workspace_violation(target, workspace)
    if violation:
        inside_box = all(lo <= x <= hi for lo, x, hi in zip(workspace.min, target[:3, 3], workspace.max))
        raise MoveRefused(f"{prefix}: {violation}", limit="orientation" if inside_box else "workspace")


class RobotBackend(abc.ABC):
    """A robot arm. Errors are ``wire.errors.CellError``s that say why; use ``async with``."""

    @abc.abstractmethod
    async def open(self) -> None:
        """Connect, and learn where the flange is."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Let go of the robot."""

    @abc.abstractmethod
    async def move(self, target: np.ndarray, on_progress: ProgressCallback) -> np.ndarray:
        """Move the flange to ``target`` (4x4, base frame); return the pose reached."""

    @abc.abstractmethod
    def pose(self) -> np.ndarray:
        """The flange's pose as last known (4x4, base frame)."""

    @abc.abstractmethod
    async def grip(self, close: bool) -> Grip:
        """Close (``close``) or open the gripper, and return once it has; a gripper that does not
        get there in time raises a ``CellError`` that says so."""

    async def __aenter__(self) -> RobotBackend:
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()
