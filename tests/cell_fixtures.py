"""Shared parts of the cell's end-to-end tests: real processes, real Zenoh on loopback.

A test module starts one cell (router, workers, daemon as child processes,
through ``cell.up.CellProcesses``) and reuses it. Parts a test must steer
run in the test process instead: the simulated camera (for fault injection)
and a reconstruction worker that can be held at a gate. Every wait here is
bounded in time, and everything started is stopped in a ``finally``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import zenoh
from rerun.chunk import RrdReader

from robocell.wire import keys
from robocell.wire.client import CellClient
from robocell.wire.config import CellConfig
from robocell.cli.demo import free_port, local_config
from robocell.wire.messages import (CellStatus, JobEvent, JobState, JobStatus, ReconstructorStatus, ReconstructReply,
                                    ReconstructRequest, RobotState, ScanRequest)
from robocell.workers.sim.scene import scene_from_config, target_from_config
from robocell.cell.store import JobStore
from robocell.wire.transport import RequestError, Transport, session_config
from robocell.cli.up import CellProcesses
from robocell.workers.reconstruct.worker import ReconstructWorker, reconstruct_request
from robocell.workers.sim.axis import SimCameraServer
from robocell.workers.sim.axis_process import robot_camera_pose

__all__ = ["free_port", "cell_config", "SMALL_CAMERA", "LoopThread", "RunningCell", "running_cell",
           "InProcessSimCamera", "GatedReconstructor", "wait_until", "accepts", "wait_for_footer", "look_away_poses",
           "add_worker", "InProcessWorker", "RecordingWorker", "printed_box_cell"]

# Generous bounds: they only matter when something is broken, and then the test fails instead of hanging.
START_TIMEOUT_S = 60.0
JOB_TIMEOUT_S = 60.0

#: The ``camera`` of a test about the cell's jobs, workers and faults rather than the model's accuracy:
#: the default camera's field of view with a quarter of its pixels, which the simulated camera renders,
#: the wire carries and the core fits in about half the time (tests scored against the truth keep the
#: default camera).
SMALL_CAMERA = {"resolution": (320, 240), "K": [[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]]}


def cell_config(run_dir: Path, *, robot: dict | None = None, camera: dict | None = None,
                timeouts: dict | None = None, **fields) -> CellConfig:
    """A test cell on free local ports: an instant robot, short time-outs (but the camera's, which
    renders) and few retries.

    ``robot``, ``camera`` and ``timeouts`` update those sections; other keyword
    arguments are top-level fields (``cell_id``, ``sim``, ``reconstruct``...).
    """
    # Red on the pale table unless a test asks for print: a printed picture costs six times the CPU,
    # and the cells' tests are about the cell (tests/test_cell_pick.py scans and picks a printed box).
    sim = {"look": "red", **fields.pop("sim", {})}
    return local_config(
        run_dir, **{"cell_id": "test", "sim": sim, **fields},
        robot={**({"speed": 0.0, "rotation_speed_deg": 0.0} if (robot or {}).get("backend", "sim") == "sim" else {}),
               **(robot or {})},
        # The simulated camera renders each picture on this machine's CPU (a printed object, its
        # shadow, a textured table: seconds when the machine is busy), where an Axis camera answers
        # in a fraction of one.
        camera={"timeout_s": 20.0, "retries": 1, **(camera or {})},
        timeouts={"move_s": 10.0, "capture_s": 45.0, "reconstruct_s": 30.0, "outage_s": 1.0, **(timeouts or {})})


def look_away_poses(config: CellConfig) -> list[list[list[float]]]:
    """Flange poses inside the workspace whose camera sees only table: the object is out of view."""
    from robocell.wire.messages import ViewPlan
    from robocell.core_cy.plan import plan_flange_poses, workspace_violation

    empty_spot = [config.sim.position[0], config.sim.position[1] + 0.4, 0.0]
    poses = plan_flange_poses(empty_spot, ViewPlan(standoff=0.3), config.T_flange_cam)
    assert not any(workspace_violation(pose, config.robot.workspace) for pose in poses)
    return [pose.tolist() for pose in poses]


def wait_for_footer(path: str | Path, *, timeout: float = 30.0) -> None:
    """Wait until the recording at ``path`` is complete: the daemon's recorder writes it a moment
    after the job ends, and closes it with a footer."""
    def complete() -> bool:
        if not Path(path).exists():
            return False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer" is what we are waiting out
            try:
                RrdReader(str(path)).store()
            except (RuntimeError, OSError, ValueError):
                return False
        return True

    wait_until(complete, timeout=timeout, interval=0.05, what=f"the footer of {path}")


def accepts(host: str, port: int) -> bool:
    """Whether something listens on ``host``:``port`` (TCP)."""
    with socket.socket() as probe:
        return probe.connect_ex((host, port)) == 0


def wait_until(predicate: Callable[[], object], *, timeout: float, interval: float = 0.01, what: str = "") -> object:
    """Poll ``predicate`` until it returns something true; fail the test after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what or predicate}")
        time.sleep(interval)


