"""The simulated robot: a ``RobotBackend`` whose moves take time, and whose gripper, when it
closes, judges the grasp against the simulated scene's true object (``workers.sim.judge``).

:class:`SceneGripper` is that judgement on its own: the simulated KUKA controller
(``workers.sim.kuka``) uses it to say what its gripper's input reports.
"""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np

from robocell.wire.backends import SimRobotConfig
from robocell.wire.config import CellConfig
from robocell.workers.robot.backend import Grip, ProgressCallback, RobotBackend

from .judge import JudgeGripper, Part, judge, parts_from_truth

__all__ = ["SimRobot", "SceneGripper"]


def _rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return math.acos(float(np.clip(cosine, -1.0, 1.0)))


class SceneGripper:
    """A parallel-jaw gripper in a simulated scene: closing with the flange at a pose, does it hold
    the true object? Judged by ``workers.sim.judge``, written apart from the planner.

    ``truth``: the scene's objects as ``truth.json`` has them; ``gripper`` the DESIGN.md §3
    dimensions, mounted at ``T_flange_grasp`` (flange-to-grasp; the identity if None).
    """

    def __init__(self, truth: list[dict], gripper: dict, *, T_flange_grasp=None, support_plane=None,
                 friction: float = 0.5) -> None:
        self._parts: list[Part] = [part for obj in truth for part in parts_from_truth(obj)]
        self._gripper = JudgeGripper.from_dict(gripper)
        self._flange_grasp = np.eye(4) if T_flange_grasp is None else np.asarray(T_flange_grasp, dtype=np.float64)
        self._plane = support_plane
        self._friction = friction

    @classmethod
    def from_config(cls, config: CellConfig) -> SceneGripper:
        """The ``[gripper]`` of ``config`` in its ``[sim]`` scene, on its support plane."""
        from .scene import scene_from_config

        return cls([obj.truth() for obj in scene_from_config(config.sim)], config.gripper.dimensions(),
                   T_flange_grasp=config.gripper.T_flange_grasp, support_plane=config.support_plane,
                   friction=config.gripper.friction)

    def close_at(self, T_base_flange: np.ndarray) -> Grip:
        """The gripper closed with the flange at ``T_base_flange`` (4x4; the scene's frame is the base's)."""
        if not self._parts:
            return Grip(closed=True)
        verdict = judge(np.asarray(T_base_flange, dtype=np.float64) @ self._flange_grasp, self._parts,
                        self._gripper, self._plane, mu=self._friction)
        width = verdict.width if np.isfinite(verdict.width) else 0.0
        return Grip(closed=True, holding=verdict.holds, width=width, reason="held" if verdict.holds else verdict.reason)

    def holds(self, T_base_flange: np.ndarray) -> bool:
        """Whether closing with the flange at ``T_base_flange`` holds the object."""
        return self.close_at(T_base_flange).holding is True


class SimRobot(RobotBackend):
    """A robot whose moves take distance / speed (or angle / rotation speed, if longer),
    or ``move_time_s`` each if that is configured."""

    def __init__(self, config: SimRobotConfig, *, gripper: SceneGripper | None = None) -> None:
        """With a ``gripper``, closing judges the grasp; without one it only closes."""
        self._config = config
        self._pose = np.asarray(config.home, dtype=np.float64)
        self._closed = False
        self._gripper = gripper

    async def open(self) -> None:
        pass

    async def close(self) -> None:
        pass

    def pose(self) -> np.ndarray:
        return self._pose.copy()

    def duration(self, target: np.ndarray) -> float:
        if self._config.move_time_s is not None:
            return self._config.move_time_s
        distance = float(np.linalg.norm(target[:3, 3] - self._pose[:3, 3]))
        angle = math.degrees(_rotation_angle(self._pose, target))
        linear = distance / self._config.speed if self._config.speed else 0.0
        angular = angle / self._config.rotation_speed_deg if self._config.rotation_speed_deg else 0.0
        return max(linear, angular)

    async def move(self, target: np.ndarray, on_progress: ProgressCallback) -> np.ndarray:
        duration = self.duration(target)
        start, began = self._pose, time.monotonic()
        period = 1.0 / self._config.publish_rate_hz
        while (elapsed := time.monotonic() - began) < duration:
            # Position moves in a straight line; the pose shown between is the nearer end's
            # rotation, which is enough for a viewer and for a camera that only shoots at rest.
            fraction = elapsed / duration
            self._pose = start.copy()
            self._pose[:3, 3] = (1 - fraction) * start[:3, 3] + fraction * target[:3, 3]
            if fraction >= 0.5:
                self._pose[:3, :3] = target[:3, :3]
            on_progress(self._pose, True)
            await asyncio.sleep(min(period, duration - elapsed))
        self._pose = target.copy()
        return self.pose()

    async def grip(self, close: bool) -> Grip:
        """Open at once; or close, and say whether the gripper holds the true object where it is."""
        self._closed = close
        if not close or self._gripper is None:
            return Grip(closed=close)
        return self._gripper.close_at(self._pose)
