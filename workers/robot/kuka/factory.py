"""The KUKA backend as ``wire.backends.BACKENDS`` names it."""

from __future__ import annotations

from robocell.wire.backends import KukaRobotConfig
from robocell.wire.config import CellConfig

from .backend import KukaBackend

__all__ = ["make_robot"]


def make_robot(config: CellConfig) -> KukaBackend:
    """The KUKA arm of the ``[robot]`` section, not yet opened."""
    robot = config.robot
    assert isinstance(robot, KukaRobotConfig), "named by [robot] backend = kuka"
    return KukaBackend.from_config(robot.kuka, robot.workspace)
