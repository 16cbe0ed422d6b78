"""The daemon in the test's own process, on an in-memory network (``wire.fake_transport``), with
stand-in workers: what a real router cannot be made to do on cue (a store that refuses a success,
a plan that would grow without end, a worker frozen mid-job) in a second or so each.

The daemon is the real one (store, recorder, publisher, pool); the workers answer at once: the robot
goes where it is told, the camera gives a small grey JPEG, the reconstruction a small superquadric
on the target (a stand-in's answer, not a reconstruction), and, when asked, a next view it is never
sure of.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import time
from collections.abc import AsyncIterator
from pathlib import Path

import cv2
import numpy as np
import pytest

import robocell.cell.daemon
import robocell.cell.requests
from robocell.cell.daemon import CellDaemon
from robocell.cell.reserve import MIN_FREE_BYTES, RESERVE_BYTES, RESERVE_NAME
from robocell.cell.store import JobStore
from robocell.wire import keys
from robocell.wire.client import AsyncCellClient, JobFailed
from robocell.wire.errors import CellError, RemoteError, StoreError
from robocell.wire.fake_transport import MemoryNetwork
from robocell.wire.messages import (POINTS_ENCODING, Blob, CaptureInfo, JobEvent, JobState, Lifecycle, MoveReply,
                           MoveRequest, NextViewAnswer, PickRequest, Reconstruction, ReconstructReply, ReconstructRequest,
                           RobotState, ScanRequest, Superquadric)
from robocell.wire.transport import Request, Response
from robocell.workers.reconstruct.worker import ReconstructWorker
from robocell.workers.sim.scene import target_from_config

from tests.cell_fixtures import cell_config
from tests.helpers import tmpfs

LIMIT_S = 60.0


#: The stand-in reconstruction's model: an ellipsoid of these half-axes (metres) on the target.
STAND_IN_SIZE = (0.02, 0.02, 0.03)


def _jpeg(config, T_base_flange: np.ndarray) -> bytes:
    """What the camera sees from ``T_base_flange``: the stand-in's ellipsoid, red on grey, drawn here
    apart from the daemon's check (sampled surface, pinhole projection, convex outline)."""
    width, height = config.camera.resolution
    image = np.full((height, width, 3), 128, np.uint8)
    eta, omega = np.meshgrid(np.linspace(-np.pi / 2, np.pi / 2, 40), np.linspace(-np.pi, np.pi, 80))
    a, b, c = STAND_IN_SIZE
    surface = np.stack([a * np.cos(eta) * np.cos(omega), b * np.cos(eta) * np.sin(omega), c * np.sin(eta)], -1)
    points = surface.reshape(-1, 3) + np.asarray(target_from_config(config.sim))
    T_world_cam = T_base_flange @ np.asarray(config.T_flange_cam)
    in_camera = (points - T_world_cam[:3, 3]) @ T_world_cam[:3, :3]
    if (in_camera[:, 2] > 0).all():
        uv = in_camera @ np.asarray(config.camera.K).T
        outline = cv2.convexHull(np.round(uv[:, :2] / uv[:, 2:] * 16).astype(np.int32))
        cv2.fillConvexPoly(image, outline, (30, 30, 210), shift=4)
    return cv2.imencode(".jpg", image)[1].tobytes()


