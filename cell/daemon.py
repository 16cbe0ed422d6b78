"""The cell daemon: one asyncio state machine per scan job.

queued -> moving(i) -> capturing(i) (for each view) -> reconstructing -> succeeded
                                   any step -> failed (with the step and reason) | cancelled

One robot and one camera: a single *motion lane* takes jobs in order and
moves and captures for one job at a time. When a job's pictures are taken,
its reconstruction runs as a task of its own, so it overlaps the next job's
motion. Every state change is stored (SQLite), published as a JobEvent and
written to the job's Rerun recording.

Reconstructions go to the pool of reconstruction workers that every cell on
the network shares (``cell.pool``): each to the least loaded live worker.
An attempt whose worker dies, hangs, runs out of time or answers an error is
made again on another worker, up to ``reconstruct.max_attempts`` attempts in
all; then the job fails, naming each attempt's worker and what went wrong.
Each retry is a JobEvent of its own.

The event loop only decides, asks and publishes. The job store runs in a
thread of its own, in order (an SQLite connection belongs to one thread); the
recordings are written by a process of their own (``cell.recorder``: their
milliseconds of logging would otherwise delay every job), and are complete a
moment after the job ends. A step's bookkeeping (store, event) is done once its
query to the worker is on its way; its recording messages wait with the job and
are handed over while the job waits for something slow (a snapshot, the
reconstruction), and a job's last ones after its end is published. What the
loop remembers of the jobs (the queue, the jobs in flight) is what its
decisions need, so no decision waits for the store. What must outlive a crash is awaited before
anyone hears of it: a job is stored before its submit is answered, a result
before the job is announced succeeded, and the end of a job (succeeded,
failed, cancelled) before its event is published. After a crash, the
restarted daemon fails the jobs caught mid-step ("interrupted") and runs the
queued ones.

Cancelling cancels the job's task and sets a flag every step checks: on
Python 3.11 a cancel that arrives as an awaited answer does can be lost.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wire import keys
from wire.config import CellConfig
from wire.errors import CellError, NoResponder, RemoteError, TransportError
from wire.messages import (CameraModel, CaptureInfo, CaptureRequest, CellStatus, FailedJob, JobEvent, JobState,
                       JobStatus, MoveReply, MoveRequest, ReconstructReply, ReconstructRequest, ReconstructView,
                       ScanRequest, ScanResult, parse)
from core_cy.plan import camera_poses, plan_flange_poses, workspace_violation
from .pool import AttemptFailed, NoReconstructor, ReconstructorPool
from .recorder import Recorder
from .store import JobStore, queued_event
from wire.transport import Request, RequestError, Response, Transport

__all__ = ["CellDaemon", "StepFailed"]

log = logging.getLogger(__name__)
_CANCEL_WAIT_S = 2.0
_RECENT_FAILURES = 10       # failed jobs in a status answer, unless asked for another number


class StepFailed(CellError):
    """A step of a job failed; the message says which step and why."""


def _later(function: Callable, *args, **kwargs) -> None:
    """Call ``function`` when the event loop next looks round, in the order of these calls.

    What a step records (store, event, recording) is done after the step's query is on its way:
    the worker starts at once, and the bookkeeping overlaps its work.
    """
    asyncio.get_running_loop().call_soon(functools.partial(function, *args, **kwargs))


class _Serial:
    """One thread that runs the calls given to it, in order.

    A call is handed to the thread when the event loop next looks round (see
    :func:`_later`), so calls and posts keep the order they were made in.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self._executor = ThreadPoolExecutor(1, thread_name_prefix=name)

    async def call(self, function: Callable, *args, **kwargs):
        """Run ``function`` in the thread after everything posted before; its result."""
        handed: asyncio.Future[Future] = asyncio.get_running_loop().create_future()
        _later(self._hand, functools.partial(function, *args, **kwargs), handed)
        return await asyncio.wrap_future(await handed)

    def _hand(self, call: Callable, handed: asyncio.Future) -> None:
        if not handed.cancelled():  # the caller gave up before the call was handed over: skip it
            handed.set_result(self._executor.submit(call))

    def post(self, function: Callable, *args, then: Callable[[], None] | None = None, **kwargs) -> None:
        """Run ``function`` in the thread after everything posted before; a failure is logged.

        ``then`` is called on the event loop once ``function`` has returned (or failed).
        """
        _later(self._post, functools.partial(function, *args, **kwargs), then)

    def _post(self, call: Callable, then: Callable[[], None] | None = None) -> None:
        future = self._executor.submit(call)
        future.add_done_callback(self._log_failure)
        if then is not None:
            loop = asyncio.get_running_loop()
            future.add_done_callback(lambda _: loop.call_soon_threadsafe(then))

    def _log_failure(self, future: Future) -> None:
        exc = future.exception()
        if exc is not None:
            log.error("%s: %s: %s", self.name, type(exc).__name__, exc, exc_info=exc)

    def close(self) -> None:
        """Run what is posted, then end the thread."""
        self._executor.shutdown(wait=True)


