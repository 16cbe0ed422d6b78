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
from collections.abc import Iterator
from pathlib import Path

import pytest

from wire.client import CellClient
from wire.messages import JobState, ScanRequest
from workers.sim.scene import target_from_config

from tests.cell_fixtures import START_TIMEOUT_S, cell_config, wait_until

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


def _first_line(process: subprocess.Popen, timeout: float) -> str:
    """The first line the process prints, waited for no longer than ``timeout`` seconds."""
    ready, _, _ = select.select([process.stdout], [], [], timeout)
    assert ready, f"nothing printed in {timeout:g} s"
    return process.stdout.readline()


def _in_groups(groups: set[int]) -> list[int]:
    """Live processes in any of these process groups (a part's own children: recorder, pool)."""
    return [pid for pid, _, pgrp, _ in _live_processes() if pgrp in groups]


@pytest.fixture
def up(tmp_path):
    config = cell_config(tmp_path / "run")
    config_path = tmp_path / "cell.json"
    config_path.write_text(config.model_dump_json())
    process = subprocess.Popen([sys.executable, "-m", "robocell", "--config", str(config_path), "up"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield config, Path(config.run_dir) / "cell-config.json", process
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate(timeout=30)
        for pid in _parts(Path(config.run_dir) / "cell-config.json").values():  # what a failure left
            with contextlib.suppress(ProcessLookupError):
                os.killpg(os.getpgid(pid), signal.SIGKILL)


def test_up_runs_the_cell_and_ctrl_c_stops_every_part(up):
    config, config_path, process = up
    line = _first_line(process, START_TIMEOUT_S)
    assert f"cell {config.cell_id} is up" in line, process.stderr.read() if process.poll() is not None else line
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
