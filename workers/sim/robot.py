"""The simulated robot: a ``RobotBackend`` whose moves take time, and whose gripper, when it
closes, judges the grasp against the simulated scene's true object (``workers.sim.judge``)."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np

from wire.backends import SimRobotConfig
from workers.robot.backend import Grip, ProgressCallback, RobotBackend

from .judge import JudgeGripper, Part, judge, parts_from_truth

__all__ = ["SimRobot"]


def _rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return math.acos(float(np.clip(cosine, -1.0, 1.0)))


class SimRobot(RobotBackend):
    """A robot whose moves take distance / speed (or angle / rotation speed, if longer),
    or ``move_time_s`` each if that is configured."""

    def __init__(self, config: SimRobotConfig, *, truth: list[dict] = (), gripper: dict | None = None,
                 T_flange_grasp=None, support_plane=None, friction: float = 0.5) -> None:
        """``truth``: the scene's objects as ``truth.json`` has them; ``gripper`` the DESIGN.md §3
        dimensions, mounted at ``T_flange_grasp``: with both, closing judges the grasp."""
        self._config = config
        self._pose = np.asarray(config.home, dtype=np.float64)
        self._closed = False
        self._parts: list[Part] = [part for obj in truth for part in parts_from_truth(obj)]
        self._gripper = JudgeGripper.from_dict(gripper) if gripper is not None else None
        self._flange_grasp = np.eye(4) if T_flange_grasp is None else np.asarray(T_flange_grasp, dtype=np.float64)
        self._plane = support_plane
        self._friction = friction

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
        if not close or self._gripper is None or not self._parts:
            return Grip(closed=close)
        verdict = judge(self._pose @ self._flange_grasp, self._parts, self._gripper, self._plane, mu=self._friction)
        width = verdict.width if np.isfinite(verdict.width) else 0.0
        return Grip(closed=True, holding=verdict.holds, width=width,
                    reason="held" if verdict.holds else verdict.reason)