@dataclass
class _Capture:
    jpeg: bytes
    T_base_flange: np.ndarray
    T_base_cam: np.ndarray


@dataclass
class _ActiveJob:
    job_id: str
    request: ScanRequest
    poses: list[np.ndarray] | None      # planned at submit; None: plan when the job starts
    started: float
    task: asyncio.Task | None = None
    cancel_requested: bool = False
    finishing: bool = False                 # the result is being stored: too late to cancel
    captures: list[_Capture] = field(default_factory=list)
    unrecorded: list[tuple] = field(default_factory=list)   # see CellDaemon._record
    durations_s: dict[str, float] = field(default_factory=dict)   # what the job waited for, see ScanResult

    def check_cancel(self) -> None:
        """Raise CancelledError if a cancel was asked for: a task's cancel can get lost in an await
        that completes at the same moment, so every step checks the flag too."""
        if self.cancel_requested:
            raise asyncio.CancelledError


class CellDaemon:
    """Runs scan jobs for one cell. Create, then ``await run(stop)``.

    The job store is ``store_path`` (default ``<run dir>/jobs.sqlite``), opened
    by ``run`` in the store's own thread.
    """

    def __init__(self, config: CellConfig, transport: Transport, *, store_path: Path | None = None,
                 clock=time.time) -> None:
        self.config = config
        self.cell = config.cell_id
        self.run_dir = Path(config.run_dir)
        self._store_path = store_path or self.run_dir / "jobs.sqlite"
        self._transport = transport
        self._clock = clock
        self._store: JobStore | None = None     # used in the store thread only
        self._db = _Serial("job-store")
        self._recorder = Recorder(n_points=config.reconstruct.n_points,
                                  sim=config.sim.model_dump() if config.robot.backend == "sim" else None)
        self._queue: asyncio.Queue[str] = asyncio.Queue()
        self._queued: dict[str, tuple[ScanRequest, list[np.ndarray] | None]] = {}   # waiting jobs, in order
        self._active: dict[str, _ActiveJob] = {}    # jobs being moved for, captured or reconstructed
        self._alive: set[str] = set()                   # this cell's workers with a liveliness token
        self._pool = ReconstructorPool(transport, heartbeat_s=config.timeouts.heartbeat_s)
        self._presence = asyncio.Condition()
        self._background: set[asyncio.Task] = set()
        self._submitting = 0                            # submits between the queue check and the queue
        self._started = clock()

    # --- lifecycle -----------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self._store = await self._db.call(JobStore, self._store_path)
        self._recorder.start()
        try:
            await self._recover()
            await self._serve(stop)
        finally:
            await asyncio.sleep(0)  # what is handed over later goes out first
            await asyncio.to_thread(self._recorder.stop)  # it closes the recordings still open
            await self._db.call(self._store.close)
            await asyncio.to_thread(self._db.close)

    async def _serve(self, stop: asyncio.Event) -> None:
        transport, cell = self._transport, self.cell
        self._spawn(self._watch(transport.watch_liveliness(keys.alive(cell)), self._on_cell_worker))
        self._pool.start()
        transport.serve(keys.submit(cell), self._on_submit)
        transport.serve(keys.jobs(cell), self._on_list)
        transport.serve(keys.status(cell), self._on_status)
        # Not "jobs/**": that matches "jobs" too, and a list query would get a second, wrong answer.
        transport.serve(keys.job(cell, "*"), self._on_job_query)
        transport.serve(f"{keys.job(cell, '*')}/*", self._on_job_query)
        lane = self._spawn(self._motion_lane())
        transport.declare_token(keys.alive(cell, "daemon"))
        log.info("cell %s ready: run directory %s", cell, self.run_dir.resolve())
        try:
            await stop.wait()
        finally:
            lane.cancel()
            for task in list(self._background):
                task.cancel()
            await asyncio.gather(*self._background, return_exceptions=True)
            await self._pool.close()
            for active in self._active.values():  # jobs cut short keep what they recorded
                self._hand_to_recorder(active)

    def _spawn(self, coroutine) -> asyncio.Task:
        task = asyncio.create_task(coroutine)
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        return task

    async def _recover(self) -> None:
        """After a restart: jobs caught mid-step failed; queued jobs run again, in order."""
        def recover(store: JobStore, now: float) -> tuple[list[JobStatus], list[JobStatus]]:
            return store.interrupt_unfinished(now=now), store.unfinished()

        interrupted, waiting = await self._db.call(recover, self._store, self._clock())
        for status in interrupted:
            self._event(status.job_id, status.state, status.error or "interrupted", now=status.updated)
            log.warning("job %s was interrupted by a restart", status.job_id)
        for status in waiting:
            self._enqueue(status.job_id, status.request)

    def _enqueue(self, job_id: str, request: ScanRequest, poses: list[np.ndarray] | None = None) -> None:
        """Queue the job; ``poses`` are its flange poses, if already planned."""
        self._queued[job_id] = (request, poses)
        self._queue.put_nowait(job_id)

    # --- worker presence -----------------------------------------------------------------------

    async def _watch(self, subscription, on_change) -> None:
        try:
            async for key, alive in subscription:
                on_change(key, alive)
                async with self._presence:
                    self._presence.notify_all()
        finally:
            subscription.close()

    def _on_cell_worker(self, key: str, alive: bool) -> None:
        part = key.rsplit("/", 1)[-1]
        if part == "daemon":
            return  # the daemon's own token, not a worker
        (self._alive.add if alive else self._alive.discard)(part)
        log.info("%s worker %s", part, "is up" if alive else "is gone")

    async def _wait_for(self, ready, what: str) -> None:
        if ready():
            return
        wait = self.config.timeouts.worker_wait_s
        try:
            async with asyncio.timeout(wait), self._presence:
                await self._presence.wait_for(ready)
        except TimeoutError:
            raise StepFailed(f"no {what} is running (waited {wait:g} s)") from None

    async def _ask(self, part: str, key: str, message, timeout: float, **kwargs):
        await self._wait_for(lambda: part in self._alive, f"{part} worker")
        try:
            return await self._transport.query(key, message.model_dump_json(), timeout=timeout, **kwargs)
        except NoResponder:
            raise StepFailed(f"no {part} worker is running") from None
        except RemoteError as exc:  # the worker's own message names the part and the reason
            raise StepFailed(str(exc)) from None
        except TransportError as exc:
            raise StepFailed(f"{part}: {exc}") from None

    # --- job state -----------------------------------------------------------------------------

    def _event(self, job_id: str, state: JobState, message: str, *, view: int | None = None,
               now: float) -> None:
        """An event that changes no state (a retry, a restart's verdict): stored, recorded, published."""
        event = JobEvent(job_id=job_id, state=state, view=view, message=message, time=now)
        self._note(event)
        self._db.post(self._store.add_event, event, then=functools.partial(self._publish, event))

    def _set(self, job_id: str, state: JobState, message: str, *, view: int | None = None,
             error: str | None = None, recording: Path | None = None) -> None:
        """Move the job to ``state``: the store is written in its thread, in order, without waiting.

        A step's event is published at once; the end of a job only once the store has it
        (see the module's text).
        """
        event = JobEvent(job_id=job_id, state=state, view=view, message=message, time=self._clock())
        self._note(event)
        stored = functools.partial(self._publish, event) if state.finished else None
        self._db.post(self._store.update, job_id, state, view=view, error=error, now=event.time,
                      recording=None if recording is None else str(recording), event=event, then=stored)
        if stored is None:
            _later(self._publish, event)

    def _note(self, event: JobEvent) -> None:
        """Write the event into the job's recording; a finished job's recording is closed (the
        recorder writes its footer a moment later)."""
        active = self._active.get(event.job_id)
        if active is None:
            return
        level = "ERROR" if event.state is JobState.FAILED else "INFO"
        self._record(active, "log_text", f"{event.state.value}: {event.message}", level)
        if event.state.finished:
            del self._active[event.job_id]
            self._hand_to_recorder(active)
            _later(self._recorder.close, event.job_id)

    def _publish(self, event: JobEvent) -> None:
        self._transport.put(keys.events(self.cell, event.job_id), event.model_dump_json())

    def _recording_path(self, job_id: str) -> Path:
        return self.run_dir / f"{job_id}.rrd"

    def _flange_poses(self, request: ScanRequest) -> list[np.ndarray]:
        if request.flange_poses is not None:
            return [np.asarray(pose, dtype=np.float64) for pose in request.flange_poses]
        plan = request.plan or self.config.scan.plan
        return plan_flange_poses(request.target, plan, self.config.T_flange_cam)

    def _record(self, active: _ActiveJob, method: str, *args, **kwargs) -> None:
        """``JobRecording.<method>(*args, **kwargs)`` on the job's recording, at the job time of now.

        Kept with the job until :meth:`_hand_to_recorder`: handing a message over costs the
        event loop and the interpreter time, and a robot that moves at once answers in under a
        millisecond. So the messages go over while the job waits for something slow.
        """
        active.unrecorded.append((self._clock() - active.started, method, args, kwargs))

    def _hand_to_recorder(self, active: _ActiveJob) -> None:
        """Hand the job's recording messages to the recorder, when the event loop next looks round."""
        for at, method, args, kwargs in active.unrecorded:
            _later(self._recorder.call, active.job_id, at, method, *args, **kwargs)
        active.unrecorded.clear()

    # --- the motion lane -----------------------------------------------------------------------

    async def _motion_lane(self) -> None:
        while True:
            job_id = await self._queue.get()
            queued = self._queued.pop(job_id, None)
            if queued is None:
                continue  # cancelled while it waited
            active = _ActiveJob(job_id, *queued, started=self._clock())
            self._active[job_id] = active
            _later(self._recorder.open, job_id, self._recording_path(job_id))
            active.task = self._spawn(self._acquire(active))  # a stopping daemon cancels it too
            # asyncio.wait, unlike await, does not raise when the job (not the lane) is cancelled.
            await asyncio.wait({active.task})

    async def _acquire(self, active: _ActiveJob) -> None:
        job_id, timeouts = active.job_id, self.config.timeouts
        step = "planning"
        try:
            poses = active.poses if active.poses is not None else self._flange_poses(active.request)
            for view, pose in enumerate(poses):
                step = f"moving to view {view}"
                self._set(job_id, JobState.MOVING, step, view=view, recording=self._recording_path(job_id))
                reply = await self._ask("robot", keys.robot_move(self.cell),
                                        MoveRequest(T_base_flange=pose.tolist(), job_id=job_id), timeouts.move_s)
                active.check_cancel()
                moved = parse(MoveReply, reply.payload)
                reached = np.asarray(moved.T_base_flange)
                active.durations_s[f"move{view}"] = moved.duration_s
                self._record(active, "log_robot_pose", reached)
                step = f"capturing view {view}"
                self._set(job_id, JobState.CAPTURING, step, view=view)
                self._hand_to_recorder(active)  # during the snapshot, which takes tens of milliseconds
                reply = await self._ask("camera", keys.camera_capture(self.cell),
                                        CaptureRequest(job_id=job_id, view=view), timeouts.capture_s)
                active.check_cancel()
                info = parse(CaptureInfo, reply.attachment)
                active.durations_s[f"capture{view}"] = info.duration_s
                T_base_cam = camera_poses([reached], self.config.T_flange_cam)[0]
                active.captures.append(_Capture(reply.payload, reached, T_base_cam))
                self._record(active, "log_view", view, reply.payload, self.config.camera.K, T_base_cam,
                             (info.width, info.height))
            step = "reconstructing"
            self._set(job_id, JobState.RECONSTRUCTING, f"{len(poses)} views taken")
        except asyncio.CancelledError:
            self._cancelled(active)
            return
        except (StepFailed, ValueError) as exc:
            self._fail(job_id, f"{step}: {exc}")
            return
        except Exception as exc:  # a bug must not leave the job hanging, nor stop the lane
            log.exception("job %s: %s failed", job_id, step)
            self._fail(job_id, f"{step}: internal error: {type(exc).__name__}: {exc}")
            return
        active.task = self._spawn(self._reconstruct(active))

    def _cancelled(self, active: _ActiveJob) -> None:
        if active.cancel_requested:
            self._set(active.job_id, JobState.CANCELLED, "cancelled by request")
        else:
            raise asyncio.CancelledError  # the daemon is stopping: the restart will deal with the job

    def _fail(self, job_id: str, error: str) -> None:
        log.warning("job %s failed: %s", job_id, error)
        self._set(job_id, JobState.FAILED, error, error=error)

    # --- reconstruction ------------------------------------------------------------------------

    async def _reconstruct(self, active: _ActiveJob) -> None:
        job_id, settings = active.job_id, self.config.reconstruct
        failures: list[str] = []      # "attempt <k> on <worker>: <why>"
        tried: set[str] = set()
        try:
            payload = b"".join(c.jpeg for c in active.captures)
            request = self._reconstruct_request(active)
            self._hand_to_recorder(active)
            for attempt in range(1, settings.max_attempts + 1):
                request.ticket = keys.ticket(self.cell, job_id, attempt)
                began = time.perf_counter()
                try:
                    worker, reply = await self._pool.run(
                        request.ticket, payload, request.model_dump_json(),
                        timeout=self.config.timeouts.reconstruct_s, wait_s=self.config.timeouts.worker_wait_s,
                        avoid=tried)
                except AttemptFailed as exc:
                    active.check_cancel()
                    tried.add(exc.worker)
                    failures.append(f"attempt {attempt} on {exc.worker}: {exc.reason}")
                    log.warning("job %s: %s", job_id, failures[-1])
                    if attempt < settings.max_attempts:
                        self._event(job_id, JobState.RECONSTRUCTING, f"{failures[-1]}; trying again",
                                    now=self._clock())
                    continue
                active.check_cancel()
                active.durations_s["reconstruct"] = time.perf_counter() - began
                answer = parse(ReconstructReply, reply.payload)
                if answer.error:
                    raise StepFailed(answer.error)  # the core's verdict on these pictures: no use retrying
                active.finishing = True
                await self._succeed(active, answer, reply.payload, worker=worker, attempts=attempt)
                return
            raise StepFailed(f"gave up after {settings.max_attempts} attempts: {'; '.join(failures)}")
        except asyncio.CancelledError:
            self._cancelled(active)
        except NoReconstructor as exc:
            earlier = f" (after {'; '.join(failures)})" if failures else ""
            self._fail(job_id, f"reconstructing: {exc}{earlier}")
        except (StepFailed, TransportError, ValueError) as exc:
            self._fail(job_id, f"reconstructing: {exc}")
        except Exception as exc:  # a bug must not leave the job hanging
            log.exception("job %s: reconstruction failed", job_id)
            self._fail(job_id, f"reconstructing: internal error: {type(exc).__name__}: {exc}")

    def _reconstruct_request(self, active: _ActiveJob) -> ReconstructRequest:
        camera = CameraModel(K=self.config.camera.K, dist=self.config.camera.dist)
        settings = self.config.reconstruct
        options = {name: value for name in ("n_points", "inside_weight", "cauchy_scale")
                   if (value := getattr(settings, name)) is not None}
        views = [ReconstructView(camera=camera, T_world_cam=c.T_base_cam.tolist(), length=len(c.jpeg))
                 for c in active.captures]
        return ReconstructRequest(job_id=active.job_id, views=views, support_plane=self.config.support_plane,
                                  options=options)

    async def _succeed(self, active: _ActiveJob, answer: ReconstructReply, reply_json: bytes, *, worker: str,
                       attempts: int) -> None:
        arrived = self._clock() - active.started
        result = answer.result
        scan_result = ScanResult(job_id=active.job_id, superquadric=result["superquadric"],
                                 silhouette_iou=result["silhouette_iou"], residual=result["residual"],
                                 timings_ms=result["timings_ms"],
                                 T_base_cam=[c.T_base_cam.tolist() for c in active.captures],
                                 durations_s=active.durations_s,
                                 recording=str(self._recording_path(active.job_id)),
                                 worker=answer.worker or worker, attempts=attempts)
        total = result["timings_ms"].get("total", float("nan"))
        attempt = f" (attempt {attempts})" if attempts > 1 else ""
        event = JobEvent(job_id=active.job_id, state=JobState.SUCCEEDED, time=self._clock(), result=scan_result,
                         message=f"reconstructed by {scan_result.worker} in {total:.1f} ms{attempt}")
        # Stored for good before anyone hears of it; shielded: once begun, the job has succeeded.
        await asyncio.shield(self._db.call(self._store.save_result, scan_result, now=event.time, event=event))
        self._publish(event)
        # The client has its result: now the recording's share, whose hand-off would delay it.
        _later(self._recorder.reconstruction, active.job_id, arrived, reply_json)
        self._note(event)

    # --- requests ------------------------------------------------------------------------------

    async def _on_submit(self, request: Request) -> Response:
        try:
            scan = parse(ScanRequest, request.payload)
            poses = self._flange_poses(scan)
        except ValueError as exc:
            raise RequestError(str(exc)) from None
        for view, pose in enumerate(poses):
            violation = workspace_violation(pose, self.config.robot.workspace)
            if violation:
                raise RequestError(f"view {view} is outside the workspace: {violation}")
        if scan.request_id is not None:  # submitted before: the same job, even when the queue is full
            known = await self._db.call(self._store.find_request, scan.request_id)
            if known is not None:
                return Response(known.model_dump_json())
        # Submits on their way to the store count: a burst cannot slip past the bound.
        if len(self._queued) + self._submitting >= self.config.max_queued:
            raise RequestError(f"the queue is full ({self.config.max_queued} jobs waiting): try again later")
        self._submitting += 1
        try:
            # Stored for good before the answer: a submitted job survives a crash.
            status, created = await self._db.call(self._store.add, scan, n_views=len(poses), now=self._clock())
        finally:
            self._submitting -= 1
        if created:  # the store added the job's "queued" event with it
            _later(self._publish, queued_event(status))
            self._enqueue(status.job_id, scan, poses)
        return Response(status.model_dump_json())

    async def _on_status(self, request: Request) -> Response:
        try:
            n_failures = int(request.parameters.get("failures", _RECENT_FAILURES))
        except ValueError as exc:
            raise RequestError(f"bad parameters: {exc}") from None
        n_failures = max(0, min(n_failures, 1000))

        def read(store: JobStore) -> tuple[dict[JobState, int], list[JobStatus]]:
            failed = store.list(states={JobState.FAILED}, limit=n_failures) if n_failures else []
            return store.counts(), failed

        counts, failed = await self._db.call(read, self._store)
        status = CellStatus(
            cell=self.cell, time=self._clock(), started=self._started,
            workers={part: part in self._alive for part in ("robot", "camera")},
            reconstructors=self._pool.snapshot(), queued=len(self._queued), max_queued=self.config.max_queued,
            waiting_for_reconstructor=self._pool.waiting,
            jobs={state.value: n for state, n in counts.items()},
            recent_failures=[FailedJob(job_id=s.job_id, error=s.error, updated=s.updated) for s in failed])
        return Response(status.model_dump_json())

    async def _on_list(self, request: Request) -> Response:
        try:
            states = {JobState(s) for s in request.parameters["state"].split(",")} \
                if "state" in request.parameters else None
            limit = int(request.parameters.get("limit", 50))
        except ValueError as exc:
            raise RequestError(f"bad parameters: {exc}") from None
        statuses = await self._db.call(self._store.list, states=states, limit=max(1, min(limit, 1000)))
        return Response("[" + ",".join(s.model_dump_json() for s in statuses) + "]")

    async def _on_job_query(self, request: Request) -> Response:
        parts = request.key.split("/")[3:]  # robocell/<cell>/jobs/<id>[/<what>]
        job_id, what = parts[0], (parts[1] if len(parts) > 1 else "status")
        if what == "cancel":
            return Response((await self._cancel(job_id)).model_dump_json())
        if what not in ("status", "result"):
            raise RequestError(f"unknown job query {what!r}: expected status, result or cancel")
        status = await self._status(job_id)
        if what == "status":
            return Response(status.model_dump_json())
        result = await self._db.call(self._store.result, job_id)
        if result is None:
            raise RequestError(f"job {job_id} has no result: it is {status.state.value}"
                               + (f" ({status.error})" if status.error else ""))
        return Response(result.model_dump_json())

    async def _status(self, job_id: str) -> JobStatus:
        status = await self._db.call(self._store.get, job_id)
        if status is None:
            raise RequestError(f"no job {job_id!r} in cell {self.cell}")
        return status

    async def _cancel(self, job_id: str) -> JobStatus:
        """Cancel the job; the status returned is "cancelled" unless the job ended first."""
        if job_id in self._queued:  # the lane will skip it
            del self._queued[job_id]
            self._set(job_id, JobState.CANCELLED, "cancelled by request")
            return await self._status(job_id)
        active = self._active.get(job_id)
        if active is None:
            status = await self._status(job_id)
            if status.state is JobState.CANCELLED:
                return status
            raise RequestError(f"job {job_id} already {status.state.value}: nothing to cancel")
        task = active.task
        if not active.finishing:
            active.cancel_requested = True
            if task is not None:
                task.cancel()
        if task is not None:
            # A step may be ending right now: let it notice the flag (bounded: the caller waits).
            await asyncio.wait({task}, timeout=_CANCEL_WAIT_S)
        return await self._status(job_id)
