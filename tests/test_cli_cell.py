"""The client commands (`robocell jobs`, `scan`, `status`, ...) as a user runs them, against a real Zenoh router.

A stand-in daemon answers the documented keys of cell "bay" with made-up jobs;
cell "empty" has no daemon at all.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from robocell.cli.main import main
from robocell.wire import keys
from robocell.wire.messages import JobState, JobStatus, ScanRequest
from robocell.wire.transport import Response, Transport

from tests.cell_fixtures import LoopThread, free_port

JOBS = 2000  # their listing is larger than a pipe's buffer: a reader that stops early is noticed


def _jobs() -> str:
    request = ScanRequest(target=[0.6, 0.0, 0.05], label="made up")
    now = time.time()
    return json.dumps([JobStatus(job_id=f"j{i:05d}", state=JobState.SUCCEEDED, n_views=3, created=now, updated=now,
                                 request=request).model_dump(mode="json") for i in range(JOBS)])


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    """A router on a free port, with the stand-in daemon of cell "bay" in the same session."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    listing = _jobs()
    loop = LoopThread()

    async def start() -> Transport:
        transport = await Transport.open(endpoint, mode="router")

        async def on_jobs(request):
            return Response(listing)

        transport.serve(keys.jobs("bay"), on_jobs)
        return transport

    transport = loop.run(start())
    try:
        yield endpoint
    finally:
        loop.run(transport.close())
        loop.close()


def _config(tmp_path: Path, router: str, cell: str) -> Path:
    path = tmp_path / f"{cell}.toml"
    path.write_text(f'cell_id = "{cell}"\n[zenoh]\nrouter = "{router}"\n')
    return path


def test_jobs_into_a_reader_that_stops_early_says_nothing(router, tmp_path):
    """`robocell jobs | head -1`."""
    process = subprocess.Popen([sys.executable, "-m", "robocell", "--config", _config(tmp_path, router, "bay"),
                                "jobs", "--limit", str(JOBS)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().startswith(b"j00000  ")
        process.stdout.close()  # as head does, once it has its line
        stderr = process.stderr.read().decode()
        process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(timeout=30)
        process.stderr.close()
    assert stderr == ""
    assert process.returncode == 141  # as a shell reports a program ended by SIGPIPE


@pytest.mark.parametrize("argv", [["jobs"], ["status"], ["job", "j1"], ["cancel", "j1"],
                                  ["scan", "--target", "0.6", "0", "0.05"]])
def test_a_cell_without_a_daemon_is_named(router, tmp_path, argv, capsys):
    assert main(["--config", str(_config(tmp_path, router, "empty")), *argv]) == 1
    assert capsys.readouterr().err == f"robocell {argv[0]}: no cell daemon is running for cell empty at {router}\n"