class Workers:
    """A robot, a camera and reconstruction workers on ``network``, answering at once."""

    def __init__(self, network: MemoryNetwork, config) -> None:
        self.network, self.config = network, config
        self.robot = network.session()
        self.pose = np.eye(4)
        self.reconstructors: dict[str, ReconstructWorker] = {}
        self.answered: list[str] = []
        self.moves: list[np.ndarray] = []
        cell_id = config.cell_id

        async def move(request: Request) -> Response:
            self.pose = np.asarray(MoveRequest.model_validate_json(request.payload).T_base_flange)
            self.moves.append(self.pose)
            return Response(MoveReply(T_base_flange=self.pose.tolist(), duration_s=0.0).model_dump_json())

        async def state(request: Request) -> Response:
            return Response(RobotState(T_base_flange=self.pose.tolist(), moving=False, time=0.0).model_dump_json())

        async def capture(request: Request) -> Response:
            width, height = config.camera.resolution
            info = CaptureInfo(width=width, height=height, source="stand-in", time=0.0, duration_s=0.0)
            return Response(_jpeg(config, self.pose), encoding="image/jpeg", attachment=info.model_dump_json())

        self.robot.serve(keys.robot_move(cell_id), move)
        self.robot.serve(keys.robot_state(cell_id), state)
        self.robot.serve(keys.camera_capture(cell_id), capture)
        self.robot.declare_token(keys.alive(cell_id, "robot"))
        self.robot.declare_token(keys.alive(cell_id, "camera"))

    async def reconstructor(self, worker_id: str, scale: float = 1.0) -> ReconstructWorker:
        """A stand-in reconstruction worker; ``scale`` > 1: a fake one, whose model is that much too big."""
        target = target_from_config(self.config.sim)

        async def run(request_json: str, payload: bytes) -> tuple[str, bytes]:
            request = ReconstructRequest.model_validate_json(request_json)
            self.answered.append(worker_id)
            T = np.eye(4)
            T[:3, 3] = target
            unsure = None
            if request.next_view is not None:
                unsure = NextViewAnswer(candidate=0, T_world_cam=request.next_view.candidates[0].T_world_cam,
                                        expected_gain=0.1, uncertainty=0.5, sure=False)
            result = Reconstruction(
                superquadric=Superquadric(size=[scale * a for a in STAND_IN_SIZE], shape=[1.0, 1.0], T_world_object=T.tolist()),
                silhouette_iou=[0.9] * len(request.views), residual=0.001, timings_ms={"total": 1.0},
                centre=list(target), radius=0.05, next_view=unsure)
            return ReconstructReply(job_id=request.job_id, result=result, worker=worker_id, ticket=request.ticket,
                                    points=Blob(encoding=POINTS_ENCODING, length=0)).model_dump_json(), b""

        worker = ReconstructWorker(self.network.session(), worker_id, 1, run, period_s=0.1)
        await worker.start()
        self.reconstructors[worker_id] = worker
        return worker

    async def close(self) -> None:
        for worker in self.reconstructors.values():
            await worker.close()
            await worker.transport.close()
        await self.robot.close()


@contextlib.asynccontextmanager
async def daemon(network: MemoryNetwork, config) -> AsyncIterator[AsyncCellClient]:
    stop = asyncio.Event()
    session = network.session()
    running = asyncio.create_task(CellDaemon(config, session).run(stop))
    client = AsyncCellClient(network.session(), config.cell_id, timeout=10.0)
    try:
        async with asyncio.timeout(30):
            while not await client._transport.alive(keys.alive(config.cell_id, "daemon")):
                assert not running.done(), running.exception()
                await asyncio.sleep(0.01)
        yield client
    finally:
        stop.set()
        await asyncio.wait_for(running, 30)
        await session.close()  # as the daemon's service does: its token and queryables go
        await client._transport.close()


def _config(tmp_path, **fields):
    return cell_config(tmp_path, cell_id="inprocess", timeouts={"heartbeat_s": 0.5, "outage_s": 2.0}, **fields)


def _run(coroutine) -> None:
    asyncio.run(asyncio.wait_for(coroutine, LIMIT_S))


def test_a_plan_that_would_grow_past_its_cap_ends_with_what_it_has_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setattr(robocell.cell.daemon, "MAX_PLAN_STEPS", 6)  # 3 views and a reconstruction, then one more view
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("never-sure")
        try:
            async with daemon(network, config) as client:
                request = ScanRequest(target=target_from_config(config.sim), views="adaptive", max_views=16)
                result = await client.scan(request, timeout=30)
                assert len(result.T_base_cam) == 4 and result.uncertainty == 0.5
                messages = [e.message for e in await _events(config, result.job_id)]
                assert "reconstructing asked for 2 more steps, past the plan's cap of 6: the job ends with what " \
                       "it has" in messages
        finally:
            await workers.close()

    _run(scenario())


