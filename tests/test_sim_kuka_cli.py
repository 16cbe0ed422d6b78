"""`robocell sim kuka` as a user runs it: where the configuration's KUKA bridge looks for it, and the
faults it plays on demand (`--fault`), met by the real bridge."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydantic import TypeAdapter

from tests.cell_fixtures import free_port, wait_until
from robocell.wire.backends import KukaConfig, Workspace
from robocell.wire.errors import DrivesOff, EmergencyStop
from robocell.workers.robot.kuka.backend import KukaBackend
from robocell.workers.robot.kuka.errors import KukaConnectionError

REPO = Path(__file__).resolve().parents[1]


def _flange(x: float, y: float, z: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
    pose[:3, 3] = [x, y, z]
    return pose


class SimKukaProcess:
    def __init__(self, tmp_path: Path, protocol: str, *argv: str) -> None:
        self.port = free_port()
        config = tmp_path / "kuka.toml"
        config.write_text(f'[robot]\nbackend = "kuka"\n[robot.kuka]\nprotocol = "{protocol}"\nport = {self.port}\n')
        self.log = tmp_path / "sim-kuka.log"
        with open(self.log, "wb") as log:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "robocell", "--config", str(config), "sim", "kuka", "--speed", "20000",
                 "--rotation-speed", "20000", *argv], stdout=log, stderr=subprocess.STDOUT,
                env={**os.environ, "PYTHONPATH": str(REPO)})
        wait_until(lambda: f"on 127.0.0.1:{self.port}" in self.log.read_text() or self._gone(), timeout=60,
                   what="the simulated controller to listen")

    def _gone(self) -> bool:
        if self.process.poll() is not None:
            raise AssertionError(self.log.read_text())
        return False

    def close(self) -> str:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=30)
        return self.log.read_text()


def _backend(protocol: str, port: int):
    settings = {"protocol": protocol, "port": port, "connect_timeout_s": 2.0, "request_timeout_s": 1.0,
                "ack_timeout_s": 0.5, "move_timeout_s": 10.0, "poll_period_s": 0.01}
    return KukaBackend.from_config(TypeAdapter(KukaConfig).validate_python(settings), Workspace())


def _run(coroutine, limit: float = 60.0):
    async def bounded():
        async with asyncio.timeout(limit):
            return await coroutine
    return asyncio.run(bounded())


@pytest.mark.parametrize(("fault", "error", "protocol"), [("estop", EmergencyStop, "kvp"),
                                                          ("drives-off", DrivesOff, "opc")])
def test_a_fault_after_n_moves_meets_the_bridge_and_sigusr1_clears_it(tmp_path, fault, error, protocol):
    """The configuration's protocol and port are the simulator's; the fault comes at the second move."""
    sim = SimKukaProcess(tmp_path, protocol, "--fault", fault, "--fault-after", "1")
    try:
        async def scenario() -> None:
            async with _backend(protocol, sim.port) as backend:
                first = _flange(0.6, 0.0, 0.3)
                np.testing.assert_allclose(await backend.move(first, lambda pose, moving: None), first, atol=1e-6)
                with pytest.raises(error):
                    await backend.move(_flange(0.6, 0.2, 0.3), lambda pose, moving: None)
                sim.process.send_signal(signal.SIGUSR1)  # as the fault acknowledged and the program restarted
                await asyncio.sleep(0.5)
                second = _flange(0.6, 0.2, 0.3)
                np.testing.assert_allclose(await backend.move(second, lambda pose, moving: None), second, atol=1e-6)

        _run(scenario())
    finally:
        log = sim.close()
    assert "Traceback" not in log, log


def test_a_dropped_link_is_a_connection_error(tmp_path):
    sim = SimKukaProcess(tmp_path, "kvp", "--fault", "drop", "--fault-after", "1")
    try:
        async def scenario() -> None:
            async with _backend("kvp", sim.port) as backend:
                await backend.move(_flange(0.6, 0.0, 0.3), lambda pose, moving: None)
                with pytest.raises(KukaConnectionError):
                    await backend.move(_flange(0.6, 0.2, 0.3), lambda pose, moving: None)

        _run(scenario())
    finally:
        sim.close()


def test_fault_after_without_a_fault_is_refused(capsys):
    from robocell.cli.main import main

    assert main(["sim", "kuka", "--fault-after", "2"]) == 2
    assert capsys.readouterr().err == "robocell sim kuka: --fault-after goes with --fault\n"
