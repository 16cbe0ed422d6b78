"""A simulated KUKA controller behind the real wire protocols: KukaVarProxy (TCP) and the OpenOPC gateway (Pyro5).

:class:`SimController` behaves like ``krl/robocell.src``: it takes a command
a moment after RC_CMD is set, checks it as the program does (override, its own
box and tilt limit, reach), moves over time ($POS_ACT follows), then reports
done or an error code and clears the command. Its gripper's output follows the
gripper commands, and its input confirms them ``grip_delay_s`` later: on closing,
only if ``holds(flange pose)`` says the gripper holds a part there (``robocell sim
kuka`` judges that against the configuration's scene, ``SceneGripper``). Faults on
demand: emergency stop, drives off, an unreachable pose, a program that is not
running ("stall"), a bridge that stops answering ("hang") or drops its connections
("drop"), a gripper whose input never changes ("grip_stuck"); each now (:meth:`SimController.inject`)
or as the program takes a later command (``fault_after``, ``robocell sim kuka --fault``).
$AXIS_ACT is made up (no kinematic model): it only has the right form.

:class:`KvpServer` speaks KukaVarProxy's framing (``workers.kuka.kvp``);
:class:`OpcGateway` is a Pyro5 daemon with the gateway's object ids
``OpenOpcGatewayServer`` and ``OpcDaClient`` and openopc2's method signatures.
``robocell sim kuka --protocol kvp|opc`` runs one (:func:`main`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import signal
import threading
import time
from collections.abc import Callable
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from robocell.workers.robot.kuka import variables as v
from robocell.wire.backends import SIM_OPC_SERVER, KukaKvpConfig, KukaOpcConfig
from robocell.workers.robot.kuka.e6pos import E6Pos, e6pos_from_pose, format_e6pos, parse_e6pos, pose_from_e6pos
from robocell.workers.robot.kuka.kvp import READ, WRITE, decode_request, encode_response

__all__ = ["SimController", "KvpServer", "OpcGateway", "SimKuka", "main"]

log = logging.getLogger(__name__)
#: Each protocol's usual port, as the bridge's configuration has it.
DEFAULT_PORTS = {"kvp": KukaKvpConfig.model_fields["port"].default, "opc": KukaOpcConfig.model_fields["port"].default}
Fault = Literal["emergency_stop", "drives_off", "unreachable", "stall", "hang", "drop", "grip_stuck"]
HOME = [[1.0, 0.0, 0.0, 0.4], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.6], [0.0, 0.0, 0.0, 1.0]]
_HANG_LIMIT_S = 30.0  # a hung bridge answers after this at the latest, so nothing waits forever


class SimController:
    """The controller and its KRL program, advanced lazily from the clock under one lock (thread-safe).

    ``box_mm`` and ``max_tilt_deg``, ``max_override`` are the program's own
    limits (robocell.dat); ``reach_mm`` the arm's reach from the base origin.
    ``grip_in`` and ``grip_timeout_s`` are the program's GRIP_IN and GRIP_TIMEOUT;
    the gripper's input follows its output ``grip_delay_s`` after a command, and a
    close holds a part when ``holds(flange pose)`` says so (None: always).
    """

    def __init__(self, home=HOME, *, speed_mm_s: float = 500.0, rotation_deg_s: float = 90.0,
                 pickup_s: float = 0.02, reach_mm: float = 1100.0, max_override: int = 30,
                 box_mm=((100.0, -700.0, 50.0), (1000.0, 700.0, 1000.0)), max_tilt_deg: float = 80.0,
                 grip_in: int = 1, grip_timeout_s: float = 2.0, grip_delay_s: float = 0.05,
                 holds: Callable[[np.ndarray], bool] | None = None,
                 fault_after: tuple[Fault, int] | None = None) -> None:
        self.speed_mm_s, self.rotation_deg_s, self.pickup_s = speed_mm_s, rotation_deg_s, pickup_s
        self.reach_mm, self.max_override, self.box_mm, self.max_tilt_deg = reach_mm, max_override, box_mm, max_tilt_deg
        self.grip_timeout_s, self.grip_delay_s, self.holds = grip_timeout_s, grip_delay_s, holds
        self._lock = threading.RLock()
        self._pose = np.asarray(home, dtype=np.float64)
        self._ints = {var.name: 0 for var in v.GLOBALS if var.type == "INT"}
        self._ints[v.RC_GRIP_IN.name] = grip_in
        # Globals only the program writes, besides its INTs: what the last gripper command left.
        self._results: dict[str, object] = {v.RC_GRIP_HELD.name: False, v.RC_GRIP_WAITED.name: 0.0}
        #: The gripper's output (TRUE closes) and input (TRUE holds a part), as the I/O shows them now.
        self.gripper_output = self.gripper_input = False
        self._grip: tuple[float, bool, bool, float] | None = None  # end, closing, the input then, time waited
        self._target = e6pos_from_pose(self._pose)
        self._motion: tuple[float, float, np.ndarray, np.ndarray] | None = None  # start, end, from, to
        self._cmd_set_at = 0.0
        self.faults: set[str] = set()
        self.unhung = threading.Event()
        self.writes: list[tuple[str, str]] = []  # every accepted write, in order
        self.commands: list[tuple[int, int, str, int]] = []  # (id, command, target, override) the program took
        #: A fault that starts as the program takes its command number N + 1 (after N commands).
        self.fault_after = fault_after

    # --- what the bridges see ------------------------------------------------------------------

    def read(self, name: str) -> object | None:
        """The value of a variable (int, bool or KRL text), or None for an unknown one."""
        with self._lock:
            self._advance(time.monotonic())
            if name in self._ints:
                return self._ints[name]
            if name in self._results:
                return self._results[name]
            if name == v.RC_TARGET.name:
                return format_e6pos(self._target)
            if name == v.POS_ACT.name:
                return format_e6pos(e6pos_from_pose(self._pose, s=2, t=35))
            if name == v.AXIS_ACT.name:
                x, y, z = 1000.0 * self._pose[:3, 3]
                return f"{{E6AXIS: A1 {math.degrees(math.atan2(y, x)):.4f}, A2 -90.0, A3 {z / 10:.4f}, A4 0.0, " \
                       "A5 90.0, A6 0.0, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
            if name == v.STOPMESS.name:
                return "emergency_stop" in self.faults
            if name == v.PERI_RDY.name:
                return not self.faults & {"emergency_stop", "drives_off"}
            return None

    def write(self, name: str, value: object) -> bool:
        """Set a global variable (system variables are write-protected); False if refused."""
        text = v.krl_text(value)
        with self._lock:
            self._advance(time.monotonic())
            try:
                if name in self._ints:
                    self._ints[name] = int(text)
                    if name == v.RC_CMD.name:
                        self._cmd_set_at = time.monotonic()
                elif name == v.RC_TARGET.name:
                    self._target = parse_e6pos(text)
                else:
                    return False
            except ValueError:
                return False
            self.writes.append((name, text))
            return True

    # --- for tests and demos -------------------------------------------------------------------

    def pose(self) -> np.ndarray:
        with self._lock:
            self._advance(time.monotonic())
            return self._pose.copy()

    def inject(self, fault: Fault) -> None:
        """Start a fault; :meth:`reset` ends them all."""
        with self._lock:
            self._advance(time.monotonic())
            self._start(fault)

    def _start(self, fault: Fault) -> None:
        if fault in ("emergency_stop", "drives_off"):
            # The arm stops where it is; the program stays mid-move or mid-wait for the gripper.
            self._motion = self._grip = None
        if fault == "hang":
            self.unhung.clear()
        self.faults.add(fault)

    def acknowledge(self) -> None:
        """Acknowledge the stop and press Start: the program resumes a move it was stopped in."""
        with self._lock:
            self.faults -= {"emergency_stop", "drives_off"}
            self._cmd_set_at = time.monotonic() - self.pickup_s  # it takes the held command again, now

    def reset(self) -> None:
        """Acknowledge every fault, switch the drives on and restart the program (its INI clears the command)."""
        with self._lock:
            self.faults.clear()
            self.unhung.set()
            self._motion = self._grip = None
            self._ints[v.RC_CMD.name] = v.Command.NONE
            self._ints[v.RC_STATUS.name] = v.Status.IDLE

    def take(self, fault: Fault) -> bool:
        """Whether ``fault`` is on, ending it (for one-shot faults such as "drop")."""
        with self._lock:
            if fault in self.faults:
                self.faults.discard(fault)
                return True
            return False

    # --- the KRL program -----------------------------------------------------------------------

    def _advance(self, now: float) -> None:
        if self.faults & {"emergency_stop", "drives_off", "stall"}:
            return  # the program is stopped, or not running
        ints = self._ints
        if self._motion is not None:
            start, end, begin, goal = self._motion
            if now < end:
                self._pose = self._between(begin, goal, (now - start) / (end - start))
                return
            self._pose, self._motion = goal, None
            self._finish(v.Status.DONE, v.ErrorCode.NONE)
        if self._grip is not None:
            end, closing, level, waited = self._grip
            if now < end:
                return
            self._grip, self.gripper_input = None, level
            self._results[v.RC_GRIP_HELD.name], self._results[v.RC_GRIP_WAITED.name] = level, waited
            if level and not closing:
                self._finish(v.Status.ERROR, v.ErrorCode.GRIP_TIMEOUT)
            else:
                self._finish(v.Status.DONE, v.ErrorCode.NONE)
        taken_at = self._cmd_set_at + self.pickup_s
        if ints[v.RC_CMD.name] == v.Command.NONE or self._motion is not None or self._grip is not None \
                or now < taken_at:
            return
        if self.fault_after is not None and len(self.commands) >= self.fault_after[1]:
            fault, self.fault_after = self.fault_after[0], None
            self._start(fault)  # as the command comes in: an e-stop holds it, a drop cuts the link
            if self.faults & {"emergency_stop", "drives_off", "stall"}:
                return
        ints[v.RC_STATUS.name] = v.Status.MOVING
        command, override = ints[v.RC_CMD.name], ints[v.RC_OVERRIDE.name]
        self.commands.append((ints[v.RC_CMD_ID.name], command, format_e6pos(self._target), override))
        if command in (v.Command.GRIP_CLOSE, v.Command.GRIP_OPEN):
            self._grip = self._gripping(command == v.Command.GRIP_CLOSE, taken_at)
            self._advance(now)
            return
        error = self._check(command, override, self._target)
        if error:
            self._finish(v.Status.ERROR, error)
            return
        goal = pose_from_e6pos(self._target)
        duration = self._duration(self._pose, goal, override)
        self._motion = (taken_at, taken_at + duration, self._pose.copy(), goal)
        self._advance(now)

    def _gripping(self, closing: bool, taken_at: float) -> tuple[float, bool, bool, float]:
        """GRIP of robocell.src: switch the output, wait for the input (at most grip_timeout_s)."""
        self.gripper_output = closing
        if "grip_stuck" in self.faults:
            level = self.gripper_input
        else:
            level = closing and (self.holds is None or bool(self.holds(self._pose)))
        waited = self.grip_delay_s if level == closing else self.grip_timeout_s
        return taken_at + waited, closing, level, waited

    def _finish(self, status: v.Status, error: v.ErrorCode) -> None:
        self._ints[v.RC_ERROR.name] = error
        self._ints[v.RC_STATUS.name] = status
        self._ints[v.RC_DONE_ID.name] = self._ints[v.RC_CMD_ID.name]
        self._ints[v.RC_CMD.name] = v.Command.NONE

    def _check(self, command: int, override: int, target: E6Pos) -> v.ErrorCode:
        if command not in (v.Command.PTP, v.Command.LIN):
            return v.ErrorCode.BAD_COMMAND
        if not 1 <= override <= self.max_override:
            return v.ErrorCode.BAD_OVERRIDE
        low, high = self.box_mm
        if not all(lo <= x <= hi for lo, x, hi in zip(low, (target.x, target.y, target.z), high)):
            return v.ErrorCode.OUTSIDE_WORKSPACE
        down = -math.cos(math.radians(target.b)) * math.cos(math.radians(target.c))
        if down < math.cos(math.radians(self.max_tilt_deg)):
            return v.ErrorCode.BAD_ORIENTATION
        if self.take("unreachable") or math.dist((0, 0, 0), (target.x, target.y, target.z)) > self.reach_mm:
            return v.ErrorCode.UNREACHABLE
        return v.ErrorCode.NONE

    def _duration(self, begin: np.ndarray, goal: np.ndarray, override: int) -> float:
        scale = override / 100.0
        distance = 1000.0 * float(np.linalg.norm(goal[:3, 3] - begin[:3, 3]))
        angle = float(np.degrees((Rotation.from_matrix(begin[:3, :3]).inv() * Rotation.from_matrix(goal[:3, :3]))
                                 .magnitude()))
        return max(distance / (self.speed_mm_s * scale), angle / (self.rotation_deg_s * scale), 1e-3)

    @staticmethod
    def _between(begin: np.ndarray, goal: np.ndarray, fraction: float) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, 3] = (1 - fraction) * begin[:3, 3] + fraction * goal[:3, 3]
        rotations = Rotation.from_matrix(np.stack([begin[:3, :3], goal[:3, :3]]))
        pose[:3, :3] = Slerp([0.0, 1.0], rotations)(fraction).as_matrix()
        return pose


class KvpServer:
    """KukaVarProxy's TCP server in front of a :class:`SimController` (``port`` 0: any free port)."""

    def __init__(self, controller: SimController, host: str = "127.0.0.1", port: int = 0) -> None:
        self.controller, self.host, self.port = controller, host, port
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._closing = False

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._serve, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        self._closing = True  # also ends a "hang"
        if self._server is not None:
            self._server.close()
            for writer in list(self._writers):
                writer.close()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(5.0):
                    await self._server.wait_closed()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        try:
            while True:
                header = await reader.readexactly(4)
                msg_id, length = int.from_bytes(header[:2], "big"), int.from_bytes(header[2:], "big")
                function, name, value = decode_request(await reader.readexactly(length))
                if self.controller.take("drop"):
                    return
                deadline = time.monotonic() + _HANG_LIMIT_S
                while "hang" in self.controller.faults and not self._closing and time.monotonic() < deadline:
                    await asyncio.sleep(0.01)
                if function == READ:
                    read = "PONG" if name == "PING" else self.controller.read(name)
                    answer = encode_response(msg_id, READ, "" if read is None else v.krl_text(read), True)
                elif function == WRITE and value is not None:
                    answer = encode_response(msg_id, WRITE, value, self.controller.write(name, value))
                else:
                    answer = encode_response(msg_id, function, "", False)
                writer.write(answer)
                await writer.drain()
        except (asyncio.IncompleteReadError, ConnectionError, ValueError):
            pass  # the client went away or sent garbage: KukaVarProxy drops such a client
        finally:
            self._writers.discard(writer)
            writer.close()


