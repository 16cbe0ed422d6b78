"""The simulated robot and camera as ``wire.backends.BACKENDS`` names them: the workers import
this module only when the configuration names the simulator."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np

from robocell.wire import keys
from robocell.wire.config import CellConfig
from robocell.wire.errors import TransportError
from robocell.wire.messages import RobotState, parse
from robocell.wire.transport import BaseTransport
from robocell.workers.camera.backend import Camera, Snapshot

from .camera import SceneCamera, SimCamera
from .robot import SceneGripper, SimRobot
from .scene import scene_from_config
from .truth_log import TruthLog, follow

__all__ = ["make_robot", "make_camera"]

_ROBOT_STATE_TIMEOUT_S = 2.0


def make_robot(config: CellConfig) -> SimRobot:
    """The simulated robot, whose gripper judges its grasps against the ``[sim]`` scene."""
    return SimRobot(config.robot, gripper=SceneGripper.from_config(config))


def make_camera(config: CellConfig, transport: BaseTransport) -> Camera:
    """The simulated camera: the ``[sim]`` scene rendered from where the robot stands; it logs the
    scene's truth into each job's recording (``workers.sim.truth_log``)."""
    camera = config.camera

    async def pose() -> np.ndarray | None:
        try:
            reply = await transport.query(keys.robot_state(config.cell_id), timeout=_ROBOT_STATE_TIMEOUT_S)
        except TransportError:
            return None
        return np.asarray(parse(RobotState, reply.payload).T_base_flange) @ config.hand_eye

    scene = scene_from_config(config.sim)
    rendered = SceneCamera(scene, K=camera.K, image_size=camera.resolution, dist=camera.dist, seed=config.sim.seed,
                           jpeg_quality=camera.jpeg_quality)
    truth = TruthLog(config.run_dir, scene)
    return _TruthfulCamera(SimCamera(rendered, pose), lambda: follow(truth, transport, config.cell_id))


class _TruthfulCamera(Camera):
    """The simulated camera, with its truth log following the jobs while it is open."""

    def __init__(self, camera: SimCamera, truth_log: Callable[[], Coroutine[Any, Any, None]]) -> None:
        self._camera, self._truth_log = camera, truth_log
        self._following: asyncio.Task[None] | None = None

    @property
    def source(self) -> str:
        return self._camera.source

    async def open(self) -> None:
        await self._camera.open()
        self._following = asyncio.create_task(self._truth_log())

    async def close(self) -> None:
        if self._following is not None:
            self._following.cancel()
            await asyncio.gather(self._following, return_exceptions=True)
            self._following = None
        await self._camera.close()

    async def snapshot(self) -> Snapshot:
        return await self._camera.snapshot()
