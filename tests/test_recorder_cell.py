"""A cell's recordings as its clients see them (issue 23): a job whose recording was lost, with its
recorder process killed mid-job or on a device that refuses every write, says so in its result's
``recording_error``; the next job is recorded again. The daemon is the real one, in this process,
with stand-in workers (``tests.test_cell_inprocess``); recordings are read back with Rerun's reader."""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import os
import signal
import socket
import subprocess
import warnings
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

from robocell.cell.daemon import CellDaemon
from robocell.cell.recording_files import rerun_executable
from robocell.wire import keys
from robocell.wire.client import AsyncCellClient
from robocell.wire.messages import (POINTS_ENCODING, Blob, JobState, Reconstruction, ReconstructReply, ReconstructRequest,
                           ScanRequest, Superquadric)
from robocell.workers.reconstruct.worker import ReconstructWorker
from robocell.workers.sim.scene import target_from_config

from robocell.wire.fake_transport import MemoryNetwork

from tests.cell_fixtures import accepts
from tests.test_cell_inprocess import STAND_IN_SIZE, Workers, _config, daemon

LIMIT_S = 240.0  # a whole scenario, on a busy machine


def _recorders() -> list[multiprocessing.process.BaseProcess]:
    return [process for process in multiprocessing.active_children() if process.name == "robocell-recorder"]


