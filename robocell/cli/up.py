"""``robocell up``: the router, the workers, the simulated camera and the daemon as child processes.

The simulated Axis camera (``robocell sim camera``) is started when the
camera is an Axis camera (``[camera] backend = "axis"``) whose ``url`` is on
this machine's loopback, whatever the robot: nothing else could be serving a
camera there.

The children share one configuration, written as JSON into the run directory
(every ``--config`` option reads TOML or JSON). Their logs go to
``<run dir>/logs/<name>.log``. Stopping sends SIGTERM to the daemon first,
then to every worker at once, then to the router; it waits for each, and
kills what is left. Each child leads a process group of its own; once it
has stopped, whatever is left in its group is killed too.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import os
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from robocell.cell.reserve import release_if_full
from robocell.wire import keys
from robocell.wire.config import CellConfig
from robocell.wire.errors import CellError
from robocell.wire.transport import Transport

__all__ = ["CellProcesses", "up", "serves_sim_camera", "on_interrupt", "port_holder", "check_port_free"]

log = logging.getLogger(__name__)
_STOP_WAIT_S = 5.0


def serves_sim_camera(config: CellConfig) -> bool:
    """Whether the cell needs the simulated Axis camera: an Axis camera at a loopback address."""
    if config.camera.backend != "axis":
        return False
    host = urlsplit(config.camera.url).hostname or ""
    try:
        return host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name
        return False


def _robot(config: CellConfig) -> str:
    robot = config.robot
    if robot.backend == "kuka":
        return f"kuka over {robot.kuka.protocol} at {robot.kuka.host}:{robot.kuka.port}"
    return f"{robot.backend} robot"


def _camera(config: CellConfig) -> str:
    camera = config.camera
    return f"Axis camera at {camera.url}" if camera.backend == "axis" else f"{camera.backend} camera, rendered in-process"


@dataclass
class _Child:
    name: str
    argv: list[str]
    token: str | None = None    # the liveliness token it declares once ready, if any
    what: str = ""              # what it is, for a person
    process: asyncio.subprocess.Process | None = None
    stopped: bool = False   # on purpose, by stop_child: not a failure


class CellProcesses:
    """Start and stop a whole cell on this machine."""

    def __init__(self, config: CellConfig, *, with_router: bool = True, reconstructors: int = 1,
                 robot: bool = True, camera: bool = True, sim_camera: bool | None = None,
                 daemon: bool = True, view: str | None = None) -> None:
        """Which parts run as children; ``sim_camera`` defaults to :func:`serves_sim_camera`;
        ``view``: the Rerun viewer's gRPC URL the daemon streams every job to (``cell --view``).

        Leaving parts out lets a caller (a test, say) run them itself, in-process.
        """
        self.config = config
        self.run_dir = Path(config.run_dir)
        self.config_path = self.run_dir / "cell-config.json"
        self.log_dir = self.run_dir / "logs"
        command = [sys.executable, "-m", "robocell", "--config", str(self.config_path)]
        if sim_camera is None:
            sim_camera = serves_sim_camera(config)
        self.command = command
        cell = config.cell_id
        children = [_Child("router", [*command, "router"], None, f"router on {config.zenoh.router}")] \
            if with_router else []
        if robot:
            children.append(_Child("robot", [*command, "worker", "robot"], keys.alive(cell, "robot"),
                                   f"robot worker ({_robot(config)})"))
        if sim_camera:
            children.append(_Child("sim-camera", [*command, "sim", "camera"], None,
                                   f"simulated Axis camera at {config.camera.url}"))
        if camera:
            children.append(_Child("camera", [*command, "worker", "camera"], keys.alive(cell, "camera"),
                                   f"camera worker ({_camera(config)})"))
        for index in range(reconstructors):
            worker_id = f"{cell}-r{index}-{os.getpid()}"
            children.append(_Child(f"reconstruct-{index}", [*command, "worker", "reconstruct", "--id", worker_id],
                                   keys.reconstructor_alive(worker_id), f"reconstruction worker {worker_id}"))
        if daemon:
            watched = ["--view", view] if view is not None else []
            children.append(_Child("daemon", [*command, "cell", *watched], keys.alive(cell, "daemon"),
                                   f"daemon of cell {cell}" + (f", streaming the jobs to {view}" if view else "")))
        self.children = children
        self._environment: dict[str, str] = {}
        self._stopping: asyncio.Future | None = None

    async def start(self, *, ready_timeout: float = 60.0) -> None:
        """Start every child and wait until the daemon and all workers announce themselves.

        Raises
        ------
        CellError
            If a child exits during start-up, or the cell is not ready in time (the
            message names what is missing and where its log is).
        """
        if any(child.name == "router" for child in self.children):
            self._check_router_port()
        self._check_roles()
        self.log_dir.mkdir(parents=True, exist_ok=True)
        release_if_full(self.run_dir)  # on a full disk, the room the daemon keeps to start (cell.reserve)
        # The JSON masks the camera password; the children get it from the environment instead.
        self.config_path.write_text(self.config.model_dump_json(indent=1))
        self._environment = dict(os.environ)
        password = self.config.camera.resolved_password()
        if password:
            self._environment["ROBOCELL_CAMERA_PASSWORD"] = password
        for child in self.children:
            await self._spawn(child)
        await self.wait_ready(ready_timeout)

    def _check_roles(self) -> None:
        """Every part runs as ``[zenoh] user``: under the config's own access control, one whose
        role that user lacks would be dropped unseen, and the cell wait for it in vain."""
        from robocell.wire.process import check_part

        for child in self.children:
            role = "reconstruct" if child.name.startswith("reconstruct-") else child.name
            if role in ("robot", "camera", "daemon", "reconstruct"):
                worker_id = child.argv[-1] if role == "reconstruct" and "--id" in child.argv else None
                check_part(self.config, role, worker_id)

    def _check_router_port(self) -> None:
        check_port_free(self.config.zenoh.router, what="the router's port", setting="[zenoh] router")

    async def _spawn(self, child: _Child) -> None:
        child.stopped = False
        with open(self.log_dir / f"{child.name}.log", "ab") as log_file:
            child.process = await asyncio.create_subprocess_exec(
                *child.argv, stdin=asyncio.subprocess.DEVNULL, stdout=log_file, stderr=log_file,
                env=self._environment, start_new_session=True)  # Ctrl-C goes to `up`, which stops the children in order

    def describe(self) -> list[str]:
        """One line per part, in start order: what it is."""
        return [child.what or child.name for child in self.children]

    def add_child(self, name: str, argv: list[str], *, token: str | None = None) -> None:
        """Add a child (not started: see :meth:`start_child`); ``token`` is the liveliness key
        it declares once ready. A reconstruction worker, say, on a machine of its own::

            cell.add_child("reconstruct-extra", [*cell.command, "worker", "reconstruct", "--id", "extra"],
                           token=keys.reconstructor_alive("extra"))
        """
        if any(child.name == name for child in self.children):
            raise CellError(f"there is already a child named {name!r}")
        self.children.append(_Child(name, argv, token))

    async def start_child(self, name: str, *, ready_timeout: float = 30.0) -> None:
        """(Re)start one child that is not running, and wait until the cell is ready again.

        Raises
        ------
        CellError
            As :meth:`start`; also if the child is still running.
        """
        child = self.child(name)
        if child.process is not None and child.process.returncode is None:
            raise CellError(f"{name} is already running")
        await self._spawn(child)
        await self.wait_ready(ready_timeout)

    async def stop_child(self, name: str, *, kill: bool = False, gone_timeout: float = 10.0) -> int:
        """Stop one child (SIGTERM, or SIGKILL with ``kill``) and wait until the router has
        forgotten its liveliness token; returns its exit status."""
        child = self.child(name)
        child.stopped = True
        await self._stop(child, signal.SIGKILL if kill else signal.SIGTERM)
        assert child.process is not None
        if child.token is not None:
            token = child.token
            async with await Transport.open(self.config.zenoh.router, settings=self.config.zenoh.client_settings(),
                                            connect_timeout_s=gone_timeout) as transport:
                deadline = asyncio.get_running_loop().time() + gone_timeout
                while token in await transport.alive(token, timeout=1.0):
                    if asyncio.get_running_loop().time() > deadline:
                        raise CellError(f"{name} stopped, but its liveliness token is still there")
                    await asyncio.sleep(0.05)
        return child.process.returncode

    def _expected(self) -> tuple[set[str], bool]:
        """Liveliness keys, and whether the simulated camera, of running children."""
        tokens, sim_camera = set(), False
        for child in self.children:
            if child.process is None or child.process.returncode is not None:
                continue
            if child.token is not None:
                tokens.add(child.token)
            elif child.name == "sim-camera":
                sim_camera = True
        return tokens, sim_camera

    async def wait_ready(self, timeout: float) -> None:
        """Wait until every running child that announces itself has done so.

        Raises
        ------
        CellError
            If a child exits meanwhile, or something is still missing after ``timeout`` seconds.
        """
        expected, sim_camera = self._expected()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        await self._wait_router_listening(deadline)
        transport = await Transport.open(self.config.zenoh.router, settings=self.config.zenoh.client_settings(),
                                         connect_timeout_s=min(max(deadline - loop.time(), 1.0), 20.0))
        missing: list[str] = []
        try:
            while loop.time() < deadline:
                self._check_running()
                # The cell's tokens and the pool's, each asked for by name: a deployment with roles
                # lets a client watch those, not the whole of robocell/**.
                alive = set(await transport.alive(keys.alive(self.config.cell_id), timeout=1.0))
                alive |= set(await transport.alive(keys.RECONSTRUCTORS_ALIVE, timeout=1.0))
                missing = sorted(expected - alive)
                if sim_camera and not await self._sim_camera_listening():
                    missing.append(f"the simulated camera at {self.config.camera.url}")
                if not missing:
                    return
                await asyncio.sleep(0.1)
        finally:
            await transport.close()
        raise CellError(f"the cell was not ready after {timeout:g} s: waiting for "
                        f"{', '.join(missing)}; logs in {self.log_dir}")

    async def _wait_router_listening(self, deadline: float) -> None:
        """Wait until the router this cell started takes TCP connections. Zenoh's open waits in a
        thread that a Ctrl-C cannot stop (and the loop's end waits for it): it is begun only once
        the router is there, so that it returns at once."""
        router = next((c for c in self.children if c.name == "router"), None)
        endpoint = self.config.zenoh.router
        if router is None or router.process is None or not endpoint.startswith(("tcp/", "tls/")):
            return
        host, _, port = endpoint.split("/", 1)[1].split("#", 1)[0].rpartition(":")
        loop = asyncio.get_running_loop()
        while loop.time() < deadline:
            self._check_running()
            if port.isdigit() and await _listening(host.strip("[]"), int(port)):
                return
            await asyncio.sleep(0.05)

    async def _sim_camera_listening(self) -> bool:
        address = urlsplit(self.config.camera.url)
        return await _listening(address.hostname or "127.0.0.1", address.port or 80)

    def _check_running(self) -> None:
        for child in self.children:
            if child.process is not None and child.process.returncode is not None and not child.stopped:
                raise CellError(f"{child.name} exited with status {child.process.returncode}; "
                                f"see {self.log_dir / (child.name + '.log')}")

    async def wait(self) -> _Child:
        """Wait until a child exits; return it."""
        waits = {asyncio.ensure_future(c.process.wait()): c for c in self.children if c.process}
        done, pending = await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        for future in pending:
            future.cancel()
        return waits[done.pop()]

    def child(self, name: str) -> _Child:
        return next(c for c in self.children if c.name == name)

    async def stop(self) -> None:
        """Stop every child: the daemon, then the workers, then the router.

        Once begun, the stop goes on to its end even if the caller is cancelled meanwhile (a
        second Ctrl-C, say): every wait in it is time-limited, and a stop cut short would leave
        the remaining children running. The cancellation is raised once all are stopped.
        """
        if self._stopping is None or self._stopping.done():
            self._stopping = asyncio.ensure_future(self._stop_all())
        cancelled = False
        while not self._stopping.done():
            try:
                await asyncio.shield(self._stopping)
            except asyncio.CancelledError:
                cancelled = True
        self._stopping.result()
        if cancelled:
            raise asyncio.CancelledError

    async def _stop_all(self) -> None:
        # The daemon first: it commands the robot no further, and ends its jobs while the workers still
        # answer. The workers need nothing of each other to stop, and each takes a moment to end its
        # Zenoh session: together. The router last, so that every session closes cleanly.
        daemons = [child for child in self.children if child.name == "daemon"]
        routers = [child for child in self.children if child.name == "router"]
        workers = [child for child in self.children if child not in daemons and child not in routers]
        for group in (daemons, workers, routers):
            await asyncio.gather(*(self._stop(child, signal.SIGTERM) for child in group))

    def kill_remaining(self) -> list[str]:
        """Kill, at once, every child (and its process group) still running: the last resort of a
        caller whose event loop is going away. Returns their names."""
        killed = []
        for child in self.children:
            process = child.process
            if process is None or process.returncode is not None:
                continue
            killed.append(child.name)
            _kill_group(process.pid)
        return killed

    async def _stop(self, child: _Child, signum: int) -> None:
        """Stop a running child. After a SIGTERM, whatever is left of its process group is
        killed; after a SIGKILL (a crash, as tests make them) what is left is left alone: the
        daemon's recorder, say, closes the recordings of a killed daemon on its own."""
        process = child.process
        if process is None or process.returncode is not None:
            return
        process.send_signal(signum)
        if signum != signal.SIGKILL:
            process.send_signal(signal.SIGCONT)  # a frozen child must wake up to hear the SIGTERM
        try:
            async with asyncio.timeout(_STOP_WAIT_S):
                await process.wait()
        except TimeoutError:
            log.warning("%s did not stop in %g s: killing it", child.name, _STOP_WAIT_S)
            process.kill()
            await process.wait()
        if signum != signal.SIGKILL:
            _kill_group(process.pid)


def on_interrupt(task: asyncio.Future, *, again: str) -> Callable[[], int]:
    """Ctrl-C (SIGINT) and SIGTERM, heard by the running loop: the first cancels ``task``, each
    later one prints ``again`` (what is still going on) and changes nothing, so that a stop under
    way is never cut short. Returns a function that says how many signals came."""
    loop = asyncio.get_running_loop()
    count = 0

    def heard() -> None:
        nonlocal count
        count += 1
        if count == 1:
            task.cancel()
        else:
            print(again, file=sys.stderr, flush=True)

    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, heard)
    return lambda: count


