"""Ctrl-C, as a terminal sends it, at several moments of `demo`, `up`, `cell`, `scan` and `replay`.

Each command runs in a session of its own, as a shell runs a foreground job, and gets SIGINT
sent to its whole process group (what a terminal's Ctrl-C does). Afterwards no process it
started may be left (each carries a tag in its environment, which its children inherit: a
process left behind is found by it even once it has a new parent), and nothing it printed may
be a traceback. On `scan`, the job must be cancelled in the cell.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest

from tests.cell_fixtures import cell_config, free_port, running_cell, wait_until
from robocell.wire.messages import JobState
from robocell.workers.sim.scene import target_from_config

#: Long enough for a loaded machine to start a cell; a test fails here instead of hanging.
START_S = 90.0
EXIT_S = 60.0


class Foreground:
    """A robocell command run as a shell's foreground job, its output gathered as it comes."""

    def __init__(self, argv: list[str], *, cwd: Path, sigint_ignored: bool = False) -> None:
        """``sigint_ignored``: the command starts with SIGINT ignored, as a script's background job does."""
        self.tag = uuid.uuid4().hex
        env = {**os.environ, "ROBOCELL_TEST_TAG": self.tag}
        ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sigint_ignored else None
        self.process = subprocess.Popen([sys.executable, "-m", "robocell", *argv], cwd=cwd, env=env,
                                        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        start_new_session=True, preexec_fn=ignore)
        self._lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in iter(self.process.stdout.readline, b""):
            self._lines.append(line.decode(errors="replace"))

    @property
    def output(self) -> str:
        return "".join(self._lines)

    def wait_for(self, pattern: str, timeout: float = START_S) -> re.Match:
        return wait_until(lambda: re.search(pattern, self.output) or self._exited_early(pattern),
                          timeout=timeout, interval=0.05, what=f"{pattern!r} in the output of {self.process.args}")

    def _exited_early(self, pattern: str):
        if self.process.poll() is not None:
            time.sleep(0.2)  # the last lines
            match = re.search(pattern, self.output)
            if match:
                return match
            raise AssertionError(f"exited with {self.process.returncode} before {pattern!r}:\n{self.output}")
        return None

    def ctrl_c(self) -> None:
        os.killpg(self.process.pid, signal.SIGINT)

    def finish(self) -> int:
        status = self.process.wait(timeout=EXIT_S)
        self._reader.join(timeout=10)
        return status

    def left_behind(self) -> list[str]:
        """The processes this command started that still run (zombies aside), as pid and command line."""
        needle = f"ROBOCELL_TEST_TAG={self.tag}".encode()
        found = []
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                if needle in (entry / "environ").read_bytes().split(b"\0") and \
                        (entry / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                    command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                    found.append(f"{entry.name} {command}")
            except OSError:
                continue
        return found

    def close(self) -> None:
        """Kill whatever is left (after a failed test), then check nothing was."""
        for line in self.left_behind():
            try:
                os.kill(int(line.split()[0]), signal.SIGKILL)
            except ProcessLookupError:
                pass
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=30)
        self._reader.join(timeout=10)
        assert self.process.stdout is not None
        self.process.stdout.close()


def _no_traceback_and_nothing_left(command: Foreground) -> None:
    assert "Traceback" not in command.output, command.output
    # Children get their SIGTERM and time-limited waits before the parent exits: none should remain.
    wait_until(lambda: not command.left_behind(), timeout=15, what="the command's processes to end")


def _cell_toml(tmp_path: Path) -> Path:
    """A cell on free loopback ports, its robot moving at 0.2 m/s."""
    path = tmp_path / "cell.toml"
    text = [f'run_dir = "{tmp_path / "runs"}"', "[zenoh]", f'router = "tcp/127.0.0.1:{free_port()}"',
            "[camera]", f'url = "http://127.0.0.1:{free_port()}"', "[robot]", "speed = 0.2"]
    path.write_text("\n".join(text) + "\n")
    return path


@pytest.fixture
def foreground(tmp_path):
    started: list[Foreground] = []

    def start(*argv: str, sigint_ignored: bool = False) -> Foreground:
        command = Foreground(list(argv), cwd=tmp_path, sigint_ignored=sigint_ignored)
        started.append(command)
        return command

    yield start
    for command in started:
        command.close()


# --- demo and up: every process they started ends ------------------------------------------------

@pytest.mark.parametrize("moment", ["starting", "scanning", "after the result"])
def test_ctrl_c_in_demo_ends_every_process(foreground, tmp_path, moment):
    demo = foreground("demo", "--run-dir", str(tmp_path / "demo"))
    pattern = {"starting": r"starting a simulated cell", "scanning": r"moving\s+moving to view 1",
               "after the result": r"succeeded\s+reconstructed"}[moment]
    demo.wait_for(pattern)
    if moment == "starting":
        time.sleep(1.0)  # its children are being started
    demo.ctrl_c()
    status = demo.finish()
    _no_traceback_and_nothing_left(demo)
    if moment == "after the result":
        assert status in (0, 130), demo.output   # it may have printed its result before it heard
    else:
        assert status == 130, demo.output
        assert "interrupted: stopping the simulated cell" in demo.output
    if moment == "scanning":
        assert re.search(r"job \S+ cancelled", demo.output), demo.output


