"""``robocell up``: the router, the workers, the simulated camera and the daemon as child processes.

The children share one configuration, written as JSON into the run directory
(every ``--config`` option reads TOML or JSON). Their logs go to
``<run dir>/logs/<name>.log``. Stopping sends SIGTERM in reverse start
order, waits, and kills what is left.
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

from . import keys
from .config import CellConfig
from .errors import CellError
from .transport import Transport

__all__ = ["CellProcesses", "up"]

log = logging.getLogger(__name__)
_STOP_WAIT_S = 5.0


@dataclass
class _Child:
    name: str
    argv: list[str]
    process: asyncio.subprocess.Process | None = None


class CellProcesses:
    """Start and stop a whole cell on this machine."""

    def __init__(self, config: CellConfig, *, with_router: bool = True, reconstructors: int = 1) -> None:
        self.config = config
        self.run_dir = Path(config.run_dir)
        self.config_path = self.run_dir / "cell-config.json"
        self.log_dir = self.run_dir / "logs"
        command = [sys.executable, "-m", "cell.cli", "--config", str(self.config_path)]
        children = [_Child("router", [*command, "router"])] if with_router else []
        children.append(_Child("robot", [*command, "worker", "robot"]))
        if config.robot.backend == "sim":
            children.append(_Child("sim-camera", [*command, "sim", "camera"]))
        children.append(_Child("camera", [*command, "worker", "camera"]))
        for index in range(reconstructors):
            children.append(_Child(f"reconstruct-{index}", [*command, "worker", "reconstruct",
                                                            "--id", f"{config.cell_id}-r{index}-{os.getpid()}"]))
        children.append(_Child("daemon", [*command, "cell"]))
        self.children = children

    async def start(self, *, ready_timeout: float = 60.0) -> None:
        """Start every child and wait until the daemon and all workers announce themselves.

        Raises
        ------
        CellError
            If a child exits during start-up, or the cell is not ready in time (the
            message names what is missing and where its log is).
        """
        self.log_dir.mkdir(parents=True, exist_ok=True)
        # The JSON masks the camera password; the children get it from the environment instead.
        self.config_path.write_text(self.config.model_dump_json(indent=1))
        environment = dict(os.environ)
        password = self.config.camera.resolved_password()
        if password:
            environment["ROBOCELL_CAMERA_PASSWORD"] = password
        for child in self.children:
            with open(self.log_dir / f"{child.name}.log", "ab") as log_file:
                child.process = await asyncio.create_subprocess_exec(
                    *child.argv, stdin=asyncio.subprocess.DEVNULL, stdout=log_file, stderr=log_file,
                    env=environment, start_new_session=True)  # Ctrl-C goes to `up`, which stops the children in order
        await self._wait_ready(ready_timeout)

    async def _wait_ready(self, timeout: float) -> None:
        expected = {keys.alive(self.config.cell_id, part) for part in ("daemon", "robot", "camera")}
        n_reconstructors = sum(1 for c in self.children if c.name.startswith("reconstruct"))
        transport = await Transport.open(self.config.zenoh.router, settings=self.config.zenoh.settings,
                                         connect_timeout_s=min(timeout, 20.0))
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        missing: set[str] = set()
        try:
            while loop.time() < deadline:
                self._check_running()
                alive = set(await transport.alive(f"{keys.ROOT}/**", timeout=1.0))
                missing = expected - alive
                pool = [key for key in alive if key.startswith(keys.RECONSTRUCTORS_ALIVE[:-1])]
                if not missing and len(pool) >= n_reconstructors:
                    return
                await asyncio.sleep(0.1)
        finally:
            await transport.close()
        raise CellError(f"the cell was not ready after {timeout:g} s: waiting for "
                        f"{', '.join(sorted(missing)) or 'reconstruction workers'}; logs in {self.log_dir}")

    def _check_running(self) -> None:
        for child in self.children:
            if child.process is not None and child.process.returncode is not None:
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
        for child in reversed(self.children):
            process = child.process
            if process is None or process.returncode is not None:
                continue
            process.send_signal(signal.SIGTERM)
            try:
                await asyncio.wait_for(process.wait(), _STOP_WAIT_S)
            except asyncio.TimeoutError:
                log.warning("%s did not stop in %g s: killing it", child.name, _STOP_WAIT_S)
                process.kill()
                await process.wait()


def up(config: CellConfig) -> int:
    """Run the cell until Ctrl-C (or SIGTERM), then stop every part cleanly."""

    async def run() -> int:
        cell = CellProcesses(config, reconstructors=1)
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)
        try:
            await cell.start()
            print(f"cell {config.cell_id} is up: router {config.zenoh.router}, run directory "
                  f"{config.run_dir}, logs in {cell.log_dir}. Ctrl-C stops it.", flush=True)
            stopped = asyncio.ensure_future(stop.wait())
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

    return asyncio.run(run())
