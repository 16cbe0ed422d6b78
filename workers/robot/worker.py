"""The robot worker: moves the flange on request and tells where it is.

It drives a :class:`~workers.robot.backend.RobotBackend` (the simulated robot,
or a KUKA arm) and checks every commanded pose against the configured
workspace before the backend sees it.
"""

from __future__ import annotations

import asyncio
import logging
import time

import numpy as np

from robocell.wire import keys
from robocell.wire.backends import load_backend
from robocell.wire.config import CellConfig
from robocell.wire.messages import GripReply, GripRequest, MoveReply, MoveRequest, RobotState, parse
from robocell.wire.process import open_transport, run_until_stopped
from robocell.wire.transport import Request, RequestError, Response, Transport

from .backend import RobotBackend, refuse_outside

__all__ = ["make_backend", "serve_robot", "main"]

log = logging.getLogger(__name__)


def make_backend(config: CellConfig) -> RobotBackend:
    """The backend the ``[robot]`` section names (``wire.backends.BACKENDS``), not yet opened."""
    return load_backend("robot", config.robot.backend)(config)


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
        refuse_outside(target, config.robot.workspace, prefix="move refused before moving")
        async with motion:
            began = time.monotonic()
            moving = True
            try:  # a CellError (the robot refused or failed) goes back to the caller with its kind
                reached = await backend.move(target, publish)
            finally:
                moving = False
            publish(reached, False)
            log.info("moved in %.2f s%s", time.monotonic() - began, f" for job {move.job_id}" if move.job_id else "")
            reply = MoveReply(T_base_flange=reached.tolist(), duration_s=time.monotonic() - began)
        return Response(reply.model_dump_json())

    async def on_grip(request: Request) -> Response:
        try:
            command = parse(GripRequest, request.payload)
        except ValueError as exc:
            raise RequestError(str(exc)) from None
        async with motion:  # the gripper is on the arm: not while it moves
            began = time.monotonic()
            grip = await backend.grip(command.close)  # a CellError goes back with its kind
            reply = GripReply(closed=grip.closed, holding=grip.holding, width=grip.width, reason=grip.reason,
                              duration_s=time.monotonic() - began)
        log.info("gripper %s%s", "closed" if grip.closed else "open",
                 f" for job {command.job_id}" if command.job_id else "")
        return Response(reply.model_dump_json())

    async def on_state(request: Request) -> Response:
        state = RobotState(T_base_flange=backend.pose().tolist(), moving=moving, time=time.time())
        return Response(state.model_dump_json())

    transport.serve(keys.robot_move(cell), on_move)
    transport.serve(keys.robot_grip(cell), on_grip)
    transport.serve(keys.robot_state(cell), on_state)


def main(config: CellConfig) -> int:
    async def run(stop: asyncio.Event) -> None:
        backend = make_backend(config)
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
