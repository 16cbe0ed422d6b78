"""The cell daemon: the wiring of the jobs, the workers, the store and the recordings.

A job is a state machine (``cell.job``) that runs its steps (``cell.steps``) in
order. Steps that need the robot and its camera run in the motion lane
(``cell.lane``), one job at a time; the others (the reconstruction) outside it,
so that job k's reconstruction overlaps job k+1's motion. Every transition is
stored (``cell.store``, in its own thread, in order: ``cell.executor``),
published as a JobEvent and written to the job's Rerun recording
(``cell.journal``, by a process of its own: ``cell.recorder``).

Reconstructions go to the pool of reconstruction workers that every cell on the
network shares (``cell.pool``), each to the least loaded live worker; an attempt
whose worker dies, hangs, runs out of time or answers an error is made again on
another, up to ``reconstruct.max_attempts`` attempts.

What must outlive a crash is awaited before anyone hears of it: a job is on disk
before its submit is answered (it may start meanwhile), a job's failure or cancel before
its event is published. What a restart can redo is not waited for: a step's state, and a
success (the job stays reconstructing on disk, its pictures kept, until the result is
stored behind the event); those writes wait for the next slow wait of a job, so that the
store's thread does not compete with the round trips of instant moves (``cell.executor``).
A step's bookkeeping is done once its query to the worker is on its way; what the
event loop remembers of the jobs (the queue, the jobs in flight) is what its
decisions need, so no decision waits for the store. After a crash, the restarted
daemon carries every accepted job on to its end: a job whose pictures were all taken resumes its
reconstruction from them (``cell.pictures``), a job caught during its views takes them again.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from collections import OrderedDict
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import numpy as np

from core_cy.plan import plan_flange_poses, workspace_violation
from wire import keys
from wire.config import CellConfig
from wire.errors import (CameraConnectionError, CameraError, CameraTimeout, CellError, ConfigError, LinkDown,
                         NoResponder, RemoteError, StoreError, TransportError, TransportTimeout, wire_kind)
from wire.messages import CellStatus, FailedJob, JobEvent, JobState, JobStatus, Message, ScanRequest, parse
from wire.transport import Reply, Request, RequestError, Response, Transport

from .executor import Serial, later
from .job import IllegalTransition, Job
from .journal import Journal
from .lane import MotionLane
from .lock import RunDirLock
from .pool import ReconstructorPool
from .presence import Absent, Presence
from .recorder import Recorder
from .pictures import Pictures
from .publisher import Publisher
from .steps import Step, StepFailed, job_steps
from .store import JobStore, job_id_for, queued_event, queued_status

__all__ = ["CellDaemon"]

log = logging.getLogger(__name__)
_CANCEL_WAIT_S = 2.0
_RETRY_S = 0.5              # between two tries of a step whose part is away
_ALIVE_QUERY_S = 2.0        # how long to ask the router whether this cell has a daemon already
_RECENT_FAILURES = 10       # failed jobs in a status answer, unless asked for another number
_RECENT_RESULTS = 100       # results kept in memory to answer at once
_QUIET_S = 0.2              # what a job records waits at most this long for a slow wait (see _start)
_HEAD_START_S = 0.002       # a slow wait's bookkeeping starts this long after its query (see hand_over)
_VIEW_STEPS = frozenset({JobState.MOVING, JobState.CAPTURING})  # written at the next slow wait
_REQUEST_IDS = 10_000       # request_ids of this run's jobs kept in memory (older ones: the store finds them)


class CellDaemon:
    """Runs the jobs of one cell. Create, then ``await run(stop)``.

    The job store is ``store_path`` (default ``<run dir>/jobs.sqlite``), opened
    by ``run`` in the store's own thread.
    """

    def __init__(self, config: CellConfig, transport: Transport, *, store_path: Path | None = None,
                 clock: Callable[[], float] = time.time) -> None:
        self.config = config
        self.cell = config.cell_id
        self.run_dir = Path(config.run_dir)
        self.clock = clock
        self._store_path = store_path or self.run_dir / "jobs.sqlite"
        self._transport = transport
        self._store: JobStore | None = None     # used in the store thread only
        self._db = Serial("job-store")
        self._recorder = Recorder(n_points=config.reconstruct.n_points,
                                  sim=config.sim.model_dump() if config.robot.backend == "sim" else None)
        self._queue: asyncio.Queue[str] = asyncio.Queue()
        self._queued: dict[str, Job] = {}           # waiting jobs, in order
        self._active: dict[str, Job] = {}           # jobs whose steps run
        # The latest results, as JSON: a client asks for a result as soon as it hears of it, and
        # gets it without a trip through the store's thread.
        self._recent_results: OrderedDict[str, str] = OrderedDict()
        self._journals: dict[str, Journal] = {}     # the recordings of the active jobs
        self._ended_journals: list[Journal] = []    # of jobs that ended, not yet handed over
        self._pictures = Pictures(self.run_dir)     # used in the store's thread
        self._presence = Presence(transport, self.cell)
        self._publisher = Publisher(transport)
        self._lane = MotionLane()
        self.pool = ReconstructorPool(transport, heartbeat_s=config.timeouts.heartbeat_s)
        self._background: set[asyncio.Task[Any]] = set()
        self._last_seq = 0                          # the number of the latest job (see run())
        # The jobs submitted with a request_id in this run, newest last: a second submit of a request
        # finds its job here even before the store has it.
        self._request_ids: OrderedDict[str, str] = OrderedDict()
        self._started = clock()

    @property
    def _jobs(self) -> JobStore:
        """The job store, to be called in its own thread (``self._db``)."""
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
            self._store = await self._db.call(JobStore, self._store_path)
            self._last_seq = await self._db.call(self._jobs.last_seq)
            self._recorder.start()
            self._publisher.start()
            try:
                await self._recover()
                await self._serve(stop)
            finally:
                await asyncio.sleep(0)  # what is handed over later goes out first
                await asyncio.to_thread(self._recorder.stop)  # it closes the recordings still open
                await self._db.call(self._jobs.close)
                await asyncio.sleep(0)  # the events published once stored, to the publisher
                await asyncio.to_thread(self._publisher.close)
        finally:
            await asyncio.to_thread(self._db.close)
            lock.release()

    async def _refuse_a_second_daemon(self) -> None:
        found = await self._transport.alive(keys.alive(self.cell, "daemon"), timeout=_ALIVE_QUERY_S)
        if found:
            raise CellError(f"a daemon of cell {self.cell} is already running on the router at "
                            f"{self._transport.endpoint}: stop it, or give this cell another cell_id")

    async def _serve(self, stop: asyncio.Event) -> None:
        transport, cell = self._transport, self.cell
        self._spawn(self._presence.follow())
        self.pool.start()
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
            await self.pool.close()
            for journal in self._journals.values():  # jobs cut short keep what they recorded
                journal.hand_over()
            self._catch_up()

    def _spawn(self, coroutine: Coroutine[Any, Any, Any]) -> asyncio.Task[Any]:
        task = asyncio.create_task(coroutine)
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        return task

    async def _recover(self) -> None:
        """After a restart every accepted job is carried on to its end: a job whose pictures were all
        taken resumes its reconstruction from them; a job caught before takes its views again, in
        its turn; a job being cancelled is cancelled; queued jobs run, in order."""
        unfinished = await self._db.call(self._jobs.unfinished)
        for status in unfinished:
            job = Job(status.job_id, status.request, [], state=status.state, view=status.view)
            pictures = None
            if status.state is JobState.RECONSTRUCTING:
                pictures = await self._db.call(self._pictures.load, job.job_id, status.n_views)
            try:
                job.poses = self._flange_poses(status.request)
            except ValueError as exc:  # the configuration changed under it
                if job.state is JobState.CANCELLING:
                    self._transition(job, JobState.CANCELLED, "cancelled by request (before the daemon restarted)")
                else:
                    self._transition(job, JobState.FAILED, f"planning: {exc}", error=StepFailed(str(exc)))
                continue
            if job.state is JobState.CANCELLING:
                self._transition(job, JobState.CANCELLED, "cancelled by request (before the daemon restarted)")
            elif job.state is JobState.PICKING:  # the gripper may hold it, wherever the arm stopped
                self._transition(job, JobState.FAILED, "picking: the daemon stopped during the pick: the gripper may "
                                 "still hold the object; not picked again", error=StepFailed("", kind="PickInterrupted"))
            elif pictures is not None:
                log.warning("job %s: the daemon restarted during its reconstruction: resuming it", job.job_id)
                job.captures = pictures
                self._start(job, job_steps(job.request, len(pictures))[2 * len(pictures):], resumed=True)
            else:
                if job.state is not JobState.QUEUED:
                    log.warning("job %s: the daemon restarted during its views: taking them again", job.job_id)
                    self._transition(job, JobState.QUEUED, "the daemon restarted: its views are taken again")
                self._enqueue(job)

    def _enqueue(self, job: Job) -> None:
        self._queued[job.job_id] = job
        self._queue.put_nowait(job.job_id)

    # --- what steps use (cell.steps.Cell) -------------------------------------------------------

    async def ask(self, job: Job, part: str, key: str, message: Message, timeout: float) -> Reply:
        loop = asyncio.get_running_loop()
        allowance = self.config.timeouts.outage_s
        deadline = loop.time() + allowance
        away: str | None = None     # why the last try did not get through
        while True:
            remaining = max(0.0, deadline - loop.time())
            kind: str | None = None
            try:
                await self._transport.wait_link(remaining)
                await self._presence.wait_for(part, remaining)
                return await self._transport.query(key, message.model_dump_json(), timeout=timeout)
            except LinkDown:
                reason, kind = "the link to the Zenoh router is down", "LinkDown"
            except Absent:
                raise StepFailed(f"no {part} worker is running (waited {allowance:g} s)") from None
            except NoResponder:
                reason, kind = f"the {part} worker is gone", "NoResponder"
            except TransportTimeout as exc:
                raise StepFailed(f"{part}: no answer: {exc}", kind="TransportTimeout") from None
            except RemoteError as exc:  # the worker's own message names the part and the reason
                raise StepFailed(str(exc), kind=exc.kind) from None
            except TransportError as exc:
                raise StepFailed(f"{part}: {exc}") from None
            except CellError as exc:  # an error of a kind both sides know: a refused move, say
                if not _briefly_away(exc):
                    raise StepFailed(str(exc), kind=wire_kind(exc)[0]) from None
                reason, kind = str(exc), wire_kind(exc)[0]
            if loop.time() >= deadline:
                raise StepFailed(f"{reason} (waited {allowance:g} s for it)", kind=kind)
            if reason != away:  # once for each reason, not at every try
                away = reason
                self.note(job, f"{reason}: waiting up to {allowance:g} s, then trying again")
            await asyncio.sleep(min(_RETRY_S, max(0.0, deadline - loop.time())))

    async def wait_link(self, job: Job) -> None:
        allowance = self.config.timeouts.outage_s
        if not self._transport.link_up:
            self.note(job, f"the link to the Zenoh router is down: waiting up to {allowance:g} s")
        try:
            await self._transport.wait_link(allowance)
        except LinkDown as exc:
            raise StepFailed(str(exc), kind="LinkDown") from None

    def record(self, job: Job, method: str, *args: object) -> None:
        self._journals[job.job_id].record(method, *args)

    def hand_over(self, job: Job) -> None:
        # A moment into the wait, not at once: the bookkeeping would compete with the messages that
        # start the worker's slow part (the camera worker first asks the robot where it stands).
        asyncio.get_running_loop().call_later(_HEAD_START_S, self._hand_over_now, job.job_id)

    def _hand_over_now(self, job_id: str) -> None:
        self._hand_over_journal(job_id)
        self._catch_up()

    def _hand_over_journal(self, job_id: str) -> None:
        """The job's recording messages, its recording's opening first, to the recorder; not those
        of an ended job, which wait for a quiet moment (``_catch_up``)."""
        journal = self._journals.get(job_id)
        if journal is not None:
            journal.hand_over()

    def _catch_up(self) -> None:
        """The store's deferred writes, and the recordings of ended jobs (see ``cell.journal``), to
        their threads: the cell waits for something slow, or has been quiet a moment."""
        self._db.flush()
        for journal in self._ended_journals:
            journal.hand_over()
        self._ended_journals.clear()

    def note(self, job: Job, message: str) -> None:
        log.warning("job %s: %s", job.job_id, message)
        self._keep(job, job.note(message, now=self.clock()))

    # --- job state -----------------------------------------------------------------------------

    def _keep(self, job: Job, event: JobEvent) -> None:
        """An event that changes no state: recorded, stored (not waited for), published."""
        self._write_down(job, event)
        self._db.post(self._jobs.add_event, event, durable=False, then=functools.partial(self._publish, event))

    def _transition(self, job: Job, to: JobState, message: str, *, view: int | None = None,
                    error: StepFailed | None = None) -> JobEvent:
        """Move ``job`` to ``to`` (see ``cell.job.TRANSITIONS``): recorded, stored, published.

        The store is written in its thread, in order, without waiting. A step's event is
        published at once; the end of a job only once the store has it.
        """
        event = job.transition(to, message, view=view, now=self.clock())
        self._write_down(job, event)
        published = functools.partial(self._publish, event)
        if to is JobState.RECONSTRUCTING and job.captures:
            # Kept before the job is stored as reconstructing: a restarted daemon resumes from them.
            self._db.post(self._pictures.save, job.job_id, list(job.captures))
        elif to.finished:
            self._db.post(self._pictures.drop, job.job_id)
        durable = to.finished or to is JobState.RECONSTRUCTING
        # A view's step waits for the job's next slow wait, or a reader (cell.executor): a restart
        # that finds it a step behind takes the views again anyway. A pick's does not wait (and
        # its first step's is on disk before it runs: Step.stored_first).
        write = self._db.defer if to in _VIEW_STEPS else self._db.post
        write(self._jobs.update, job.job_id, to, view=view, now=event.time, event=event,
              error=None if error is None else message, error_kind=None if error is None else error.kind,
              durable=durable, then=published if to.finished else None)
        if not to.finished:
            later(self._publish, event)
        return event

    def _write_down(self, job: Job, event: JobEvent) -> None:
        """The event in the job's recording; a finished job's recording is closed."""
        journal = self._journals.get(job.job_id)
        if journal is None:
            return
        level = "ERROR" if event.state is JobState.FAILED else "INFO"
        journal.record("log_text", f"{event.state.value}: {event.message}", level)
        if event.state.finished:
            del self._journals[job.job_id]
            self._active.pop(job.job_id, None)
            journal.close()
            # Handed over at the next slow wait of a job, or once the cell has been quiet a moment:
            # the recorder's work on it would otherwise compete with the next job's first moves.
            self._ended_journals.append(journal)
            asyncio.get_running_loop().call_later(_QUIET_S, self._catch_up)

    def _publish(self, event: JobEvent) -> None:
        self._publisher.put(keys.events(self.cell, event.job_id), event.model_dump_json())

    def _recording_path(self, job_id: str) -> Path:
        return self.run_dir / f"{job_id}.rrd"

    def _check_recording(self, job: Job, path: Path) -> None:
        """In the store's thread: can the job's recording be written? The job's status names the
        file only if it can (the recorder, a process of its own, cannot say so in time)."""
        try:
            with open(path, "ab"):
                pass
        except OSError as exc:
            job.recording_error = f"the recording {path} cannot be written: {exc.strerror or exc}"
            log.warning("job %s: %s", job.job_id, job.recording_error)
            return
        self._jobs.set_recording(job.job_id, str(path))

    def _flange_poses(self, request: ScanRequest) -> list[np.ndarray]:
        if request.flange_poses is not None:
            return [np.asarray(pose, dtype=np.float64) for pose in request.flange_poses]
        plan = request.plan or self.config.scan.plan
        return plan_flange_poses(request.target, plan, self.config.T_flange_cam)

    # --- running jobs --------------------------------------------------------------------------

    async def _motion_lane(self) -> None:
        """Start the queued jobs one after the other, each once the one before has left the lane."""
        while True:
            job_id = await self._queue.get()
            job = self._queued.pop(job_id, None)
            if job is None:
                continue  # cancelled while it waited
            # Set by the job however it ends, so a cancelled job does not stop the lane.
            await self._start(job, job_steps(job.request, len(job.poses))).wait()

    def _start(self, job: Job, steps: list[Step], *, resumed: bool = False) -> asyncio.Event:
        """Run the job's steps in a task of its own (a stopping daemon cancels it); the event is
        set once the job has no more use for the lane until further notice."""
        job.started = self.clock()
        self._active[job.job_id] = job
        path = self._recording_path(job.job_id)
        checked: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        job.recording_checked = checked
        self._db.defer(self._check_recording, job, path, then=functools.partial(checked.set_result, None))
        journal = Journal(self._recorder, job.job_id, path, started=job.started, clock=self.clock)
        self._journals[job.job_id] = journal
        # The recording opens at the job's first slow wait (cell.journal); a job whose first move is
        # a real robot's, seconds long, has it opened meanwhile, so that a daemon killed then leaves one.
        asyncio.get_running_loop().call_later(_QUIET_S, self._hand_over_journal, job.job_id)
        if resumed:  # the recording starts again: the pictures first
            for view, picture in enumerate(job.captures):
                journal.record("log_view", view, picture.jpeg, self.config.camera.K, picture.T_base_cam,
                               self.config.camera.resolution)
        left_lane = asyncio.Event()
        job.task = self._spawn(self._run(job, steps, left_lane))
        return left_lane

    async def _run(self, job: Job, steps: list[Step], left_lane: asyncio.Event) -> None:
        """Run the job's steps: those that need the robot in the lane, in runs of consecutive ones."""
        step: Step | None = None
        try:
            index, first_run = 0, True
            while index < len(steps):
                end = index
                while end < len(steps) and steps[end].needs_robot == steps[index].needs_robot:
                    end += 1
                if steps[index].needs_robot:
                    async with self._lane.hold(urgent=not first_run):
                        for step in steps[index:end]:
                            await self._step(job, step)
                    first_run = False
                else:
                    left_lane.set()
                    for step in steps[index:end]:
                        await self._step(job, step)
                index = end
            left_lane.set()
            await self._succeed(job)
        except asyncio.CancelledError:
            left_lane.set()
            if job.state is not JobState.CANCELLING:
                raise  # the daemon is stopping: the restart will deal with the job
            self._transition(job, JobState.CANCELLED, "cancelled by request")
        except StepFailed as exc:
            self._fail(job, f"{step.label() if step else 'starting'}: {exc}", exc)
        except Exception as exc:  # a bug must not leave the job hanging, nor stop the lane
            log.exception("job %s: %s failed", job.job_id, step.label() if step else "starting")
            self._fail(job, f"{step.label() if step else 'starting'}: internal error: {type(exc).__name__}: {exc}",
                       StepFailed(str(exc), kind="InternalError"))
        finally:
            left_lane.set()

    async def _step(self, job: Job, step: Step) -> None:
        if job.state is JobState.CANCELLING:  # a cancel that came as the last step ended
            raise asyncio.CancelledError
        self._transition(job, step.state, step.describe(), view=step.view)
        if step.stored_first:
            await self._db.call(self._jobs.sync)
        await step.run(job, self)
        if job.state is JobState.CANCELLING:
            raise asyncio.CancelledError

    def _fail(self, job: Job, error: str, cause: StepFailed) -> None:
        log.warning("job %s failed: %s", job.job_id, error)
        if job.state is JobState.CANCELLING:  # it was stopping anyway
            self._transition(job, JobState.CANCELLED, f"cancelled by request ({error})")
        else:
            self._transition(job, JobState.FAILED, error, error=cause)

    async def _succeed(self, job: Job) -> None:
        result = job.result
        assert result is not None, "the last step leaves the result"
        total = result.timings_ms.get("total", float("nan"))
        attempt = f" (attempt {result.attempts})" if result.attempts > 1 else ""
        message = f"reconstructed by {result.worker} in {total:.1f} ms{attempt}"
        if result.pick is not None:
            held = {True: "held", False: "missed", None: "closed on it"}[result.pick.held]
            message += f"; picked with grasp {result.pick.grasp}: {held}" + (", placed" if result.pick.placed else "")
        if job.recording_checked is not None:  # tried at the job's start, so long done
            await asyncio.shield(job.recording_checked)
        if job.recording_error is None:
            result.recording = str(self._recording_path(job.job_id))
        else:
            result.recording_error = job.recording_error
        event = job.transition(JobState.SUCCEEDED, message, now=self.clock(), result=result)
        self._recent_results[job.job_id] = result.model_dump_json()
        if len(self._recent_results) > _RECENT_RESULTS:
            self._recent_results.popitem(last=False)
        # Published, then stored without waiting: a success is not worth a wait for the disk or
        # the store's thread, and its writes wait for the next job's slow wait (the next job's first
        # moves come at once). If the daemon dies before, the job is still reconstructing in the
        # store, with its pictures kept, and the restarted daemon reconstructs it again. Whoever
        # asks the store after hearing the event asks behind the save (a read flushes what waits).
        self._db.defer(self._jobs.save_result, result, now=event.time, event=event, durable=False)
        self._db.defer(self._pictures.drop, job.job_id)
        self._publish(event)
        if job.reconstruction is not None and job.job_id in self._journals:
            reply, payload, at = job.reconstruction
            self._journals[job.job_id].reconstruction(reply.decode(), payload, at=at)
        self._write_down(job, event)

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
        if scan.pick is not None and scan.pick.place is not None:  # the poses wait for the grasp; the spot need not
            workspace = self.config.robot.workspace
            for axis, (value, low, high) in enumerate(zip(scan.pick.place, workspace.min, workspace.max)):
                if not low <= value <= high:
                    raise RequestError(f"pick.place: {'xy'[axis]} = {value:g} m is outside the workspace's "
                                       f"{low:g} to {high:g} m")
        if scan.request_id is not None:  # submitted before: the same job, even when the queue is full
            known = await self._known_request(scan.request_id)
            if known is not None:
                await self._db.call(self._jobs.sync)
                return Response(known.model_dump_json())
        if len(self._queued) >= self.config.max_queued:
            raise RequestError(f"the queue is full ({self.config.max_queued} jobs waiting): try again later")
        # Numbered here, not by the store: the job starts now, while the store's thread writes it.
        seq, now = self._last_seq + 1, self.clock()
        self._last_seq = seq
        status = queued_status(job_id_for(seq, now), scan, n_views=len(poses), now=now)
        # Ahead of the writes deferred for other jobs: the next job's first moves need no company.
        added = self._db.call(self._jobs.add, scan, n_views=len(poses), now=now, seq=seq, durable=False, ahead=True)
        job = Job(status.job_id, scan, poses)
        self._enqueue(job)
        later(self._publish, queued_event(status))
        if scan.request_id is not None:
            self._request_ids[scan.request_id] = status.job_id
            if len(self._request_ids) > _REQUEST_IDS:
                self._request_ids.popitem(last=False)
        try:
            stored, created = await added
        except StoreError as exc:
            why = f"the job store could not take the job: {exc}"
            self._withdraw(job, why)
            raise StoreError(why) from None
        if not created:  # the store knew the request_id after all: its job it is
            self._withdraw(job, f"the store has request {scan.request_id} as job {stored.job_id}")
            return Response(stored.model_dump_json())
        # On disk before the answer, so an answered submit survives a crash; the job need not wait
        # for the disk to start. (A crash before the answer may leave the job, unanswered, to run
        # after the restart: a client's retry with the same request_id finds it.)
        await self._db.call(self._jobs.sync, ahead=True)
        return Response(status.model_dump_json())

    async def _known_request(self, request_id: str) -> JobStatus | None:
        """The job submitted with ``request_id`` before, in its state now; None if there is none."""
        job_id = self._request_ids.get(request_id)
        if job_id is None:  # not in this run (or long ago): the store knows
            known = await self._db.call(self._jobs.find_request, request_id, ahead=True)
            if known is not None:
                return known
            job_id = self._request_ids.get(request_id)  # submitted while the store looked
            if job_id is None:
                return None
        return await self._status(job_id)

    def _withdraw(self, job: Job, why: str) -> None:
        """Take back a job the store did not take, wherever it is: it fails, told to those who
        listen and to its recording, not to the store, which does not have it."""
        log.error("job %s: withdrawn: %s", job.job_id, why)
        self._queued.pop(job.job_id, None)
        if job.task is not None:
            job.task.cancel()  # not a cancel by request: its steps end without another word
        with contextlib.suppress(IllegalTransition):  # it cannot have ended yet; should it have, so be it
            event = job.transition(JobState.FAILED, why, now=self.clock())
            self._write_down(job, event)
            self._publish(event)

    async def _on_status(self, request: Request) -> Response:
        try:
            n_failures = int(request.parameters.get("failures", _RECENT_FAILURES))
        except ValueError as exc:
            raise RequestError(f"bad parameters: {exc}") from None
        n_failures = max(0, min(n_failures, 1000))

        def read(store: JobStore) -> tuple[dict[JobState, int], list[JobStatus]]:
            failed = store.list(states={JobState.FAILED}, limit=n_failures) if n_failures else []
            return store.counts(), failed

        counts, failed = await self._db.call(read, self._jobs)
        status = CellStatus(
            cell=self.cell, time=self.clock(), started=self._started,
            workers={part: part in self._presence for part in ("robot", "camera")},
            reconstructors=self.pool.snapshot(), queued=len(self._queued), max_queued=self.config.max_queued,
            waiting_for_reconstructor=self.pool.waiting,
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
        statuses = await self._db.call(self._jobs.list, states=states, limit=max(1, min(limit, 1000)))
        return Response("[" + ",".join(s.model_dump_json() for s in statuses) + "]")

    async def _on_job_query(self, request: Request) -> Response:
        parts = request.key.split("/")[3:]  # robocell/<cell>/jobs/<id>[/<what>]
        job_id, what = parts[0], (parts[1] if len(parts) > 1 else "status")
        if what == "cancel":
            return Response((await self._cancel(job_id)).model_dump_json())
        if what not in ("status", "result"):
            raise RequestError(f"unknown job query {what!r}: expected status, result or cancel")
        if what == "result" and job_id in self._recent_results:
            return Response(self._recent_results[job_id])
        status = await self._status(job_id)
        if what == "status":
            return Response(status.model_dump_json())
        result = await self._db.call(self._jobs.result, job_id)
        if result is None:
            raise RequestError(f"job {job_id} has no result: it is {status.state.value}"
                               + (f" ({status.error})" if status.error else ""))
        return Response(result.model_dump_json())

    async def _status(self, job_id: str) -> JobStatus:
        status = await self._db.call(self._jobs.get, job_id)
        if status is None:
            raise RequestError(f"no job {job_id!r} in cell {self.cell}")
        return status

    async def _cancel(self, job_id: str) -> JobStatus:
        """Cancel the job; the status returned is "cancelled" unless the job ended first."""
        job = self._queued.pop(job_id, None) or self._active.get(job_id)
        if job is None:
            status = await self._status(job_id)
            if status.state is JobState.CANCELLED:
                return status
            raise RequestError(f"job {job_id} already {status.state.value}: nothing to cancel")
        try:
            event = job.request_cancel(now=self.clock())
        except IllegalTransition:  # cancelling already, or it has just ended
            pass
        else:
            if event.state.finished:  # it was waiting: that is all
                self._db.post(self._jobs.update, job_id, event.state, now=event.time, event=event,
                              then=functools.partial(self._publish, event))
            else:
                self._write_down(job, event)
                self._db.post(self._jobs.update, job_id, event.state, view=event.view, now=event.time,
                              event=event, durable=False)
                later(self._publish, event)
                if job.task is not None:
                    job.task.cancel()
        if job.task is not None:
            # A step may be ending right now: let it notice (bounded: the caller waits).
            await asyncio.wait({job.task}, timeout=_CANCEL_WAIT_S)
        return await self._status(job_id)


def _briefly_away(exc: CellError) -> bool:
    """Whether ``exc`` says a part is away for now (a camera that does not answer, or answers a
    server error), rather than that the request was wrong."""
    if isinstance(exc, (CameraConnectionError, CameraTimeout)):
        return True
    return isinstance(exc, CameraError) and exc.status is not None and exc.status >= 500
