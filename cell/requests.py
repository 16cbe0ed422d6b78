"""What clients ask of the cell daemon: submit a job, a job's status, result or cancel, the list of
jobs, the cell's status. Part of :class:`cell.daemon.CellDaemon`."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robocell.core_cy.plan import workspace_violation
from robocell.wire.config import CellConfig
from robocell.wire.errors import StoreError
from robocell.wire.messages import (REQUEST_LIMITS, CancelRequest, CellStatus, FailedJob, JobState, JobStatus, ScanRequest,
                           parse_request)
from robocell.wire.transport import Request, RequestError, Response

from .handle import JobHandle
from .job import Checkpoint, IllegalTransition
from .plan import job_steps
from .reserve import full_disk_refusal
from .steps import Step
from .store import JobStore
from .tokens import JobTokenRefused, check_token, new_token, token_digest
from .upkeep import disk_used

if TYPE_CHECKING:
    from .pool import ReconstructorPool
    from .presence import Presence

__all__ = ["RequestHandlers"]

_CANCEL_WAIT_S = 2.0
_RECENT_FAILURES = 10       # failed jobs in a status answer, unless asked for another number
_RESULT_WAIT_S = 3600.0     # the longest a result query waits for its job to end (parameter wait)


class RequestHandlers:
    """The daemon's answers to its clients' queries (the daemon provides what is declared here)."""

    config: CellConfig
    cell: str
    run_dir: Path
    clock: Callable[[], float]
    pool: ReconstructorPool
    _live: dict[str, JobHandle]
    _presence: Presence
    _started: float

    _queued: Callable[[], int]
    _admit: Callable[[JobStatus, ScanRequest, list[Step]], None]
    _flange_poses: Callable[[ScanRequest], list[np.ndarray]]

    @property
    def _jobs(self) -> JobStore:
        raise NotImplementedError  # the daemon's store, in its thread

    async def _on_submit(self, request: Request) -> Response:
        try:
            scan = parse_request(ScanRequest, request.payload, REQUEST_LIMITS["submit"])
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
            known = self._jobs.find_request(scan.request_id)
            if known is not None:
                return Response(known.model_dump_json())
        if self._queued() >= self.config.max_queued:
            raise RequestError(f"the queue is full ({self.config.max_queued} jobs waiting): try again later")
        full = full_disk_refusal(self.run_dir)
        if full is not None:
            raise RequestError(full)
        plan = job_steps(scan, poses)
        point = Checkpoint(plan=[step.spec() for step in plan], done=0).model_dump_json()
        token = new_token()  # the job's secret: its client's alone (only its digest is kept)
        try:  # on disk before the answer, so an answered submit survives a crash
            status, created = self._jobs.add(scan, n_views=len(poses), now=self.clock(), checkpoint=point,
                                             token_digest=token_digest(token))
            await asyncio.to_thread(self._jobs.sync)
        except StoreError as exc:
            raise StoreError(f"the job store could not take the job: {exc}") from None
        if created:
            self._admit(status, scan, plan)
            return Response(status.model_copy(update={"token": token}).model_dump_json())
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

        counts, failed = read(self._jobs)
        disk = await disk_used(self.run_dir, self._jobs, self.config.retention, active=set(self._live),
                               now=self.clock())
        status = CellStatus(
            cell=self.cell, time=self.clock(), started=self._started,
            workers={part: part in self._presence for part in ("robot", "camera")},
            reconstructors=self.pool.snapshot(), queued=self._queued(), max_queued=self.config.max_queued,
            waiting_for_reconstructor=self.pool.waiting,
            jobs={state.value: n for state, n in counts.items()},
            recent_failures=[FailedJob(job_id=s.job_id, error=s.error, updated=s.updated) for s in failed],
            disk=disk)
        return Response(status.model_dump_json())

    async def _on_list(self, request: Request) -> Response:
        try:
            states = {JobState(s) for s in request.parameters["state"].split(",")} \
                if "state" in request.parameters else None
            limit = int(request.parameters.get("limit", 50))
        except ValueError as exc:
            raise RequestError(f"bad parameters: {exc}") from None
        statuses = self._jobs.list(states=states, limit=max(1, min(limit, 1000)))
        return Response("[" + ",".join(s.model_dump_json() for s in statuses) + "]")

    async def _on_job_query(self, request: Request) -> Response:
        parts = request.key.split("/")[3:]  # robocell/<cell>/jobs/<id>[/<what>]
        job_id, what = parts[0], (parts[1] if len(parts) > 1 else "status")
        if what == "cancel":
            try:
                token = parse_request(CancelRequest, request.payload, REQUEST_LIMITS["cancel"]).token \
                    if request.payload else None
                check_token(job_id, token, self._jobs.token_digest(job_id))
            except (ValueError, JobTokenRefused) as exc:
                raise RequestError(str(exc)) from None
            return Response((await self._cancel(job_id)).model_dump_json())
        if what == "result":
            return Response(await self._result(job_id, request.parameters.get("wait")))
        if what != "status":
            raise RequestError(f"unknown job query {what!r}: expected status, result or cancel")
        return Response((await self._status(job_id)).model_dump_json())

    async def _result(self, job_id: str, wait: str | None) -> str:
        """The job's result as the store took it (validated then); with ``wait`` (seconds), once a job
        under way has ended, or that many seconds have passed: a client asks as it submits, and has
        its answer as the job ends (``AsyncCellClient.scan``)."""
        try:
            seconds = 0.0 if wait is None else min(float(wait), _RESULT_WAIT_S)
        except ValueError:
            raise RequestError(f"bad parameters: wait={wait!r} is not a number of seconds") from None
        handle = self._live.get(job_id)
        if seconds > 0 and handle is not None:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(seconds):
                    await handle.ended.wait()
        stored = self._jobs.result_json(job_id)
        if stored is not None:
            return stored
        status = await self._status(job_id)
        raise RequestError(f"job {job_id} has no result: it is {status.state.value}"
                           + (f" ({status.error})" if status.error else ""))

    async def _status(self, job_id: str) -> JobStatus:
        status = self._jobs.get(job_id)
        if status is None:
            raise RequestError(f"no job {job_id!r} in cell {self.cell}")
        return status

    async def _cancel(self, job_id: str) -> JobStatus:
        """Cancel the job; the status returned is "cancelled" unless the job ended first."""
        handle = self._live.get(job_id)
        if handle is None:
            status = await self._status(job_id)
            if status.state is JobState.CANCELLED:
                return status
            raise RequestError(f"job {job_id} already {status.state.value}: nothing to cancel")
        task = handle.job.task
        try:
            await handle.request_cancel()
        except IllegalTransition:  # cancelling already, or it has just ended
            pass
        else:
            if task is not None:
                task.cancel()
        if task is not None:  # a step may be ending right now: let it notice (bounded: the caller waits)
            await asyncio.wait({task}, timeout=_CANCEL_WAIT_S)
        return await self._status(job_id)
