"""The cell daemon: the wiring of the jobs, the workers, the store and the recordings.

A job (``cell.job``) runs the steps of its plan (``cell.steps``) in order, in a task
of its own from the moment it is accepted. Steps that need the robot and its camera
run in the motion lane (``cell.lane``), one job at a time, in the order the jobs came;
the others (the reconstruction) outside it, so that job k's reconstruction overlaps
job k+1's motion. Every change of a job goes through its handle (``cell.handle``):
into the store (``cell.store``; its syncs in a thread), then to its listeners (a
JobEvent, put by ``cell.publisher``), then into its Rerun recording (written by a
process of its own: ``cell.recorder``); the handle's table says what is synced first.

Reconstructions go to the pool of reconstruction workers that every cell on the
network shares (``cell.pool``); clients' queries are answered by ``cell.requests``.

After a crash, the restarted daemon carries every accepted job on from its checkpoint
(its plan so far, the steps done, ``cell.job.Checkpoint``) with the pictures the store kept;
a job whose pick had begun fails instead (the gripper may hold the
object), and a job being cancelled is cancelled.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import numpy as np

from robocell.wire import keys
from robocell.wire.config import CellConfig
from robocell.wire.errors import CellError, ConfigError, StoreError
from robocell.wire.messages import REQUEST_LIMITS, JobEvent, JobState, JobStatus, Lifecycle, Progress, ScanRequest
from robocell.wire.transport import BaseTransport

from .asking import Asker
from .upkeep import apply_retention_every
from .handle import JobHandle, stored_when_taken
from .job import Checkpoint, Job, Picture, success_message
from .lane import MotionLane
from .lock import RunDirLock
from .pool import ReconstructorPool
from .presence import Presence
from .publisher import Publisher
from .recorder import Recorder
from .backgrounds import Backgrounds
from .plan import flange_poses, job_steps, next_view_candidates, resume
from .requests import RequestHandlers
from .reserve import release_if_full
from .steps import Step, StepFailed, View
from .store import JobStore, queued_event

__all__ = ["CellDaemon", "MAX_PLAN_STEPS"]

log = logging.getLogger(__name__)
_ALIVE_QUERY_S = 2.0        # how long to ask the router whether this cell has a daemon already
_STORE_BUSY_S = 1.0         # how long a write waits for the store's lock
#: How long a success waits for the recorder to close its recording and say whether it is whole.
RECORDING_VERDICT_S = 20.0
#: The most steps a job's plan may grow to: past it, the job ends with what it has, and says so.
MAX_PLAN_STEPS = 64


class CellDaemon(RequestHandlers):
    """Runs the jobs of one cell. Create, then ``await run(stop)``; the job store is ``store_path``
    (default ``<run dir>/jobs.sqlite``), opened by ``run`` in the store's own thread."""

    def __init__(self, config: CellConfig, transport: BaseTransport, *, store_path: Path | None = None,
                 clock: Callable[[], float] = time.time, view: str | None = None) -> None:
        self.config = config
        self.cell = config.cell_id
        self.run_dir = Path(config.run_dir)
        self.clock = clock
        self._store_path = store_path or self.run_dir / "jobs.sqlite"
        self._transport = transport
        self._store: JobStore | None = None
        # ``view``: a Rerun viewer's gRPC URL that every job is streamed to as well (``robocell cell --view``).
        self._recorder = Recorder(n_points=config.reconstruct.n_points, live=view)
        self._live: dict[str, JobHandle] = {}   # the jobs not yet ended, in the order they came
        self._presence = Presence(transport, self.cell)
        self._asker = Asker(transport, self._presence, config.timeouts.outage_s, self.note)
        self.ask, self.wait_link = self._asker.ask, self._asker.wait_link
        self._publisher = Publisher(transport)
        self._lane = MotionLane()
        self.pool = ReconstructorPool(transport, heartbeat_s=config.timeouts.heartbeat_s)
        self.backgrounds = Backgrounds(self.run_dir)
        self._background: set[asyncio.Task[Any]] = set()
        self._started = clock()

    @property
    def _jobs(self) -> JobStore:
        assert self._store is not None, "run() opens the store"
        return self._store

    # --- lifecycle -------------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event) -> None:
        """Serve until ``stop`` is set.

        Raises
        ------
        CellError
            Before it touches anything, if the run directory cannot be made, another daemon holds
            it (``RunDirBusy``), another daemon of this cell id is on the router, or the job
            store cannot be opened (``StoreError``: missing, damaged, of a newer version).
        """
        try:
            self.run_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"cannot make the run directory {self.run_dir}: {exc.strerror or exc}") from None
        lock = RunDirLock(self.run_dir)
        lock.acquire()
        try:
            await self._refuse_a_second_daemon()
            release_if_full(self.run_dir)  # on a full disk, the room kept to open the store (cell.reserve)
            self._store = JobStore(self._store_path, timeout=_STORE_BUSY_S)  # a lock held long is a fault
            self._recorder.start()
            self._publisher.start()
            try:
                await self._recover()
                await self._serve(stop)
            finally:
                await asyncio.to_thread(self._recorder.stop)  # it closes the recordings still open
                self._jobs.close()
                await asyncio.to_thread(self._publisher.close)
        finally:
            lock.release()

    async def _refuse_a_second_daemon(self) -> None:
        found = await self._transport.alive(keys.alive(self.cell, "daemon"), timeout=_ALIVE_QUERY_S)
        if found:
            raise CellError(f"a daemon of cell {self.cell} is already running on the router at "
                            f"{self._transport.endpoint}: stop it, or give this cell another cell_id")

    async def _serve(self, stop: asyncio.Event) -> None:
        transport, cell = self._transport, self.cell
        self._spawn(self._presence.follow())
        self._spawn(apply_retention_every(self.run_dir, self._jobs, self.config.retention, active=self._live.keys,
                                          clock=self.clock))
        self.pool.start()
        # Each request's size is checked before it is read: a 50 MB submit is refused unparsed.
        transport.serve(keys.submit(cell), self._on_submit, limit=REQUEST_LIMITS["submit"])
        transport.serve(keys.jobs(cell), self._on_list, limit=REQUEST_LIMITS["query"])
        transport.serve(keys.status(cell), self._on_status, limit=REQUEST_LIMITS["query"])
        # Not "jobs/**": that matches "jobs" too, and a list query would get a second, wrong answer.
        transport.serve(keys.job(cell, "*"), self._on_job_query, limit=REQUEST_LIMITS["query"])
        transport.serve(f"{keys.job(cell, '*')}/*", self._on_job_query, limit=REQUEST_LIMITS["cancel"])
        transport.declare_token(keys.alive(cell, "daemon"))
        log.info("cell %s ready: run directory %s", cell, self.run_dir.resolve())
        try:
            await stop.wait()
        finally:
            for task in list(self._background):
                task.cancel()
            await asyncio.gather(*self._background, return_exceptions=True)
            await self.pool.close()

    def _spawn(self, coroutine: Coroutine[Any, Any, Any]) -> asyncio.Task[Any]:
        task = asyncio.create_task(coroutine)
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        return task

    async def _recover(self) -> None:
        """After a restart every accepted job is carried on from its checkpoint, in the order they came."""
        for status in self._jobs.unfinished():
            raw = self._jobs.checkpoint(status.job_id)
            job = Job(status.job_id, status.request, [], lifecycle=status.lifecycle, progress=status.progress)
            handle = self._live[job.job_id] = JobHandle(job, self, self.clock)
            end = resume(job, raw, lambda: job_steps(job.request, self._flange_poses(job.request)))
            if end is not None:
                message, to, kind = end
                await handle.change(message, lifecycle=to, error_kind=kind)
                continue
            n_pictures = sum(isinstance(step, View) for step in job.plan[:job.done])
            kept = self._jobs.pictures(job.job_id)
            try:
                pictures = [Picture.kept(jpeg, poses) for jpeg, poses in kept[:n_pictures]]
            except ValueError:
                pictures = []
            if len(pictures) < n_pictures:  # not all of them kept: from the first view again
                job.done, pictures = 0, []
            job.captures = pictures
            self._launch(handle)
            if job.lifecycle is Lifecycle.RUNNING:
                log.warning("job %s: the daemon restarted: carrying it on from step %d", job.job_id, job.done)
                await handle.change(f"the daemon restarted: carrying on from step {job.done + 1} of "
                                    f"{len(job.plan)}, with {len(pictures)} pictures kept")
            for view, picture in enumerate(pictures):
                self.record(job, "log_view", view, picture.jpeg, self.config.camera.K, picture.T_base_cam,
                            self.config.camera.resolution)

    def _launch(self, handle: JobHandle) -> None:
        """The job's recording opened, its steps run in a task of their own (a stopping daemon cancels it)."""
        job = handle.job
        job.started = self.clock()
        path = self.run_dir / f"{job.job_id}.rrd"
        try:
            with open(path, "ab"):
                pass
        except OSError as exc:
            job.recording_error = f"the recording {path} cannot be written: {exc.strerror or exc}"
            log.warning("job %s: %s", job.job_id, job.recording_error)
        else:
            self._recorder.open(job.job_id, path)
        job.task = self._spawn(self._run(handle))

    def _admit(self, status: JobStatus, request: ScanRequest, plan: list[Step]) -> None:
        """A job the store has taken: its handle made, its steps started, its first event told."""
        handle = self._live[status.job_id] = JobHandle(Job(status.job_id, request, plan), self, self.clock)
        self._launch(handle)
        handle.accepted(queued_event(status))

    def _queued(self) -> int:
        return sum(handle.job.lifecycle is Lifecycle.QUEUED for handle in self._live.values())

    # --- what steps use (cell.steps.Cell) -------------------------------------------------------

    def record(self, job: Job, method: str, *args: object) -> None:
        self._recorder.call(job.job_id, self.clock() - job.started, method, *args)

    def record_reconstruction(self, job: Job, reply_json: bytes, payload: bytes) -> None:
        self._recorder.reconstruction(job.job_id, self.clock() - job.started, reply_json.decode(), payload)

    async def note(self, job: Job, message: str, *, level: int = logging.WARNING) -> None:
        log.log(level, "job %s: %s", job.job_id, message)
        await self._live[job.job_id].change(message)

    async def doing(self, job: Job, activity: JobState, doing: str) -> None:
        assert job.progress is not None, "a step runs"
        await self._live[job.job_id].change(doing, progress=job.progress.model_copy(
            update={"activity": activity, "doing": doing}))

    async def keep(self, job: Job, picture: Picture) -> None:
        self._jobs.keep_picture(job.job_id, len(job.captures), picture.jpeg, picture.poses())

    def candidates(self, job: Job) -> list[np.ndarray]:
        return next_view_candidates(job, self.config)

    # --- what a job's handle uses (cell.handle.Books) ------------------------------------------

    async def store(self, event: JobEvent, *, sync: bool, error_kind: str | None,
                    checkpoint: Checkpoint | None) -> None:
        n_views = None if checkpoint is None else sum(spec["kind"] == View.kind for spec in checkpoint.plan)
        await stored_when_taken(self._jobs, event, error_kind=error_kind, n_views=n_views,
                                checkpoint=checkpoint.model_dump_json() if checkpoint else None)
        if sync:
            await asyncio.to_thread(self._jobs.sync)

    def publish(self, event: JobEvent) -> None:
        self._publisher.put(keys.events(self.cell, event.job_id), event.model_dump_json())

    def record_event(self, job: Job, event: JobEvent) -> None:
        level = "ERROR" if event.lifecycle is Lifecycle.FAILED else "INFO"
        at = event.time - job.started
        # (A success's recording was drawn to its end and closed before it was told: _finish_recording.)
        self._recorder.call(job.job_id, at, "log_text", f"{event.state.value}: {event.message}", level)
        if event.lifecycle.finished:
            self._recorder.close(job.job_id)

    def _flange_poses(self, request: ScanRequest) -> list[np.ndarray]:
        return flange_poses(request, self.config)

    # --- running jobs --------------------------------------------------------------------------

    async def _run(self, handle: JobHandle) -> None:
        """Run the job's plan: the steps that need the robot in the lane, in runs of consecutive ones."""
        job, first = handle.job, True
        try:
            while job.done < len(job.plan):
                if not job.plan[job.done].needs_robot:
                    await self._step(handle)
                    continue
                async with self._lane.hold(urgent=not first):  # a job under way goes first
                    first = False
                    while job.done < len(job.plan) and job.plan[job.done].needs_robot:
                        await self._step(handle)
            await self._succeed(handle)
        except asyncio.CancelledError:
            if job.lifecycle is Lifecycle.CANCELLING:
                await handle.change("cancelled by request", lifecycle=Lifecycle.CANCELLED)
            elif not job.lifecycle.finished:
                raise  # the daemon is stopping: the restart carries the job on
        except StepFailed as exc:
            await self._fail(handle, f"{_label(job)}: {exc}", exc.kind)
        except StoreError as exc:  # nobody was told of what the store did not take
            log.error("job %s: the store cannot keep it (%s): the restarted daemon carries it on", job.job_id, exc)
        except Exception as exc:  # a bug must not leave the job hanging, nor stop the lane
            log.exception("job %s: %s failed", job.job_id, _label(job))
            await self._fail(handle, f"{_label(job)}: internal error: {type(exc).__name__}: {exc}",
                             "InternalError")
        finally:
            self._live.pop(job.job_id, None)

    async def _step(self, handle: JobHandle) -> None:
        """Run the job's next step, and put the steps it asks for next in the plan."""
        job = handle.job
        if job.lifecycle is Lifecycle.CANCELLING:  # a cancel that came as the last step ended
            raise asyncio.CancelledError
        index = job.done
        step = job.plan[index]
        progress = Progress(activity=step.activity, doing=step.describe(), view=step.view, step=index,
                            steps=len(job.plan))
        await handle.change(step.describe(), progress=progress, checkpoint=True,
                            lifecycle=Lifecycle.RUNNING if job.lifecycle is Lifecycle.QUEUED else None)
        grown = await step.run(job, self)
        job.done = index + 1
        if grown and len(job.plan) + len(grown) > MAX_PLAN_STEPS:
            await self.note(job, f"{step.describe()} asked for {len(grown)} more steps, past the plan's cap of "
                                 f"{MAX_PLAN_STEPS}: the job ends with what it has")
        elif grown:
            job.plan[job.done:job.done] = grown
        if job.lifecycle is Lifecycle.CANCELLING:
            raise asyncio.CancelledError

    async def _fail(self, handle: JobHandle, error: str, kind: str | None) -> None:
        log.warning("job %s failed: %s", handle.job.job_id, error)
        if handle.job.lifecycle is Lifecycle.CANCELLING:  # it was stopping anyway
            await handle.change(f"cancelled by request ({error})", lifecycle=Lifecycle.CANCELLED)
        else:
            await handle.change(error, lifecycle=Lifecycle.FAILED, error_kind=kind)

    async def _succeed(self, handle: JobHandle) -> None:
        job, result = handle.job, handle.job.result
        if job.request.kind == "backgrounds":  # no model: the pictures kept are what it made
            await handle.change(f"kept {len(job.captures)} backgrounds of the empty workspace in "
                                f"{self.backgrounds.root}", lifecycle=Lifecycle.SUCCEEDED)
            return
        if result is None:
            raise StepFailed("the plan ended without a result")
        message = success_message(result)
        job.recording_error = job.recording_error or await self._finish_recording(job, message)
        if job.recording_error is None:
            result.recording = str(self.run_dir / f"{job.job_id}.rrd")
        result.recording_error = job.recording_error
        await handle.change(message, lifecycle=Lifecycle.SUCCEEDED, result=result)

    async def _finish_recording(self, job: Job, message: str) -> str | None:
        """A success's recording closed before the success is told, so that its result names a
        recording that could not be written, or whose recorder died (issue 23): what is wrong with
        it, or None. The success's own line comes before its event is stored, here."""
        self.record(job, "log_text", f"{Lifecycle.SUCCEEDED.value}: {message}", "INFO")
        return await self._recorder.verdict(job.job_id, self.run_dir / f"{job.job_id}.rrd", RECORDING_VERDICT_S)


def _label(job: Job) -> str:
    """What the job was doing, in its error: "<what>: <reason>"."""
    return job.progress.doing if job.progress is not None else "starting"