@pytest.mark.parametrize("moment", ["starting", "up"])
def test_ctrl_c_in_up_ends_every_process(foreground, tmp_path, moment):
    up = foreground("--config", str(_cell_toml(tmp_path)), "up")
    up.wait_for("starting daemon" if moment == "starting" else r"cell \S+ is up")
    if moment == "starting":
        time.sleep(1.0)
    up.ctrl_c()
    assert up.finish() == 0, up.output
    _no_traceback_and_nothing_left(up)


def test_twice_ctrl_c_in_up_still_stops_all(foreground, tmp_path):
    up = foreground("--config", str(_cell_toml(tmp_path)), "up")
    up.wait_for(r"cell \S+ is up")
    up.ctrl_c()
    time.sleep(0.1)
    up.ctrl_c()
    assert up.finish() == 0, up.output
    _no_traceback_and_nothing_left(up)


def test_ctrl_c_on_a_foreground_cell_daemon(foreground, tmp_path):
    config = _cell_toml(tmp_path)
    router = foreground("--config", str(config), "router")
    router.wait_for("router listening")
    cell = foreground("--config", str(config), "cell")
    cell.wait_for(r"cell \S+ ready")
    time.sleep(1.0)  # the recorder process is up by now
    cell.ctrl_c()
    router.ctrl_c()
    assert cell.finish() == 0, cell.output
    assert router.finish() == 0, router.output
    _no_traceback_and_nothing_left(cell)
    _no_traceback_and_nothing_left(router)


def test_ctrl_c_on_replay_web_ends_the_viewer(foreground, tmp_path):
    from robocell.cell.recording import JobRecording

    run_dir = tmp_path / "runs"
    with JobRecording(run_dir / "j1.rrd", "j1") as recording:
        recording.log_text("moving")
    config = tmp_path / "replay.toml"
    config.write_text(f"run_dir = '{run_dir}'\n")
    # Started with SIGINT ignored, as a script's background job is (CI's, once): Python then installs no
    # Ctrl-C handler of its own, and the command once went on serving for good.
    replay = foreground("--config", str(config), "replay", "j1", "--web", "--web-port", str(free_port()),
                        "--grpc-port", str(free_port()), sigint_ignored=True)
    replay.wait_for("serving")
    wait_until(lambda: len(replay.left_behind()) >= 2, timeout=30, what="the viewer to start")
    replay.ctrl_c()
    assert replay.finish() == 0, replay.output
    _no_traceback_and_nothing_left(replay)


# --- scan: Ctrl-C cancels the job ----------------------------------------------------------------

@pytest.fixture(scope="module")
def slow_cell(tmp_path_factory):
    """A cell whose robot takes seconds per move: a scan is caught moving."""
    config = cell_config(tmp_path_factory.mktemp("slow"), robot={"speed": 0.05})
    with running_cell(config) as cell:
        yield cell


def _scan(foreground, cell) -> Foreground:
    return foreground("--config", str(cell.processes.config_path), "scan",
                      "--target", *map(str, target_from_config(cell.config.sim)))


def test_ctrl_c_on_scan_cancels_the_job(foreground, slow_cell):
    scan = _scan(foreground, slow_cell)
    job_id = scan.wait_for(r"job (\S+) queued").group(1)
    scan.wait_for(r"moving\s+moving to view 0")
    scan.ctrl_c()
    assert scan.finish() == 130, scan.output
    assert f"Ctrl-C: cancelling job {job_id}" in scan.output
    assert f"job {job_id} cancelled" in scan.output
    assert slow_cell.client.status(job_id).state is JobState.CANCELLED
    _no_traceback_and_nothing_left(scan)


def test_ctrl_c_twice_on_scan_leaves_the_job_and_says_how_to_cancel_it(foreground, slow_cell):
    scan = _scan(foreground, slow_cell)
    job_id = scan.wait_for(r"job (\S+) queued").group(1)
    scan.wait_for(r"moving\s+moving to view 0")
    # The daemon, frozen for a moment, cannot answer the cancel before the second Ctrl-C.
    daemon = slow_cell.processes.child("daemon").process.pid
    os.kill(daemon, signal.SIGSTOP)
    try:
        scan.ctrl_c()
        scan.wait_for(r"Ctrl-C: cancelling", timeout=10)
        scan.ctrl_c()
        assert scan.finish() == 130, scan.output
    finally:
        os.kill(daemon, signal.SIGCONT)
    assert f"robocell cancel {job_id}" in scan.output and "no longer watches it" in scan.output
    assert "Traceback" not in scan.output
    # The first Ctrl-C's cancel had been sent: the daemon, woken, still cancels the job.
    assert slow_cell.wait(job_id).state is JobState.CANCELLED
