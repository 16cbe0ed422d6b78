"""The cell daemon: one asyncio state machine per scan job.

queued -> moving(i) -> capturing(i) (for each view) -> reconstructing -> succeeded
                                   any step -> failed (with the step and reason) | cancelled

One robot and one camera: a single *motion lane* takes jobs in order and
moves and captures for one job at a time. When a job's pictures are taken,
its reconstruction runs as a task of its own, so it overlaps the next job's
motion. Every state change is stored (SQLite), published as a JobEvent and
written to the job's Rerun recording.
"""

from __future__ import annotations

import asyncio
import base64
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import keys
from .config import CellConfig
from .errors import CellError, NoResponder, TransportError
from .messages import (CameraModel, CaptureInfo, CaptureRequest, JobEvent, JobState, JobStatus, MoveReply,
                       MoveRequest, ReconstructReply, ReconstructRequest, ReconstructView, ScanRequest,
                       ScanResult, parse)
from .plan import camera_poses, plan_flange_poses, workspace_violation
from .recording import JobRecording
from .store import JobStore
from .transport import Request, RequestError, Response, Transport

__all__ = ["CellDaemon", "StepFailed"]

log = logging.getLogger(__name__)


class StepFailed(CellError):
    """A step of a job failed; the message says which step and why."""


@dataclass
class _Capture:
    jpeg: bytes
    T_base_flange: np.ndarray
    T_base_cam: np.ndarray


@dataclass
class _ActiveJob:
    job_id: str
    started: float
    recording: JobRecording
    task: asyncio.Task | None = None
    cancel_requested: bool = False
    captures: list[_Capture] = field(default_factory=list)