class LoopThread:
    """An asyncio event loop in a thread of its own, for the async parts of a sync test."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name="test-loop", daemon=True)
        self._thread.start()

    def run(self, coroutine, timeout: float = 60.0):
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(timeout)

    def close(self) -> None:
        async def drain() -> None:
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await self.loop.shutdown_asyncgens()
            await self.loop.shutdown_default_executor()

        try:
            self.run(drain(), timeout=30.0)
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(10.0)
            self.loop.close()


class RunningCell:
    """A started cell: its processes, a blocking client, and a reader of its job store."""

    def __init__(self, config: CellConfig, processes: CellProcesses, loop: LoopThread, client: CellClient) -> None:
        self.config = config
        self.processes = processes
        self.loop = loop
        self.client = client
        self.worker_ids: dict[str, str] = {}    # reconstruction workers added by name (running_cell's workers)

    @property
    def router(self) -> str:
        return self.config.zenoh.router

    def scan_request(self, **fields) -> ScanRequest:
        if "flange_poses" not in fields and "target" not in fields:
            fields["target"] = target_from_config(self.config.sim)
        return ScanRequest(**fields)

    def submit(self, **fields) -> JobStatus:
        return self.client.submit(self.scan_request(**fields))

    def wait(self, job_id: str, timeout: float = JOB_TIMEOUT_S) -> JobStatus:
        return self.client.wait(job_id, timeout=timeout)

    def wait_state(self, job_id: str, states: set[JobState], timeout: float = JOB_TIMEOUT_S) -> JobStatus:
        """Poll until the job is in one of ``states``; fail if it finishes in another state first."""
        def check() -> JobStatus | None:
            status = self.client.status(job_id)
            if status.state in states:
                return status
            assert not status.state.finished, f"job {job_id} ended {status.state.value} ({status.error}) " \
                                              f"before reaching {sorted(s.value for s in states)}"
            return None

        return wait_until(check, timeout=timeout, interval=0.005, what=f"job {job_id} in {states}")

    def events(self, job_id: str) -> list[JobEvent]:
        """The job's events as the daemon stored them, once it has written what it held back (a
        query that reads the store makes it: see ``cell.executor``; a daemon that stops writes it)."""
        if self.daemon_running():
            self.client.status(job_id)
        with JobStore(self.config.run_dir / "jobs.sqlite") as store:
            return store.events(job_id)

    def robot_state(self) -> RobotState:
        return self.loop.run(self._robot_state())

    async def _robot_state(self) -> RobotState:
        async with await Transport.open(self.router) as transport:
            reply = await transport.query(keys.robot_state(self.config.cell_id), timeout=5.0)
        return RobotState.model_validate_json(reply.payload)

    def log(self, name: str) -> str:
        return (self.processes.log_dir / f"{name}.log").read_text(errors="replace")

    def tracebacks(self) -> dict[str, str]:
        """The log of every child that logged a traceback, by name."""
        logs = {child.name: self.log(child.name) for child in self.processes.children
                if (self.processes.log_dir / f"{child.name}.log").exists()}
        return {name: text for name, text in logs.items() if "Traceback" in text}

    def daemon_running(self) -> bool:
        process = self.processes.child("daemon").process
        return process is not None and process.returncode is None

    # --- the reconstruction pool ---------------------------------------------------------------

    def status(self) -> CellStatus:
        return self.client.cell_status()

    def reconstructor(self, worker_id: str) -> ReconstructorStatus | None:
        """The worker as the daemon sees it now; None if the daemon does not know it (any more)."""
        return next((r for r in self.status().reconstructors if r.worker == worker_id), None)

    def start_worker(self, name: str, *, delay: float = 0.0, fail: bool = False) -> str:
        """Start one more reconstruction worker process (see :func:`add_worker`); its id, once ready."""
        worker_id = add_worker(self.processes, name, delay=delay, fail=fail)
        self.loop.run(self.processes.start_child(name, ready_timeout=START_TIMEOUT_S), timeout=START_TIMEOUT_S + 10)
        return worker_id

    def hold(self, worker_id: str) -> None:
        """Hold the jobs of a worker of :func:`add_worker`: from now on each waits, in flight there,
        until :meth:`release`."""
        path = hold_file(self.processes, worker_id)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()

    def release(self, worker_id: str) -> None:
        """Let the worker's held jobs go on (see :meth:`hold`)."""
        hold_file(self.processes, worker_id).unlink(missing_ok=True)

    def put_job_on(self, worker_id: str) -> str:
        """Submit a job and hold it in flight at ``worker_id``, the only reconstruction worker the
        daemon knows (the test stops or has not started the others: the job can go nowhere else);
        the job's id, once the worker has it. It stays there until :meth:`release`."""
        # The daemon hears of a worker stopped a moment after the router does: wait for its view.
        wait_until(lambda: {r.worker for r in self.status().reconstructors} == {worker_id}, timeout=JOB_TIMEOUT_S,
                   interval=0.02, what=f"{worker_id} alone in the daemon's pool")
        self.hold(worker_id)
        job_id = self.submit(label=f"for {worker_id}").job_id
        prefix = f"{self.config.cell_id}/{job_id}/"

        def placed() -> bool:
            worker = self.reconstructor(worker_id)
            if worker is not None and any(t.startswith(prefix) for t in worker.tickets_here):
                return True
            status = self.client.status(job_id)
            assert not status.state.finished, f"job {job_id} ended {status.state.value} ({status.error}) " \
                                              f"before it reached {worker_id}"
            return False

        wait_until(placed, timeout=JOB_TIMEOUT_S, interval=0.02, what=f"job {job_id} in flight at {worker_id}")
        return job_id