async def _events(config, job_id: str) -> list[JobEvent]:
    with JobStore(config.run_dir / "jobs.sqlite") as store:
        return store.events(job_id)


def test_a_success_the_store_refuses_is_told_to_nobody_and_the_restart_carries_the_job_on(tmp_path, monkeypatch):
    config = _config(tmp_path)
    change = JobStore.change

    def full_disk_at_the_success(store, event, **fields):
        if event.lifecycle is Lifecycle.SUCCEEDED:
            raise StoreError(f"job store {store.path}: database or disk is full")
        return change(store, event, **fields)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("w")
        try:
            monkeypatch.setattr(JobStore, "change", full_disk_at_the_success)
            async with daemon(network, config) as client:
                client.listen()
                status = await client.submit(ScanRequest(target=target_from_config(config.sim)))
                heard: list[JobEvent] = []
                async with asyncio.timeout(20):
                    async for event in client.events(status.job_id):
                        heard.append(event)
                        if event.state is JobState.RECONSTRUCTING:
                            break
                    while workers.answered != ["w"]:
                        await asyncio.sleep(0.01)
                await asyncio.sleep(0.5)  # the success the store refused: nothing more is told
                assert (await client.status(status.job_id)).state is JobState.RECONSTRUCTING
            assert not any(e.lifecycle.finished for e in heard)
            monkeypatch.setattr(JobStore, "change", change)  # the disk has room again
            async with daemon(network, config) as client:
                final = await client.wait(status.job_id, timeout=20)
                assert final.state is JobState.SUCCEEDED
                assert len((await client.result(status.job_id)).T_base_cam) == 3
            states = [e.state for e in await _events(config, status.job_id)]
            assert states.count(JobState.SUCCEEDED) == 1 and states.count(JobState.CAPTURING) == 3
            assert workers.answered == ["w", "w"]  # reconstructed again from the pictures kept, none taken again
        finally:
            await workers.close()

    _run(scenario())


def test_a_change_the_store_cannot_take_holds_the_job_until_the_disk_has_room_then_it_carries_on(tmp_path,
                                                                                                 monkeypatch):
    """Issue 23: a full disk mid-job neither ends the job untold nor leaves it to nothing (a phantom
    until a restart): the job waits, nobody hears of the change, and it goes on by itself."""
    config = _config(tmp_path)
    change, keep_picture = JobStore.change, JobStore.keep_picture
    full = {"disk": True}
    refused: list[str] = []

    def full_disk_from_view_1(store, event, **fields):
        if full["disk"] and event.view == 1 and event.state is JobState.CAPTURING:
            refused.append(event.message)
            raise StoreError(f"job store {store.path}: database or disk is full")
        return change(store, event, **fields)

    def no_room_for_pictures(store, job_id, view, jpeg, poses):
        if full["disk"]:
            raise StoreError(f"job store {store.path}: database or disk is full")
        return keep_picture(store, job_id, view, jpeg, poses)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("w")
        monkeypatch.setattr(JobStore, "change", full_disk_from_view_1)
        monkeypatch.setattr(JobStore, "keep_picture", no_room_for_pictures)
        try:
            async with daemon(network, config) as client:
                client.listen()
                status = await client.submit(ScanRequest(target=target_from_config(config.sim)))
                async with asyncio.timeout(20):
                    while len(refused) < 2:  # tried, and tried again
                        await asyncio.sleep(0.01)
                held = await client.status(status.job_id)
                assert held.state is JobState.MOVING and held.view == 1 and not held.state.finished
                full["disk"] = False   # room again: the same daemon carries the job on, no restart
                final = await client.wait(status.job_id, timeout=20)
                assert final.state is JobState.SUCCEEDED
                assert len((await client.result(status.job_id)).T_base_cam) == 3
            states = [(e.state, e.view) for e in await _events(config, status.job_id)]
            assert states.count((JobState.CAPTURING, 1)) == 1 and states.count((JobState.SUCCEEDED, None)) == 1
            assert workers.answered == ["w"]
        finally:
            await workers.close()

    _run(scenario())


