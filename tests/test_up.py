"""``robocell up``: the whole cell from one command, and Ctrl-C stops every part of it.

The command runs as a user runs it, a process of its own; its parts are found
among this machine's processes by the configuration file on their command line
(``up`` writes the one they share into the run directory).
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from robocell.cli.up import CellProcesses
from robocell.wire.client import CellClient
from robocell.wire.config import CellConfig
from robocell.wire.messages import JobState, ScanRequest
from robocell.workers.sim.scene import target_from_config

from tests.cell_fixtures import START_TIMEOUT_S, accepts, cell_config, free_port, wait_until

PARTS = {"router", "worker robot", "sim camera", "worker camera", "worker reconstruct", "cell"}


def _live_processes() -> Iterator[tuple[int, int, int, list[str]]]:
    """(pid, parent pid, process group, argv) of every live process on this machine."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().decode(errors="replace").split("\0")
            state, ppid, pgrp = (entry / "stat").read_text().rsplit(")", 1)[1].split()[:3]
        except (OSError, ValueError):  # gone meanwhile
            continue
        if state != "Z":
            yield int(entry.name), int(ppid), int(pgrp), argv


def _parts(config_path: Path, parent: int | None = None) -> dict[str, int]:
    """The live processes started with ``--config config_path`` (children of ``parent`` only, if
    given): what each runs, and its pid."""
    found = {}
    for pid, ppid, _, argv in _live_processes():
        if str(config_path) not in argv or (parent is not None and ppid != parent):
            continue
        after = argv[argv.index(str(config_path)) + 1:]
        found[" ".join(after[:2]) if after[0] in ("worker", "sim") else after[0]] = pid
    return found


def _lines_until(process: subprocess.Popen, end: str, timeout: float) -> list[str]:
    """What the process prints up to the line that holds ``end``, waited for no longer than ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    lines: list[str] = []
    while not lines or end not in lines[-1]:
        ready, _, _ = select.select([process.stdout], [], [], max(0.0, deadline - time.monotonic()))
        assert ready, f"not printed in {timeout:g} s: {end!r}; printed: {lines}"
        lines.append(process.stdout.readline())
        assert lines[-1], f"{lines[:-1]}; then it ended: {process.stderr.read()}"
    return lines


def _in_groups(groups: set[int]) -> list[int]:
    """Live processes in any of these process groups (a part's own children: recorder, pool)."""
    return [pid for pid, _, pgrp, _ in _live_processes() if pgrp in groups]


@contextlib.contextmanager
def _up(config: CellConfig, config_path: Path) -> Iterator[subprocess.Popen]:
    """`robocell up` with this configuration; whatever is left of it is killed at the end."""
    config_path.write_text(config.model_dump_json())
    process = subprocess.Popen([sys.executable, "-m", "robocell", "--config", str(config_path), "up"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate(timeout=30)
        for pid in _parts(Path(config.run_dir) / "cell-config.json").values():  # what a failure left
            with contextlib.suppress(ProcessLookupError):
                os.killpg(os.getpgid(pid), signal.SIGKILL)


@pytest.fixture
def up(tmp_path):
    config = cell_config(tmp_path / "run")
    with _up(config, tmp_path / "cell.json") as process:
        yield config, Path(config.run_dir) / "cell-config.json", process


def test_up_runs_the_cell_and_ctrl_c_stops_every_part(up):
    config, config_path, process = up
    lines = _lines_until(process, f"cell {config.cell_id} is up", START_TIMEOUT_S)
    assert lines[:-1] == [f"starting {part}\n" for part in (
        f"router on {config.zenoh.router}", "robot worker (sim robot)", f"simulated Axis camera at {config.camera.url}",
        f"camera worker (Axis camera at {config.camera.url})")] + lines[4:5] + [f"starting daemon of cell {config.cell_id}\n"]
    assert lines[4].startswith(f"starting reconstruction worker {config.cell_id}-r0-")
    parts = _parts(config_path, parent=process.pid)
    assert set(parts) == PARTS
    with CellClient(config.zenoh.router, config.cell_id) as client:
        result = client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=60)
        assert client.status(result.job_id).state is JobState.SUCCEEDED

    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr
    assert _parts(config_path) == {}
    assert _in_groups(set(parts.values())) == []


def test_ctrl_c_while_the_cell_starts_stops_it_at_once(up):
    """A part that never gets ready (here: the daemon, frozen) would keep ``up`` waiting for its
    60 s start-up limit; Ctrl-C must not wait for that."""
    config, config_path, process = up
    daemon = wait_until(lambda: _parts(config_path, parent=process.pid).get("cell"), timeout=START_TIMEOUT_S,
                        interval=0.002, what="the daemon's process")
    os.kill(daemon, signal.SIGSTOP)
    started = set(_parts(config_path, parent=process.pid).values())
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=30)  # well inside the 60 s start-up limit
    assert process.returncode == 0, stderr
    assert "is up" not in stdout and "stopped while starting" in stderr
    assert _parts(config_path) == {}
    assert _in_groups(started) == []


@pytest.fixture
def simulated_kuka(tmp_path):
    """`robocell sim kuka` (KukaVarProxy) on a free port, fast."""
    port = free_port()
    process = subprocess.Popen([sys.executable, "-m", "robocell", "sim", "kuka", "--port", str(port), "--speed",
                                "10000", "--rotation-speed", "3000"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        # Listening before the cell starts: its robot worker connects once, and stops if nobody answers.
        wait_until(lambda: accepts("127.0.0.1", port), timeout=START_TIMEOUT_S, interval=0.1, what="the simulated KUKA controller")
        yield port
    finally:
        process.terminate()
        process.communicate(timeout=30)


def test_up_with_a_kuka_robot_starts_the_simulated_camera_its_configuration_needs(simulated_kuka, tmp_path):
    """The camera at a loopback address can only be the simulated one, whatever the robot."""
    config = cell_config(tmp_path / "run", robot={"backend": "kuka", "kuka": {"port": simulated_kuka}})
    with _up(config, tmp_path / "cell.json") as process:
        lines = _lines_until(process, f"cell {config.cell_id} is up", START_TIMEOUT_S)
        assert f"starting robot worker (kuka over kvp at 127.0.0.1:{simulated_kuka})\n" in lines
        assert f"starting simulated Axis camera at {config.camera.url}\n" in lines  # and it was listening: "is up"
        assert "sim camera" in _parts(Path(config.run_dir) / "cell-config.json", parent=process.pid)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
        assert process.returncode == 0, stderr


@pytest.mark.parametrize("camera, simulated", [
    ({"url": "http://127.0.0.1:8080"}, True),
    ({"url": "http://localhost:8080"}, True),
    ({"url": "http://[::1]:8080"}, True),
    ({"url": "http://192.0.2.90"}, False),        # a real camera on the network
    ({"url": "http://camera.lab"}, False),
    ({"backend": "sim"}, False),                  # the camera worker renders the scene itself
])
def test_up_starts_the_simulated_axis_camera_only_for_an_axis_camera_on_loopback(tmp_path, camera, simulated):
    config = CellConfig.model_validate({"run_dir": str(tmp_path), "camera": camera,
                                        "robot": {"backend": "kuka"}})
    described = CellProcesses(config).describe()
    assert any(part.startswith("simulated Axis camera at ") for part in described) is simulated
    assert "camera worker (" in " ".join(described)
