"""The simulated robot: a ``RobotBackend`` whose moves take time, and nothing else."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np

from wire.backends import SimRobotConfig
from workers.robot.backend import Grip, ProgressCallback, RobotBackend

__all__ = ["SimRobot"]


def _rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return math.acos(float(np.clip(cosine, -1.0, 1.0)))


class SimRobot(RobotBackend):
    """A robot whose moves take distance / speed (or angle / rotation speed, if longer),
    or ``move_time_s`` each if that is configured."""

    def __init__(self, config: SimRobotConfig) -> None:
        self._config = config
        self._pose = np.asarray(config.home, dtype=np.float64)
        self._closed = False

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
        """The simulated gripper closes or opens at once; it cannot tell whether it holds."""
        self._closed = close
        return Grip(closed=close)