class OpcGateway:
    """An OpenOPC gateway (Pyro5 daemon, in a thread) in front of a :class:`SimController`."""

    def __init__(self, controller: SimController, host: str = "127.0.0.1", port: int = 0, *,
                 server_name: str = SIM_OPC_SERVER, item_prefix: str = "") -> None:
        self.controller, self.host, self.port = controller, host, port
        self.server_name, self.item_prefix = server_name, item_prefix
        self._daemon = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        from .kuka_opc import make_daemon
        self._daemon = make_daemon(self, self.host, self.port)
        self.port = self._daemon.sock.getsockname()[1]
        self._thread = threading.Thread(target=self._daemon.requestLoop, name="sim-opc-gateway", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self.controller.unhung.set()  # release hung calls, so the daemon's threads can end
        if self._daemon is not None:
            self._daemon.shutdown()
            if self._thread is not None:
                self._thread.join(10.0)
            self._daemon.close()
            self._daemon = None


class SimKuka:
    """A simulated controller behind one protocol's server: ``async with SimKuka("kvp") as sim``.

    ``sim.port`` is the port it listens on (a free one when ``port`` is 0),
    ``sim.controller`` the :class:`SimController` to inspect and to inject faults into.
    """

    def __init__(self, protocol: Literal["kvp", "opc"], host: str = "127.0.0.1", port: int = 0, *,
                 server_name: str = SIM_OPC_SERVER, item_prefix: str = "", **controller) -> None:
        if protocol not in DEFAULT_PORTS:
            raise ValueError(f"unknown protocol {protocol!r}: kvp or opc")
        self.protocol, self.host = protocol, host
        self.controller = SimController(**controller)
        self._server = (KvpServer(self.controller, host, port) if protocol == "kvp" else
                        OpcGateway(self.controller, host, port, server_name=server_name, item_prefix=item_prefix))

    @property
    def port(self) -> int:
        return self._server.port

    async def __aenter__(self) -> "SimKuka":
        if isinstance(self._server, KvpServer):
            await self._server.start()
        else:
            await asyncio.to_thread(self._server.start)
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        if isinstance(self._server, KvpServer):
            await self._server.stop()
        else:
            await asyncio.to_thread(self._server.stop)


async def main(protocol: Literal["kvp", "opc"], host: str = "127.0.0.1", port: int | None = None, *,
               stop: asyncio.Event | None = None, **options) -> None:
    """Serve a simulated controller until ``stop`` is set (or the task is cancelled).

    ``port`` None is the protocol's usual port (7000 kvp, 7766 opc); ``options``
    go to :class:`SimKuka` and :class:`SimController`.
    """
    port = DEFAULT_PORTS[protocol] if port is None else port
    async with SimKuka(protocol, host, port, **options) as sim:
        # SIGUSR1 resets the controller, as acknowledging a fault on the pendant and restarting would.
        asyncio.get_running_loop().add_signal_handler(signal.SIGUSR1, sim.controller.reset)
        fault = sim.controller.fault_after
        log.info("simulated KUKA controller: %s on %s:%d%s", protocol, host, sim.port,
                 "" if fault is None else f"; {fault[0]} as it takes command {fault[1] + 1} (SIGUSR1 resets)")
        await (stop or asyncio.Event()).wait()