def check_port_free(endpoint: str, *, what: str, setting: str) -> None:
    """Raise, naming the port and who holds it, if a Zenoh TCP or TLS ``endpoint`` on this machine
    is taken: before a router fails on it with no more than "Address already in use" in its log.

    Raises
    ------
    CellError
        ``"the router's port 7447 on 127.0.0.1 is in use by process 1234 (...): stop that, or give
        [zenoh] router another port"``.
    """
    if not endpoint.startswith(("tcp/", "tls/")):
        return
    host, _, port = endpoint.split("/", 1)[1].split("#", 1)[0].rpartition(":")
    if not port.isdigit():
        return
    host = host.strip("[]")
    holder = port_holder(host, int(port))
    if holder is not None:
        raise CellError(f"{what} {port} on {host} is in use by {holder}: stop that, or give {setting} another port")


def port_holder(host: str, port: int) -> str | None:
    """Who listens on TCP ``port`` of ``host`` already, or None if nobody does: ``"process 1234
    (python -m robocell router)"``, or ``"another process"`` where it cannot be told (Linux's
    /proc tells; another user's processes stay hidden)."""
    import errno
    import socket

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as a listener binds: TIME_WAIT is no holder
        try:
            probe.bind((host, port))
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                return None  # not ours to bind (another machine's address): the router will say
        else:
            return None
    return _listener(port) or "another process"


