"""The robot worker: moves the flange on request and tells where it is.

Backends implement :class:`RobotBackend`; this issue brings the simulated
robot, a later one the KUKA bridges. Every commanded pose is checked against
the configured workspace before the backend sees it.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from typing import Protocol

import numpy as np

from wire import keys
from wire.config import CellConfig, RobotConfig
from wire.errors import CellError
from wire.messages import MoveReply, MoveRequest, RobotState, parse
from core_cy.plan import workspace_violation
from wire.transport import Request, RequestError, Response, Transport

from wire.process import open_transport, run_until_stopped

__all__ = ["RobotBackend", "SimRobot", "serve_robot", "main"]

log = logging.getLogger(__name__)


class RobotBackend(Protocol):
    """What the worker needs of a robot. Errors are ``cell.errors.CellError``s that say why."""

    async def open(self) -> None:
        """Connect, and learn where the flange is."""

    async def close(self) -> None:
        """Let go of the robot."""

    async def move(self, target: np.ndarray, on_progress) -> np.ndarray:
        """Move the flange to ``target`` (4x4, base frame); return the pose reached."""

    def pose(self) -> np.ndarray:
        """The flange's pose as last known (4x4, base frame)."""


def _rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return math.acos(float(np.clip(cosine, -1.0, 1.0)))


class SimRobot:
    """A robot whose moves take distance / speed (or angle / rotation speed, if longer),
    or ``move_time_s`` each if that is configured."""

    def __init__(self, config: RobotConfig) -> None:
        self._config = config
        self._pose = np.asarray(config.home, dtype=np.float64)

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

    async def move(self, target: np.ndarray, on_progress) -> np.ndarray:
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


def make_backend(config: RobotConfig) -> RobotBackend:
    if config.backend == "kuka":
        from .kuka.backend import KukaBackend

        return KukaBackend.from_config(config.kuka, config.workspace)
    return SimRobot(config)


def serve_robot(transport: Transport, config: CellConfig, backend: RobotBackend) -> None:
    """Answer move and state queries for the cell; publish the pose while moving."""
    cell = config.cell_id
    motion = asyncio.Lock()  # one arm: moves run one after the other
    moving = False

    def publish(pose: np.ndarray, is_moving: bool) -> None:
        state = RobotState(T_base_flange=pose.tolist(), moving=is_moving, time=time.time())
        transport.put(keys.robot_state(cell), state.model_dump_json())

    async def on_move(request: Request) -> Response:
        nonlocal moving
        try:
            move = parse(MoveRequest, request.payload)
        except ValueError as exc:
            raise RequestError(str(exc)) from None
        target = np.asarray(move.T_base_flange, dtype=np.float64)
        violation = workspace_violation(target, config.robot.workspace)
        if violation:
            raise RequestError(f"move refused before moving: {violation}")
        async with motion:
            began = time.monotonic()
            moving = True
            try:
                reached = await backend.move(target, publish)
            except CellError as exc:  # the robot refused or failed: the caller hears why
                raise RequestError(str(exc)) from None
            finally:
                moving = False
            publish(reached, False)
            log.info("moved in %.2f s%s", time.monotonic() - began, f" for job {move.job_id}" if move.job_id else "")
            reply = MoveReply(T_base_flange=reached.tolist(), duration_s=time.monotonic() - began)
        return Response(reply.model_dump_json())

    async def on_state(request: Request) -> Response:
        state = RobotState(T_base_flange=backend.pose().tolist(), moving=moving, time=time.time())
        return Response(state.model_dump_json())

    transport.serve(keys.robot_move(cell), on_move)
    transport.serve(keys.robot_state(cell), on_state)


def main(config: CellConfig) -> int:
    async def run(stop: asyncio.Event) -> None:
        backend = make_backend(config.robot)
        await backend.open()
        try:
            transport = await open_transport(config)
            try:
                serve_robot(transport, config, backend)
                transport.declare_token(keys.alive(config.cell_id, "robot"))
                log.info("robot worker (%s) of cell %s ready", config.robot.backend, config.cell_id)
                await stop.wait()
            finally:
                await transport.close()
        finally:
            await backend.close()  # the controller's link too, when the router cannot be reached

    return run_until_stopped(run, "robot worker")