def _fill(disk: Path) -> Path:
    """Write a file on ``disk`` until it has no room left; the file."""
    filler = disk / "filler"
    with open(filler, "wb", buffering=0) as file:
        for chunk in (1 << 20, 1 << 12, 1):
            try:
                while True:
                    file.write(bytes(chunk))
            except OSError:  # no room for one more of this size: try smaller ones
                pass
    return filler


def test_a_daemon_on_a_full_disk_starts_refuses_new_jobs_saying_why_and_takes_them_again_once_there_is_room(
        tmp_path):
    """Issue 23: a daemon whose disk something else filled could not open its store, and under systemd
    restarted for ever. It gives back the room it kept (cell.reserve), starts, says so, and resumes."""
    with tmpfs(tmp_path, "24m") as disk:
        config = _config(disk / "run", retention={"interval_s": 0.2})  # the upkeep keeps the reserve
        reserve = config.run_dir / RESERVE_NAME

        async def reserve_kept() -> None:
            async with asyncio.timeout(20):
                while not (reserve.exists() and reserve.stat().st_size == RESERVE_BYTES):
                    await asyncio.sleep(0.05)

        async def scenario() -> None:
            network = MemoryNetwork()
            workers = Workers(network, config)
            await workers.reconstructor("w")
            request = ScanRequest(target=target_from_config(config.sim))
            try:
                async with daemon(network, config) as client:   # room: the daemon makes its reserve
                    await reserve_kept()
                    await client.scan(request, timeout=30)
                filler = _fill(disk)
                assert shutil.disk_usage(disk).free < 4096
                async with daemon(network, config) as client:   # it starts
                    status = await client.cell_status()
                    assert status.disk is not None and status.disk.free_on_disk is not None
                    assert status.disk.free_on_disk < MIN_FREE_BYTES
                    with pytest.raises(RemoteError, match=r"^the cell's disk is full: \d+\.\d MB free where "
                                                          r".*: no new job until there is room$"):
                        await client.submit(request)
                    filler.unlink()   # room again: the same daemon takes jobs
                    result = await client.scan(request, timeout=30)
                    assert len(result.T_base_cam) == 3
                    await reserve_kept()   # and keeps its reserve again
            finally:
                await workers.close()

        _run(scenario())


def test_a_worker_frozen_mid_job_loses_it_to_another_and_the_job_succeeds(tmp_path):
    config = _config(tmp_path, reconstruct={"max_attempts": 2})

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        frozen = await workers.reconstructor("frozen")
        network.freeze(frozen.transport)  # its heartbeats stop; its token stays
        async with daemon(network, config) as client:
            await asyncio.sleep(0.05)
            other = await workers.reconstructor("other")
            result = await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=30)
            messages = [e.message for e in await _events(config, result.job_id)]
        network.thaw(frozen.transport)
        await workers.close()
        assert other is not None
        assert result.worker == "other"
        if result.attempts == 2:  # it went to the frozen one first
            assert any(m.startswith("attempt 1 on frozen: no heartbeat") for m in messages), messages

    _run(scenario())


@pytest.mark.parametrize("job_ends_meanwhile", [False, True], ids=["job running", "job ends meanwhile"])
def test_a_wait_while_the_client_s_link_is_down_waits_for_it_and_the_job(tmp_path, job_ends_meanwhile):
    """A program waits on a job just after the router restarted, before its own link is back: the wait asked
    the job's status first, and that raised LinkDown (seen in CI: a job queued across a router restart). Or
    the job's end reaches the waiting program while its link is down, so that the daemon cannot confirm it
    yet: that raised LinkDown too (seen in CI on a busy machine, where the job ended within the half second
    the link was down). The job goes on without the client; the wait goes on until the link is back, and
    returns the job's end."""
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("r1")
        async with daemon(network, config) as client:
            status = await client.submit(ScanRequest(target=target_from_config(config.sim)))
            if job_ends_meanwhile:
                waiting = asyncio.create_task(client.wait(status.job_id, timeout=60, poll_s=0.1))
                await asyncio.sleep(0)
                client._transport.set_link(False)
                for _ in range(300):  # bounded: the job ends within seconds
                    if any(event.state.finished for event in await _events(config, status.job_id)):
                        break
                    await asyncio.sleep(0.1)
                else:
                    raise AssertionError("the job did not end")
            else:
                client._transport.set_link(False)
                waiting = asyncio.create_task(client.wait(status.job_id, timeout=30, poll_s=0.1))
            await asyncio.sleep(0.5)
            assert not waiting.done(), waiting.exception()
            client._transport.set_link(True)
            final = await waiting
        await workers.close()
        assert final.state is JobState.SUCCEEDED, final

    _run(scenario())