def _listener(port: int) -> str | None:
    inodes = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 9 and fields[3] == "0A" and int(fields[1].rsplit(":", 1)[1], 16) == port:  # LISTEN
                inodes.add(f"socket:[{fields[9]}]")
    if not inodes:
        return None
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if any(os.readlink(fd) in inodes for fd in (entry / "fd").iterdir()):
                command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
                return f"process {entry.name} ({command or '?'})"
        except OSError:  # gone meanwhile, or not ours to look into
            continue
    return None


async def _listening(host: str, port: int) -> bool:
    """Whether something takes TCP connections at ``host:port`` now."""
    try:
        async with asyncio.timeout(1.0):
            _, writer = await asyncio.open_connection(host, port)
    except (OSError, TimeoutError):
        return False
    writer.close()
    try:
        await writer.wait_closed()
    except OSError:
        pass
    return True


def _kill_group(pgid: int) -> None:
    """Kill what is left of a child's process group (the child itself has exited)."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):  # nothing left: the usual case
        pass


def up(config: CellConfig, *, view: str | None = None, view_web_port: int = 9090, view_grpc_port: int = 9877) -> int:
    """Run the cell until Ctrl-C (or SIGTERM), then stop every part cleanly; ``view``: stream every
    job to that Rerun viewer's gRPC URL, or with ``"web"`` to a web viewer started as one more part
    (``robocell.cli.view``)."""
    from .view import WEB, check_view_ports, view_url, web_viewer_argv

    if view == WEB:
        check_view_ports(view_web_port, view_grpc_port)

    async def run() -> int:
        cell = CellProcesses(config, reconstructors=1, view=view_url(view, view_grpc_port))
        if view == WEB:
            cell.add_child("viewer", web_viewer_argv(view_web_port, view_grpc_port))
        for part in cell.describe():
            print(f"starting {part}", flush=True)
        cells.append(cell)
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        heard = 0

        def on_signal() -> None:
            nonlocal heard
            heard += 1
            if heard > 1:
                print(f"still stopping the cell (each part gets {_STOP_WAIT_S:g} s, then is killed)",
                      file=sys.stderr, flush=True)
            stop.set()

        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, on_signal)
        try:
            # Ctrl-C is heard while the parts start too (that can take a minute, if one hangs).
            starting = asyncio.ensure_future(cell.start())
            stopped = asyncio.ensure_future(stop.wait())
            await asyncio.wait({starting, stopped}, return_when=asyncio.FIRST_COMPLETED)
            if not starting.done():
                starting.cancel()
                await asyncio.gather(starting, return_exceptions=True)
                print("stopped while starting", file=sys.stderr)
                return 0
            starting.result()
            print(f"cell {config.cell_id} is up: router {config.zenoh.router}, run directory "
                  f"{config.run_dir}, logs in {cell.log_dir}. Ctrl-C stops it.", flush=True)
            if view == WEB:
                from .replay import web_viewer_address

                print(f"watch the jobs live: open {web_viewer_address('127.0.0.1', view_web_port, view_grpc_port)}",
                      flush=True)
            exited = asyncio.ensure_future(cell.wait())
            await asyncio.wait({stopped, exited}, return_when=asyncio.FIRST_COMPLETED)
            if exited.done():
                child = exited.result()
                print(f"{child.name} exited with status {child.process.returncode}; stopping the cell "
                      f"(see {cell.log_dir / (child.name + '.log')})", file=sys.stderr)
                return 1
            exited.cancel()
            return 0
        except CellError as exc:
            print(f"robocell up: {exc}", file=sys.stderr)
            return 1
        finally:
            await cell.stop()

    cells: list[CellProcesses] = []
    try:
        return asyncio.run(run())
    finally:
        for cell in cells:  # only if the stop above could not finish: its loop went away first
            cell.kill_remaining()
