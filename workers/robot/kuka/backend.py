"""The robot worker's backend for a KUKA arm, over KukaVarProxy or an OpenOPC gateway.

Safety first: :func:`check_move` checks a target against the workspace box,
the tilt limit and the override limit before anything is written; a refused
move raises :class:`MoveRefused` naming the limit. Then the handshake of
``variables`` (target, override and id first, the command last), polling until
the KRL program reports done or an error, each wait bounded. The gripper takes
the same handshake; its output, input and time-out are the program's own
(``krl/robocell.dat``), and the bridge only reads what the input said.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable, Sequence
from typing import Literal, Protocol

import numpy as np

from robocell.wire.backends import KukaConfig, KukaKvpConfig, Workspace

from ..backend import Grip, RobotBackend, refuse_outside
from . import variables as v
from .e6pos import E6Pos, e6pos_from_pose, format_e6pos, parse_e6pos, pose_from_e6pos
from robocell.wire.errors import DrivesOff, EmergencyStop, MoveFailed, MoveRefused

from .errors import (ControllerBusy, ControllerRefused, GripperTimeout, KukaError, KukaProtocolError, KukaTimeout,
                     Unreachable)

__all__ = ["KukaClient", "KukaBackend", "check_move", "make_client"]

log = logging.getLogger(__name__)
Motion = Literal["ptp", "lin"]
_COMMANDS = {"ptp": v.Command.PTP, "lin": v.Command.LIN}
# Read RC_DONE_ID before RC_STATUS, RC_ERROR and the gripper's results: the program writes it after them
# (see variables). Read $PERI_RDY before $STOPMESS: a stop sets the message and drops the drives, and
# KukaVarProxy reads one variable at a time, so a stop that falls between the two reads shows as the stop,
# not as drives off.
_POLLED = [v.RC_DONE_ID.name, v.RC_STATUS.name, v.RC_ERROR.name, v.PERI_RDY.name, v.STOPMESS.name]
_POLLED_MOVING = [*_POLLED, v.POS_ACT.name]
_POLLED_GRIPPING = [*_POLLED, v.RC_GRIP_HELD.name, v.RC_GRIP_WAITED.name, v.RC_GRIP_IN.name]


class KukaClient(Protocol):
    """What the backend needs of a bridge: KRL variables as text (``KvpClient``, ``OpcClient``)."""

    address: str

    async def open(self) -> None: ...

    async def close(self) -> None: ...

    async def read(self, names: Sequence[str]) -> dict[str, str]: ...

    async def write(self, values: Sequence[tuple[str, str]]) -> None: ...


def make_client(config: KukaConfig) -> KukaClient:
    """The client of ``config.protocol``, not yet connected."""
    timeouts = {"connect_timeout": config.connect_timeout_s, "request_timeout": config.request_timeout_s}
    if isinstance(config, KukaKvpConfig):
        from .kvp import KvpClient
        return KvpClient(config.host, config.port, **timeouts)
    from .opc import OpcClient  # imports Pyro5 only when OPC is used
    return OpcClient(config.host, config.port, opc_server=config.opc_server, opc_host=config.opc_host,
                     item_prefix=config.opc_item_prefix, **timeouts)


def check_move(target, workspace: Workspace, *, override: int, max_override: int, motion: str) -> E6Pos:
    """The E6POS to command for ``target``, or :class:`MoveRefused` naming the limit it breaks.

    Pure: nothing is sent anywhere.
    """
    if motion not in _COMMANDS:
        raise MoveRefused(f"move refused: unknown motion type {motion!r} (ptp or lin)", limit="motion")
    if not 1 <= override <= max_override:
        raise MoveRefused(f"move refused: override {override} % is outside 1..{max_override} % "
                          f"(the configured maximum)", limit="override")
    try:
        position = e6pos_from_pose(target)
    except ValueError as exc:
        raise MoveRefused(f"move refused: {exc}", limit="pose") from None
    refuse_outside(np.asarray(target, dtype=np.float64), workspace)
    return position


def _parse(text: str, parse: Callable[[str], object], name: str):
    try:
        return parse(text)
    except ValueError as exc:
        raise KukaProtocolError(f"{name}: {exc}") from None


def _flag(values: dict[str, str], var: v.KrlVar) -> bool:
    return bool(_parse(values[var.name], lambda text: v.from_krl_text("BOOL", text), var.name))


def _int(values: dict[str, str], var: v.KrlVar) -> int:
    return int(_parse(values[var.name], int, var.name))


def _real(values: dict[str, str], var: v.KrlVar) -> float:
    return float(_parse(values[var.name], float, var.name))


class KukaBackend(RobotBackend):
    """``RobotBackend`` for a KUKA controller running ``krl/robocell.src``.

    ``client`` is a :class:`KukaClient`; the backend opens and closes it
    (``async with KukaBackend(...)`` or :meth:`open` / :meth:`close`).
    """

    def __init__(self, client: KukaClient, workspace: Workspace, *, max_override: int = 30, override: int = 20,
                 motion: Motion = "ptp", ack_timeout_s: float = 2.0, move_timeout_s: float = 60.0,
                 grip_timeout_s: float = 10.0, poll_period_s: float = 0.05, reached_tolerance_mm: float = 1.0,
                 reached_tolerance_deg: float = 0.5) -> None:
        self.client, self.workspace = client, workspace
        self.max_override, self.override, self.motion = max_override, override, motion
        self.ack_timeout_s, self.move_timeout_s, self.poll_period_s = ack_timeout_s, move_timeout_s, poll_period_s
        self.grip_timeout_s = grip_timeout_s
        self.reached_tolerance_mm, self.reached_tolerance_deg = reached_tolerance_mm, reached_tolerance_deg
        self._pose: np.ndarray | None = None
        self._motion_lock = asyncio.Lock()

    @classmethod
    def from_config(cls, config: KukaConfig, workspace: Workspace) -> "KukaBackend":
        return cls(make_client(config), workspace, max_override=config.max_override, override=config.override,
                   motion=config.motion, ack_timeout_s=config.ack_timeout_s, move_timeout_s=config.move_timeout_s,
                   grip_timeout_s=config.grip_timeout_s, poll_period_s=config.poll_period_s,
                   reached_tolerance_mm=config.reached_tolerance_mm, reached_tolerance_deg=config.reached_tolerance_deg)

    async def open(self) -> None:
        """Connect and read the flange's pose (so that :meth:`pose` has one)."""
        await self.client.open()
        await self.read_pose()

    async def close(self) -> None:
        await self.client.close()

    def pose(self) -> np.ndarray:
        """The flange's pose as last read ($POS_ACT, during a move or by :meth:`read_pose`)."""
        if self._pose is None:
            raise KukaError(f"no pose read from {self.client.address} yet: open the backend first")
        return self._pose.copy()

    async def read_pose(self) -> np.ndarray:
        """Read $POS_ACT now: the flange's pose in the robot base frame (4x4, metres)."""
        text = (await self.client.read([v.POS_ACT.name]))[v.POS_ACT.name]
        self._pose = pose_from_e6pos(_parse(text, parse_e6pos, v.POS_ACT.name))
        return self._pose.copy()

    async def move(self, target: np.ndarray, on_progress, *, motion: Motion | None = None,
                   override: int | None = None) -> np.ndarray:
        """Move the flange to ``target`` (4x4, base frame, metres); return the pose reached.

        ``on_progress(pose, True)`` is called at every poll while moving.

        Raises
        ------
        MoveRefused
            Before anything is written: the target breaks a limit (``limit`` says which).
        ControllerBusy
            Before anything is written: the controller still holds a command.
        EmergencyStop, DrivesOff
            Before or during the move.
        ControllerRefused, Unreachable
            The KRL program checked the command and refused it.
        KukaTimeout
            The program did not take the command within ``ack_timeout_s`` (it is withdrawn),
            or the move took longer than ``move_timeout_s``.
        MoveFailed
            The move ended away from the target.
        KukaConnectionError, KukaProtocolError, KukaVariableError
        """
        motion = motion or self.motion
        override = self.override if override is None else override
        position = check_move(target, self.workspace, override=override, max_override=self.max_override,
                              motion=motion)
        async with self._motion_lock:
            await self._command(_COMMANDS[motion], [(v.RC_TARGET.name, format_e6pos(position)),
                                                    (v.RC_OVERRIDE.name, str(override))],
                                "move", self.move_timeout_s, _POLLED_MOVING, on_progress)
        reached = self.pose()
        self._check_reached(reached, np.asarray(target, dtype=np.float64))
        return reached

    async def grip(self, close: bool) -> Grip:
        """Close (``close``) or open the gripper; closing says whether the gripper's input confirms a hold.

        The program (robocell.src ``GRIP``) switches its output and waits at most its
        GRIP_TIMEOUT for its input. A close the input does not confirm is a miss:
        ``holding`` False, and ``reason`` names the input and the time waited.
        An open returns ``holding`` None.

        Raises
        ------
        GripperTimeout
            The gripper opened, but its input still said it held a part after GRIP_TIMEOUT.
        ControllerBusy, EmergencyStop, DrivesOff, KukaTimeout, KukaConnectionError, ...
            As for :meth:`move` (``grip_timeout_s`` bounds the whole command).
        """
        command = v.Command.GRIP_CLOSE if close else v.Command.GRIP_OPEN
        async with self._motion_lock:
            values = await self._command(command, [], "gripper's closing" if close else "gripper's opening",
                                         self.grip_timeout_s, _POLLED_GRIPPING, None)
        if not close:
            return Grip(closed=False)
        waited, number = _real(values, v.RC_GRIP_WAITED), _int(values, v.RC_GRIP_IN)
        if _flag(values, v.RC_GRIP_HELD):
            return Grip(closed=True, holding=True, reason=f"held: $IN[{number}] confirmed it in {waited:.2f} s")
        return Grip(closed=True, holding=False,
                    reason=f"the gripper's input $IN[{number}] (robocell.dat GRIP_IN) did not confirm a hold within "
                           f"{waited:g} s (GRIP_TIMEOUT): nothing between the jaws, or the gripper did not close")

    async def _command(self, command: v.Command, arguments: list[tuple[str, str]], what: str, timeout_s: float,
                       polled: list[str], on_progress) -> dict[str, str]:
        """Send one command by the handshake and wait for the program to finish it: its last poll."""
        command_id = await self._preflight(what)
        await self.client.write([*arguments, (v.RC_CMD_ID.name, str(command_id))])
        # Alone and last: the trigger must not reach the program before its arguments.
        await self.client.write([(v.RC_CMD.name, str(int(command)))])
        log.info("commanded %s (id %d)%s", command.name, command_id,
                 "".join(f", {name} {value}" for name, value in arguments))
        return await self._wait(command_id, what, timeout_s, polled, on_progress)

    async def _preflight(self, what: str) -> int:
        values = await self.client.read([v.RC_CMD.name, v.RC_DONE_ID.name, v.PERI_RDY.name, v.STOPMESS.name])
        self._raise_if_stopped(values, f"before the {what}")
        if _int(values, v.RC_CMD) != v.Command.NONE:
            raise ControllerBusy(f"{self.client.address}: RC_CMD is {values[v.RC_CMD.name]}, not 0: the program "
                                 "still holds a command (one in progress, or a program stopped in the middle of one: "
                                 "reset it)")
        # Never the id the controller last finished, even after this bridge restarted.
        return _int(values, v.RC_DONE_ID) % 32767 + 1

    def _raise_if_stopped(self, values: dict[str, str], when: str) -> None:
        if _flag(values, v.STOPMESS):
            raise EmergencyStop(f"{when}: a stop message is active on the controller ($STOPMESS): emergency stop "
                                "or safety stop; acknowledge it on the smartPAD")
        if not _flag(values, v.PERI_RDY):
            raise DrivesOff(f"{when}: the drives are off ($PERI_RDY is FALSE): switch them on")

    async def _wait(self, command_id: int, what: str, timeout_s: float, polled: list[str],
                    on_progress) -> dict[str, str]:
        began = time.monotonic()
        taken = False
        while True:
            values = await self.client.read(polled)
            if v.POS_ACT.name in values:
                self._pose = pose_from_e6pos(_parse(values[v.POS_ACT.name], parse_e6pos, v.POS_ACT.name))
            done = _int(values, v.RC_DONE_ID) == command_id
            status = _int(values, v.RC_STATUS)
            taken = taken or done or status == v.Status.MOVING
            elapsed = time.monotonic() - began
            if done:
                if status == v.Status.DONE:
                    return values
                if status == v.Status.ERROR:
                    self._raise_refused(values, what)
                raise KukaProtocolError(f"command {command_id} finished with RC_STATUS {status}, "
                                        "neither DONE nor ERROR")
            self._raise_if_stopped(values, f"{elapsed:.1f} s into the {what}")
            if not taken and elapsed > self.ack_timeout_s:
                await self._withdraw(command_id)
                raise KukaTimeout(f"the KRL program did not take the command within {self.ack_timeout_s:g} s "
                                  "(is robocell.src running, in AUT or EXT?); the command was withdrawn")
            if elapsed > timeout_s:
                raise KukaTimeout(f"the {what} did not end within {timeout_s:g} s")
            if on_progress is not None:
                on_progress(self._pose, True)
            await asyncio.sleep(self.poll_period_s)

    async def _withdraw(self, command_id: int) -> None:
        # Otherwise the program would run this stale move whenever it is next started.
        with contextlib.suppress(KukaError):
            await self.client.write([(v.RC_CMD.name, str(int(v.Command.NONE)))])
            return
        log.warning("could not withdraw command %d from %s", command_id, self.client.address)

    @staticmethod
    def _raise_refused(values: dict[str, str], what: str) -> None:
        """The program's error code (RC_ERROR) as the error it stands for."""
        code = _int(values, v.RC_ERROR)
        if code == v.ErrorCode.GRIP_TIMEOUT and v.RC_GRIP_IN.name in values:
            raise GripperTimeout(f"the gripper did not let go: its input $IN[{_int(values, v.RC_GRIP_IN)}] "
                                 f"(robocell.dat GRIP_IN) still said it held a part after "
                                 f"{_real(values, v.RC_GRIP_WAITED):g} s (GRIP_TIMEOUT); it may still hold it",
                                 code=code)
        try:
            reason = v.ERROR_MESSAGES[v.ErrorCode(code)]
        except ValueError:
            reason = "an error code robocell does not know"
        message = f"the KRL program refused the {what} (RC_ERROR {code}): {reason}"
        if code == v.ErrorCode.UNREACHABLE:
            raise Unreachable(message, code=code)
        raise ControllerRefused(message, code=code)

    def _check_reached(self, reached: np.ndarray, target: np.ndarray) -> None:
        distance_mm = 1000.0 * float(np.linalg.norm(reached[:3, 3] - target[:3, 3]))
        cosine = (np.trace(reached[:3, :3].T @ target[:3, :3]) - 1.0) / 2.0
        angle_deg = math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))
        if distance_mm > self.reached_tolerance_mm or angle_deg > self.reached_tolerance_deg:
            raise MoveFailed(f"the move ended {distance_mm:.2f} mm and {angle_deg:.2f} deg from its target "
                             f"(tolerance {self.reached_tolerance_mm:g} mm, {self.reached_tolerance_deg:g} deg)")