@pytest.mark.parametrize("end", ["cancelled"])
def test_a_cancel_reaches_the_store_before_anyone_hears_of_it(tmp_path, end):
    """Whoever hears of an end and asks the store finds it there."""
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        try:
            async with daemon(network, config) as client:  # no reconstruction worker: the job waits for one
                client.listen()
                status = await client.submit(ScanRequest(target=target_from_config(config.sim)))
                async with asyncio.timeout(20):
                    async for event in client.events(status.job_id):
                        if event.state is JobState.RECONSTRUCTING:
                            await client.cancel(status.job_id)
                        if event.lifecycle.finished:
                            assert event.state.value == end
                            with JobStore(config.run_dir / "jobs.sqlite") as store:
                                assert store.get(status.job_id).state.value == end
                            break
        finally:
            await workers.close()

    _run(scenario())


def test_a_fake_workers_oversized_model_is_refused_and_the_job_succeeds_on_the_real_one(tmp_path):
    """No worker is trusted with the robot: a model 9 times too big disagrees with the daemon's own
    pictures, is never stored nor used, and the job goes to another worker."""
    config = _config(tmp_path, reconstruct={"max_attempts": 2})

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("fake", scale=9.0)
        async with daemon(network, config) as client:
            submitted = asyncio.create_task(client.scan(ScanRequest(target=target_from_config(config.sim)),
                                                        timeout=30))
            for _ in range(3000):  # the real one comes once the fake has answered: the fake goes first
                if "fake" in workers.answered or submitted.done():
                    break
                await asyncio.sleep(0.01)
            await workers.reconstructor("real")
            result = await submitted
            messages = [e.message for e in await _events(config, result.job_id)]
        await workers.close()
        assert workers.answered[0] == "fake"
        assert result.worker == "real" and result.attempts == 2
        assert result.superquadric.size == pytest.approx(STAND_IN_SIZE)
        assert any(m.startswith("attempt 1 on fake: refused: ") for m in messages), messages
        assert len(workers.moves) == len(result.T_base_cam)  # to the views, and nowhere the fake's model led

    _run(scenario())


def test_an_object_no_grasp_holds_fails_the_pick_and_the_arm_stays_put(tmp_path):
    """A model with no grasp (the planner finds none for a ball wider than the opening:
    tests/test_grasp.py) fails the pick at its first step, before the arm moves for it."""
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("w")  # its models carry no grasp
        try:
            async with daemon(network, config) as client:
                request = ScanRequest(target=target_from_config(config.sim), pick=PickRequest())
                with pytest.raises(JobFailed, match="choosing a grasp: no grasp holds this object") as failed:
                    await client.scan(request, timeout=30)
                assert failed.value.kind == "NoGrasp"
                job_id = failed.value.status.job_id
                assert (await client.status(job_id)).state is JobState.FAILED
        finally:
            await workers.close()
        assert len(workers.moves) == 3  # the views; no move of the pick

    _run(scenario())