def hold_file(processes: CellProcesses, worker_id: str) -> Path:
    """The file whose presence holds the jobs of a worker of :func:`add_worker` (``--hold``)."""
    return Path(processes.config.run_dir) / "holds" / worker_id


def add_worker(processes: CellProcesses, name: str, *, delay: float = 0.0, fail: bool = False) -> str:
    """Add (not start) a reconstruction worker child running ``tests/scale_worker.py``: the real
    worker, its jobs ``delay`` seconds longer (or failing, with ``fail``), held while the test says
    (``RunningCell.hold``); returns its id."""
    worker_id = f"{processes.config.cell_id}-{name}-{os.getpid()}"
    argv = [sys.executable, str(Path(__file__).with_name("scale_worker.py")), "--config",
            str(processes.config_path), "--id", worker_id, "--delay", str(delay),
            "--hold", str(hold_file(processes, worker_id))]
    if fail:
        argv.append("--fail")
    processes.add_child(name, argv, token=keys.reconstructor_alive(worker_id))
    return worker_id


@contextlib.contextmanager
def running_cell(config: CellConfig, *, workers: dict[str, float] | None = None, **parts) -> Iterator[RunningCell]:
    """Start a cell as child processes (``parts`` as for CellProcesses); stop it all afterwards.

    ``workers`` adds reconstruction workers (:func:`add_worker`), name to delay; their ids are
    ``RunningCell.worker_ids[name]``.
    """
    loop = LoopThread()
    processes = CellProcesses(config, **parts)
    worker_ids = {name: add_worker(processes, name, delay=delay) for name, delay in (workers or {}).items()}
    client = None
    try:
        loop.run(processes.start(ready_timeout=START_TIMEOUT_S), timeout=START_TIMEOUT_S + 10)
        client = CellClient(config.zenoh.router, config.cell_id, timeout=10.0)
        running = RunningCell(config, processes, loop, client)
        running.worker_ids = worker_ids
        yield running
    finally:
        try:
            if client is not None:
                client.close()
        finally:
            try:
                loop.run(processes.stop(), timeout=60.0)
            finally:
                loop.close()


class InProcessSimCamera:
    """The simulated Axis camera, served by the test itself so that it can inject faults.

    As ``robocell sim camera`` does, it renders from the robot worker's pose,
    asked over Zenoh. :meth:`restart` serves again on the same port, e.g. with
    other credentials.
    """

    def __init__(self, config: CellConfig) -> None:
        self.config = config
        self._session = zenoh.open(session_config(config.zenoh.router, connect_timeout_ms=10_000))
        self.server: SimCameraServer | None = None

    def start(self, password: str | None = None) -> SimCameraServer:
        camera = self.config.camera
        password = password if password is not None else camera.resolved_password()
        host, port = camera.url.rsplit(":", 1)
        server = SimCameraServer(
            scene_from_config(self.config.sim), K=np.asarray(camera.K), image_size=tuple(camera.resolution),
            dist=camera.dist, pose_provider=lambda: robot_camera_pose(self._session, self.config),
            host=host.removeprefix("http://"), port=int(port), username=camera.username, password=password,
            auth=camera.auth if camera.username else None, seed=self.config.sim.seed)
        server.start()
        self.server = server
        return server

    def restart(self, password: str | None = None) -> SimCameraServer:
        self.stop_server()
        return self.start(password)

    def stop_server(self) -> None:
        server, self.server = self.server, None
        if server is not None:
            server.stop()

    def close(self) -> None:
        try:
            self.stop_server()
        finally:
            self._session.close()