def _entities(path: str | Path) -> set[str]:
    """The entity paths of a complete recording (no footer, or a bad one, fails)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return {chunk.entity_path for chunk in RrdReader(str(path)).stream()}


async def _gated_reconstructor(workers: Workers, worker_id: str, gate: asyncio.Event) -> ReconstructWorker:
    """A stand-in reconstruction worker that answers once ``gate`` is set."""
    config = workers.config
    target = target_from_config(config.sim)

    async def run(request_json: str, payload: bytes) -> tuple[str, bytes]:
        request = ReconstructRequest.model_validate_json(request_json)
        workers.answered.append(worker_id)
        await gate.wait()
        T = np.eye(4)
        T[:3, 3] = target
        result = Reconstruction(superquadric=Superquadric(size=list(STAND_IN_SIZE), shape=[1.0, 1.0],
                                                          T_world_object=T.tolist()),
                                silhouette_iou=[0.9] * len(request.views), residual=0.001,
                                timings_ms={"total": 1.0}, centre=list(target), radius=0.05)
        return ReconstructReply(job_id=request.job_id, result=result, worker=worker_id, ticket=request.ticket,
                                points=Blob(encoding=POINTS_ENCODING, length=0)).model_dump_json(), b""

    worker = ReconstructWorker(workers.network.session(), worker_id, 1, run, period_s=0.1)
    await worker.start()
    workers.reconstructors[worker_id] = worker
    return worker


def test_a_recorder_killed_mid_job_is_named_in_the_result_and_the_next_job_is_recorded(tmp_path):
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        gate = asyncio.Event()
        await _gated_reconstructor(workers, "gated", gate)
        try:
            async with daemon(network, config) as client:
                status = await client.submit(ScanRequest(target=target_from_config(config.sim)))
                path = config.run_dir / f"{status.job_id}.rrd"
                async with asyncio.timeout(60):  # three views taken, the reconstruction held
                    while not workers.answered or not path.exists() or path.stat().st_size == 0:
                        await asyncio.sleep(0.05)
                [recorder] = _recorders()
                os.kill(recorder.pid, signal.SIGKILL)
                gate.set()
                final = await client.wait(status.job_id, timeout=60)
                assert final.state is JobState.SUCCEEDED
                lost = await client.result(status.job_id)
                assert lost.recording is None
                assert lost.recording_error is not None and "killed by SIGKILL" in lost.recording_error
                assert str(path) in lost.recording_error

                result = await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=60)
                assert result.recording_error is None and result.recording is not None
                assert Path(result.recording).stat().st_size > 0
                entities = _entities(result.recording)
                assert {"/world/camera0/image", "/world/camera2/image", "/world/fit", "/log"} <= entities
                assert recorder.pid not in [process.pid for process in _recorders()]
        finally:
            await workers.close()

    asyncio.run(asyncio.wait_for(scenario(), LIMIT_S))


def test_a_recording_on_a_device_that_refuses_every_write_is_named_in_the_result(tmp_path):
    """The next job's recording is a link to /dev/full, which takes the file's opening and refuses
    every write, as a full disk does."""
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("w")
        try:
            async with daemon(network, config) as client:
                first = await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=60)
                assert first.recording_error is None
                day, number = first.job_id.split("-")
                upcoming = f"{day}-{int(number) + 1:06d}"
                full = config.run_dir / f"{upcoming}.rrd"
                full.symlink_to("/dev/full")
                result = await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=60)
                assert result.job_id == upcoming
                assert result.recording is None
                assert result.recording_error is not None and str(full) in result.recording_error
                assert "No space left on device" in result.recording_error
                assert (await client.status(upcoming)).recording is None
                again = await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=60)
                assert again.recording_error is None and "/world/fit" in _entities(again.recording)
        finally:
            await workers.close()

    asyncio.run(asyncio.wait_for(scenario(), LIMIT_S))


@contextlib.asynccontextmanager
async def _daemon_viewed(network: MemoryNetwork, config, view: str) -> AsyncIterator[AsyncCellClient]:
    """As ``tests.test_cell_inprocess.daemon``, the daemon streaming every job to ``view``."""
    stop = asyncio.Event()
    session = network.session()
    running = asyncio.create_task(CellDaemon(config, session, view=view).run(stop))
    client = AsyncCellClient(network.session(), config.cell_id, timeout=10.0)
    try:
        async with asyncio.timeout(60):
            while not await client._transport.alive(keys.alive(config.cell_id, "daemon")):
                assert not running.done(), running.exception()
                await asyncio.sleep(0.01)
        yield client
    finally:
        stop.set()
        await asyncio.wait_for(running, 60)
        await session.close()
        await client._transport.close()


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _received(path: Path, job_id: str) -> tuple[set[str], list[str]]:
    """What a viewer saved of job ``job_id``'s recording: its entity paths and its log lines."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a viewer's saved stream may end without a footer
        reader = RrdReader(str(path))
        [entry] = [entry for entry in reader.recordings() if entry.recording_id == job_id]
        entities, texts = set(), []
        for chunk in reader.stream(store=entry):
            entities.add(chunk.entity_path)
            if chunk.entity_path == "/log":
                texts += [text for [text] in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    return entities, texts


def test_a_live_viewer_receives_every_job_whole_beside_its_recording(tmp_path):
    """``robocell cell --view URL``: Rerun's own viewer, listening on a free port and saving what
    it receives, gets each job as it happens, as the job's file has it."""
    config = _config(tmp_path)
    port = _free_port()
    received = tmp_path / "viewer.rrd"
    viewer = subprocess.Popen([rerun_executable(), "--port", str(port), "--bind", "127.0.0.1", "--save",
                               str(received)], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)

    async def scenario() -> list:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("w")
        try:
            async with asyncio.timeout(60):
                while not accepts("127.0.0.1", port):
                    assert viewer.poll() is None, "the viewer exited"
                    await asyncio.sleep(0.05)
            async with _daemon_viewed(network, config, f"rerun+http://127.0.0.1:{port}/proxy") as client:
                return [await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=60)
                        for _ in range(2)]
        finally:
            await workers.close()

    try:
        results = asyncio.run(asyncio.wait_for(scenario(), LIMIT_S))
    finally:
        viewer.send_signal(signal.SIGINT)  # the viewer writes what it saved, and ends
        try:
            viewer.wait(30)
        except subprocess.TimeoutExpired:
            viewer.kill()
            viewer.wait()
    for result in results:
        assert result.recording_error is None
        entities, texts = _received(received, result.job_id)
        in_file = _entities(result.recording)
        assert {"/world/camera0/image", "/world/camera1/image", "/world/camera2/image", "/world/robot/flange",
                "/world/fit", "/log"} <= entities
        assert entities == in_file
        assert texts[-1].startswith("succeeded: ")