class CellDaemon:
    """Runs scan jobs for one cell. Create, then ``await run(stop)``."""

    def __init__(self, config: CellConfig, transport: Transport, store: JobStore, *, clock=time.time) -> None:
        self.config = config
        self.cell = config.cell_id
        self._transport = transport
        self._store = store
        self._clock = clock
        self._queue: asyncio.Queue[str] = asyncio.Queue()
        self._active: dict[str, _ActiveJob] = {}
        self._alive: set[str] = set()                   # this cell's workers with a liveliness token
        self._reconstructors: dict[str, int] = {}       # live reconstructor -> jobs in flight
        self._presence = asyncio.Condition()
        self._background: set[asyncio.Task] = set()
        self.run_dir = Path(config.run_dir)

    # --- lifecycle -----------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self._recover()
        transport, cell = self._transport, self.cell
        self._spawn(self._watch(transport.watch_liveliness(keys.alive(cell)), self._on_cell_worker))
        self._spawn(self._watch(transport.watch_liveliness(keys.RECONSTRUCTORS_ALIVE), self._on_reconstructor))
        transport.serve(keys.submit(cell), self._on_submit)
        transport.serve(keys.jobs(cell), self._on_list)
        transport.serve(f"{keys.jobs(cell)}/**", self._on_job_query)
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
            for active in self._active.values():
                active.recording.close()

    def _spawn(self, coroutine) -> asyncio.Task:
        task = asyncio.create_task(coroutine)
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        return task

    def _recover(self) -> None:
        """After a restart: jobs caught mid-step failed; queued jobs run again, in order."""
        now = self._clock()
        for status in self._store.interrupt_unfinished(now=now):
            self._event(status, status.error or "interrupted")
            log.warning("job %s was interrupted by a restart", status.job_id)
        for status in self._store.unfinished():
            self._queue.put_nowait(status.job_id)

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
        (self._alive.add if alive else self._alive.discard)(part)
        log.info("%s worker %s", part, "is up" if alive else "is gone")

    def _on_reconstructor(self, key: str, alive: bool) -> None:
        worker = key.rsplit("/", 1)[-1]
        if alive:
            self._reconstructors.setdefault(worker, 0)
        else:
            self._reconstructors.pop(worker, None)
        log.info("reconstructor %s %s", worker, "joined" if alive else "left")

    async def _wait_for(self, ready, what: str) -> None:
        wait = self.config.timeouts.worker_wait_s
        async with self._presence:
            try:
                await asyncio.wait_for(self._presence.wait_for(ready), wait)
            except asyncio.TimeoutError:
                raise StepFailed(f"no {what} is running (waited {wait:g} s)") from None

    async def _ask(self, part: str, key: str, message, timeout: float, **kwargs):
        await self._wait_for(lambda: part in self._alive, f"{part} worker")
        try:
            return await self._transport.query(key, message.model_dump_json(), timeout=timeout, **kwargs)
        except NoResponder:
            raise StepFailed(f"no {part} worker is running") from None
        except TransportError as exc:
            raise StepFailed(f"{part}: {exc}") from None

    # --- job state -----------------------------------------------------------------------------

    def _event(self, status: JobStatus, message: str) -> None:
        event = JobEvent(job_id=status.job_id, state=status.state, view=status.view, message=message,
                         time=status.updated)
        self._store.add_event(event)
        self._transport.put(keys.events(self.cell, status.job_id), event.model_dump_json())
        active = self._active.get(status.job_id)
        if active is not None:
            active.recording.set_time(self._clock() - active.started)
            level = "ERROR" if status.state is JobState.FAILED else "INFO"
            active.recording.log_text(f"{status.state.value}: {message}", level)

    def _set(self, job_id: str, state: JobState, message: str, *, view: int | None = None,
             error: str | None = None, recording: Path | None = None) -> JobStatus:
        status = self._store.update(job_id, state, view=view, error=error, now=self._clock(),
                                    recording=None if recording is None else str(recording))
        self._event(status, message)
        return status

    def _finish(self, job_id: str) -> None:
        active = self._active.pop(job_id, None)
        if active is not None:
            active.recording.close()

    def _recording_path(self, job_id: str) -> Path:
        return self.run_dir / f"{job_id}.rrd"

    def _flange_poses(self, request: ScanRequest) -> list[np.ndarray]:
        if request.flange_poses is not None:
            return [np.asarray(pose, dtype=np.float64) for pose in request.flange_poses]
        plan = request.plan or self.config.scan.plan
        return plan_flange_poses(request.target, plan, self.config.T_flange_cam)

    # --- the motion lane -----------------------------------------------------------------------

    async def _motion_lane(self) -> None:
        while True:
            job_id = await self._queue.get()
            status = self._store.get(job_id)
            if status is None or status.state is not JobState.QUEUED:
                continue  # cancelled while it waited
            active = _ActiveJob(job_id, self._clock(), JobRecording(self._recording_path(job_id), job_id))
            self._active[job_id] = active
            active.task = asyncio.create_task(self._acquire(active, status.request))
            # asyncio.wait, unlike await, does not raise when the job (not the lane) is cancelled.
            await asyncio.wait({active.task})

    async def _acquire(self, active: _ActiveJob, request: ScanRequest) -> None:
        job_id, timeouts = active.job_id, self.config.timeouts
        step = "planning"
        try:
            poses = self._flange_poses(request)
            for view, pose in enumerate(poses):
                step = f"moving to view {view}"
                self._set(job_id, JobState.MOVING, step, view=view, recording=self._recording_path(job_id))
                reply = await self._ask("robot", keys.robot_move(self.cell),
                                        MoveRequest(T_base_flange=pose.tolist(), job_id=job_id), timeouts.move_s)
                reached = np.asarray(parse(MoveReply, reply.payload).T_base_flange)
                active.recording.set_time(self._clock() - active.started)
                active.recording.log_robot_pose(reached)
                step = f"capturing view {view}"
                self._set(job_id, JobState.CAPTURING, step, view=view)
                reply = await self._ask("camera", keys.camera_capture(self.cell),
                                        CaptureRequest(job_id=job_id, view=view), timeouts.capture_s)
                info = parse(CaptureInfo, reply.attachment)
                T_base_cam = camera_poses([reached], self.config.T_flange_cam)[0]
                active.captures.append(_Capture(reply.payload, reached, T_base_cam))
                active.recording.set_time(self._clock() - active.started)
                active.recording.log_view(view, reply.payload, self.config.camera.K, T_base_cam,
                                          (info.width, info.height))
            step = "reconstructing"
            self._set(job_id, JobState.RECONSTRUCTING, f"{len(poses)} views taken")
        except asyncio.CancelledError:
            self._cancelled(active)
            return
        except (StepFailed, ValueError) as exc:
            self._fail(job_id, f"{step}: {exc}")
            return
        active.task = self._spawn(self._reconstruct(active))

    def _cancelled(self, active: _ActiveJob) -> None:
        if active.cancel_requested:
            self._set(active.job_id, JobState.CANCELLED, "cancelled by request")
            self._finish(active.job_id)
        else:
            raise asyncio.CancelledError  # the daemon is stopping: the restart will deal with the job

    def _fail(self, job_id: str, error: str) -> None:
        log.warning("job %s failed: %s", job_id, error)
        self._set(job_id, JobState.FAILED, error, error=error)
        self._finish(job_id)

    # --- reconstruction ------------------------------------------------------------------------

    async def _reconstruct(self, active: _ActiveJob) -> None:
        job_id = active.job_id
        try:
            await self._wait_for(lambda: bool(self._reconstructors), "reconstruction worker")
            worker = min(self._reconstructors, key=self._reconstructors.get)
            self._reconstructors[worker] += 1
            try:
                reply = await self._transport.query(
                    keys.reconstructor(worker), b"".join(c.jpeg for c in active.captures),
                    attachment=self._reconstruct_request(active).model_dump_json(),
                    timeout=self.config.timeouts.reconstruct_s)
            finally:
                if worker in self._reconstructors:
                    self._reconstructors[worker] -= 1
            answer = parse(ReconstructReply, reply.payload)
            if answer.error:
                raise StepFailed(answer.error)
            self._succeed(active, answer)
        except asyncio.CancelledError:
            self._cancelled(active)
        except (StepFailed, TransportError, ValueError) as exc:
            self._fail(job_id, f"reconstructing: {exc}")

    def _reconstruct_request(self, active: _ActiveJob) -> ReconstructRequest:
        camera = CameraModel(K=self.config.camera.K, dist=self.config.camera.dist)
        settings = self.config.reconstruct
        options = {name: value for name in ("n_points", "inside_weight", "cauchy_scale")
                   if (value := getattr(settings, name)) is not None}
        views = [ReconstructView(camera=camera, T_world_cam=c.T_base_cam.tolist(), length=len(c.jpeg))
                 for c in active.captures]
        return ReconstructRequest(job_id=active.job_id, views=views, support_plane=self.config.support_plane,
                                  options=options)

    def _succeed(self, active: _ActiveJob, answer: ReconstructReply) -> None:
        result = answer.result
        scan_result = ScanResult(job_id=active.job_id, superquadric=result["superquadric"],
                                 silhouette_iou=result["silhouette_iou"], residual=result["residual"],
                                 timings_ms=result["timings_ms"],
                                 T_base_cam=[c.T_base_cam.tolist() for c in active.captures],
                                 recording=str(self._recording_path(active.job_id)))
        self._log_reconstruction(active, answer)
        status = self._store.save_result(scan_result, now=self._clock())
        total = result["timings_ms"].get("total", float("nan"))
        self._event(status, f"reconstructed by {answer.worker} in {total:.1f} ms")
        self._finish(active.job_id)

    def _log_reconstruction(self, active: _ActiveJob, answer: ReconstructReply) -> None:
        from core_cy.sphere import fibonacci_sphere
        from core_cy.superquadric import Superquadric

        recording, result = active.recording, answer.result
        recording.set_time(self._clock() - active.started)
        for view, encoded in enumerate(answer.silhouettes_png):
            mask = cv2.imdecode(np.frombuffer(base64.b64decode(encoded), np.uint8), cv2.IMREAD_GRAYSCALE)
            recording.log_silhouette(view, mask)
        n_points = self.config.reconstruct.n_points
        sphere = np.asarray(answer.centre) + answer.radius * fibonacci_sphere(n_points)
        recording.log_points("sphere", sphere, colour=(150, 150, 150))
        recording.log_points("carved", np.asarray(result["points"]))
        recording.log_superquadric("fit", Superquadric.from_dict(result["superquadric"]))
        timings = ", ".join(f"{stage} {ms:.1f} ms" for stage, ms in result["timings_ms"].items())
        recording.log_text(f"reconstruction on {answer.worker}: {timings}")
        if self.config.robot.backend == "sim":
            from .sim.scene import scene_from_config

            for obj in scene_from_config(self.config.sim):
                recording.log_mesh("truth", *obj.mesh())

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
        if self._store.count({JobState.QUEUED}) >= self.config.max_queued:
            raise RequestError(f"the queue is full ({self.config.max_queued} jobs waiting): try again later")
        status, created = self._store.add(scan, n_views=len(poses), now=self._clock())
        if created:
            self._event(status, "queued")
            self._queue.put_nowait(status.job_id)
        return Response(status.model_dump_json())

    async def _on_list(self, request: Request) -> Response:
        try:
            states = {JobState(s) for s in request.parameters["state"].split(",")} \
                if "state" in request.parameters else None
            limit = int(request.parameters.get("limit", 50))
        except ValueError as exc:
            raise RequestError(f"bad parameters: {exc}") from None
        statuses = self._store.list(states=states, limit=max(1, min(limit, 1000)))
        return Response("[" + ",".join(s.model_dump_json() for s in statuses) + "]")

    async def _on_job_query(self, request: Request) -> Response:
        parts = request.key.split("/")[3:]  # robocell/<cell>/jobs/<id>[/<what>]
        job_id, what = parts[0], (parts[1] if len(parts) > 1 else "status")
        status = self._store.get(job_id)
        if status is None:
            raise RequestError(f"no job {job_id!r} in cell {self.cell}")
        if what == "status":
            return Response(status.model_dump_json())
        if what == "result":
            result = self._store.result(job_id)
            if result is None:
                raise RequestError(f"job {job_id} has no result: it is {status.state.value}"
                                   + (f" ({status.error})" if status.error else ""))
            return Response(result.model_dump_json())
        if what == "cancel":
            return Response(self._cancel(status).model_dump_json())
        raise RequestError(f"unknown job query {what!r}: expected status, result or cancel")

    def _cancel(self, status: JobStatus) -> JobStatus:
        if status.state is JobState.CANCELLED:
            return status
        if status.state.finished:
            raise RequestError(f"job {status.job_id} already {status.state.value}: nothing to cancel")
        active = self._active.get(status.job_id)
        if active is None:  # still queued: the lane will skip it
            return self._set(status.job_id, JobState.CANCELLED, "cancelled by request")
        active.cancel_requested = True
        if active.task is not None:
            active.task.cancel()
        return status