class GatedReconstructor:
    """A reconstruction worker served in the test process: the real core, behind a gate.

    It serves the pool keys with ``workers.reconstruct.ReconstructWorker``
    (capacity 1), as ``robocell worker reconstruct`` does. While :meth:`hold`
    is in force a request waits (at most ``max_hold_s``) until :meth:`release`.
    """

    def __init__(self, loop: LoopThread, router: str, worker_id: str = "gated", *, max_hold_s: float = 30.0) -> None:
        self.loop = loop
        self.worker_id = worker_id
        self.max_hold_s = max_hold_s
        self.received: list[str] = []       # ReconstructRequest JSON of each request
        self.answered = 0
        self.waiting = threading.Event()   # a request is at the closed gate
        self._open = threading.Event()
        self._open.set()
        self._transport: Transport = loop.run(Transport.open(router, connect_timeout_s=10.0))
        self._worker = ReconstructWorker(self._transport, worker_id, 1, self._run)
        loop.run(self._worker.start())

    def announce(self) -> None:
        self.loop.run(_call(self._worker.announce))

    def withdraw(self) -> None:
        """Take the liveliness token back: the daemon then sees no reconstructor."""
        self.loop.run(_call(self._worker.withdraw))

    def hold(self) -> None:
        self.waiting.clear()
        self._open.clear()

    def release(self) -> None:
        self._open.set()

    async def _run(self, request_json: str, payload: bytes) -> tuple[str, bytes]:
        self.received.append(request_json)
        if not self._open.is_set():
            self.waiting.set()
            if not await asyncio.to_thread(self._open.wait, self.max_hold_s):
                raise RequestError(f"test gate still closed after {self.max_hold_s:g} s")
        reply = await asyncio.to_thread(reconstruct_request, request_json, payload, self.worker_id)
        self.answered += 1
        return reply

    def close(self) -> None:
        self.release()
        try:
            self.loop.run(self._worker.close(), timeout=20.0)
        finally:
            self.loop.run(self._transport.close(), timeout=20.0)


async def _call(function: Callable[[], object]) -> object:
    """``function()`` on the event loop (Zenoh declarations of a transport belong to its loop)."""
    return function()


class InProcessWorker:
    """A reconstruction worker served in the test process (``ReconstructWorker``), whose work is
    ``run(request_json, payload) -> reply JSON``, a coroutine function of the test's."""

    def __init__(self, loop: LoopThread, router: str, worker_id: str, run, *, capacity: int = 1) -> None:
        self.loop = loop
        self.worker_id = worker_id
        self._transport: Transport = loop.run(Transport.open(router, connect_timeout_s=10.0))
        self._worker = ReconstructWorker(self._transport, worker_id, capacity, run)
        loop.run(self._worker.start())

    def close(self) -> None:
        try:
            self.loop.run(self._worker.close(), timeout=20.0)
        finally:
            self.loop.run(self._transport.close(), timeout=20.0)


class RecordingWorker:
    """The real reconstruction, which keeps each request, its payload and its reply."""

    def __init__(self) -> None:
        self.seen: list[tuple[ReconstructRequest, bytes, ReconstructReply, bytes]] = []

    async def run(self, request_json: str, payload: bytes) -> tuple[str, bytes]:
        reply_json, reply_payload = await asyncio.to_thread(reconstruct_request, request_json, payload, "recorder")
        self.seen.append((ReconstructRequest.model_validate_json(request_json), payload,
                          ReconstructReply.model_validate_json(reply_json), reply_payload))
        return reply_json, reply_payload


@contextlib.contextmanager
def printed_box_cell(root: Path) -> Iterator[RunningCell]:
    """A cell whose table holds a printed box, served by a :class:`RecordingWorker` in the test
    process (``cell.recorder``): the cell of the tests of picks and of backgrounds, started once
    for both (tests/conftest.py)."""
    config = cell_config(root, cell_id="printed",
                         sim={"shape": "box", "size": [0.04, 0.025, 0.05], "position": [0.6, 0.0], "yaw_deg": 20,
                              "look": "printed"})
    with running_cell(config, reconstructors=0) as running:
        recorder = RecordingWorker()
        worker = InProcessWorker(running.loop, running.router, "recorder", recorder.run)
        running.recorder = recorder  # type: ignore[attr-defined]
        try:
            wait_until(lambda: [r.worker for r in running.status().reconstructors] == ["recorder"], timeout=20,
                       what="the in-process worker in the pool")
            yield running
        finally:
            worker.close()