def test_a_50_mb_submit_is_refused_unread_and_the_daemon_keeps_serving(tmp_path, monkeypatch):
    config = _config(tmp_path)
    parsed: list[int] = []
    real_parse = robocell.cell.requests.parse_request

    def counting(model, payload, limit):
        parsed.append(len(payload))
        return real_parse(model, payload, limit)

    monkeypatch.setattr(robocell.cell.requests, "parse_request", counting)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        await workers.reconstructor("real")
        async with daemon(network, config) as client:
            huge = b'{"target": [' + b" " * (50 * 1024 * 1024) + b"0, 0, 0]}"
            with pytest.raises(CellError) as refused:
                await client._transport.query(keys.submit(config.cell_id), huge, timeout=10)
            with pytest.raises(CellError) as unversioned:
                await client._transport.query(keys.submit(config.cell_id), b'{"target": [0.6, 0, 0.05]}', timeout=10)
            result = await client.scan(ScanRequest(target=target_from_config(config.sim)), timeout=30)
        await workers.close()
        assert str(refused.value) == f"the request is {len(huge)} bytes: at most 65536 are taken"
        assert len(huge) not in parsed  # refused before any parse
        assert str(unversioned.value) == ("invalid ScanRequest: schema_version: Field required "
                                          "(every request names its schema version, 1 or 2)")
        assert result.worker == "real"

    _run(scenario())


def test_only_the_client_that_submitted_a_job_may_cancel_it(tmp_path):
    """The submit's answer carries the job's token; another client, without it or with a guess, is
    refused in one line; the owner's client shows it by itself."""
    config = _config(tmp_path)

    async def scenario() -> None:
        network = MemoryNetwork()
        workers = Workers(network, config)
        other = AsyncCellClient(network.session(), config.cell_id, timeout=10.0)
        try:
            async with daemon(network, config) as owner:  # no reconstruction worker: the job waits for one
                status = await owner.submit(ScanRequest(target=target_from_config(config.sim)))
                refusals = []
                for guess in (None, "guessed-token-" * 2):
                    with pytest.raises(CellError) as refused:
                        await other.cancel(status.job_id, guess)
                    refusals.append(str(refused.value))
                still = await other.status(status.job_id)
                cancelled = await owner.cancel(status.job_id)
        finally:
            await other._transport.close()
            await workers.close()
        assert status.token is not None and len(status.token) >= 43
        assert refusals == [
            f"job {status.job_id}: no token shown: only the client that submitted it may do this "
            "(its submit's answer holds the token)",
            f"job {status.job_id}: the token shown is not the job's: only the client that submitted it may do this"]
        assert not still.lifecycle.finished and still.token is None
        assert cancelled.state is JobState.CANCELLED

    _run(scenario())


def test_retention_removes_old_recordings_while_the_cell_runs(tmp_path):
    """With a short interval the daemon deletes recordings past their age as it runs, keeps the new
    ones, and its status says what the run directory holds."""
    config = _config(tmp_path, retention={"interval_s": 0.2, "recordings_max_age_days": 1.0})
    config.run_dir.mkdir(parents=True, exist_ok=True)
    old, new = config.run_dir / "20200101-000001.rrd", config.run_dir / "20200101-000002.rrd"
    for path, age_days in ((old, 3.0), (new, 0.5)):
        path.write_bytes(b"r" * 100_000)
        when = time.time() - age_days * 86400
        os.utime(path, (when, when))

    async def scenario() -> tuple[bool, object]:
        network = MemoryNetwork()
        workers = Workers(network, config)
        try:
            async with daemon(network, config) as client:
                before = (await client.cell_status()).disk
                for _ in range(500):  # bounded: the first run comes after 0.2 s
                    if not old.exists():
                        break
                    await asyncio.sleep(0.02)
                after = (await client.cell_status()).disk
        finally:
            await workers.close()
        return before, after

    before, after = asyncio.run(asyncio.wait_for(scenario(), LIMIT_S))
    assert not old.exists() and new.exists()
    assert before.recordings >= 200_000 and before.recordings_to_free >= 100_000
    assert after.recordings_to_free == 0 and 100_000 <= after.recordings < 200_000
    assert "retention will free" in format_status_of(after)


def format_status_of(disk) -> str:
    from robocell.cli.jobs import format_status
    from robocell.wire.messages import CellStatus
    status = CellStatus(cell="c", time=0.0, started=0.0, workers={}, reconstructors=[], queued=0, max_queued=1,
                        waiting_for_reconstructor=0, jobs={}, recent_failures=[], disk=disk)
    return format_status(status)
