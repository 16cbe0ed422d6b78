"""The one path of every change of a job, after rclpy's ``ServerGoalHandle._update_state``.

A change (the job's life moves on, or it starts another step, or it has something
to say) goes through :meth:`JobHandle.change`, and only there, always in this order:

1. into the store, synced to disk first when :func:`must_sync` says so;
2. to its listeners (the event is published);
3. into the job's recording.

A change the store refuses goes no further: nobody hears of it, and the job's state
in memory stays what the store has. The daemon's store does not refuse a change for
want of room (:func:`stored_when_taken`): the job waits, trying again, and carries on
by itself once the disk has room (a full disk must neither end a job a client was not
told of, nor leave one that nothing runs). Changes of one job are applied one at a
time, in the order they were asked for; once begun, a change is carried through even
if its caller is cancelled (a cancelled step must not leave the store and the
listeners apart).

What must be on disk before anyone hears of it (:func:`must_sync`):

=====================  ===============================================================
the job is accepted    a submit answered is a job that survives a crash
a pick begins          restarted, the daemon must not pick again: the gripper may hold it
every end              a client told of an end never finds the job running again
=====================  ===============================================================

Everything else (the next step, a note) is written without waiting for the disk: a
``kill -9`` loses nothing written, and after a power cut a restart finds the job a
step behind, which it carries on from.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any, Protocol

from robocell.wire.errors import StoreError
from robocell.wire.messages import JobEvent, JobState, JobStatus, Lifecycle, Progress, ScanResult, wire_state

from .job import Checkpoint, IllegalTransition, Job, check_transition
from .store import JobStore

__all__ = ["Books", "JobHandle", "must_sync", "stored_when_taken", "SYNCED_LIFECYCLES", "SYNCED_ACTIVITIES",
           "STORE_RETRY_S"]

log = logging.getLogger(__name__)

#: A change into one of these lifecycles is synced before anyone hears of it.
SYNCED_LIFECYCLES = frozenset({Lifecycle.QUEUED, Lifecycle.SUCCEEDED, Lifecycle.FAILED, Lifecycle.CANCELLED})
#: A change that begins one of these activities is synced before anyone hears of it.
SYNCED_ACTIVITIES = frozenset({JobState.PICKING})
#: How often a change the store could not take (a full disk) is tried again.
STORE_RETRY_S = 1.0


def must_sync(before: Progress | None, lifecycle: Lifecycle, progress: Progress | None) -> bool:
    """Whether the change to ``lifecycle`` and ``progress`` (from ``before``) must be on disk before
    anyone hears of it (see the module's table)."""
    if lifecycle in SYNCED_LIFECYCLES:
        return True
    begins = progress is not None and (before is None or before.activity is not progress.activity)
    return begins and progress is not None and progress.activity in SYNCED_ACTIVITIES


async def stored_when_taken(store: JobStore, event: JobEvent, *, retry_s: float = STORE_RETRY_S,
                            **fields: Any) -> JobStatus:
    """``store.change(event, **fields)``, tried again every ``retry_s`` seconds while the store is
    open and cannot take it (a full disk): the job waits there, and nobody hears of the change
    before it is stored; it carries on by itself once the store takes it. Raises the store's
    error once the store is closed (the daemon stops: the restarted one carries the job on)."""
    tries = 0
    while True:
        tries += 1
        try:
            status = store.change(event, **fields)
        except StoreError as exc:
            if store.closed:
                raise
            if tries == 1:
                log.error("job %s: the store cannot take its change (%s): trying again every %g s",
                          event.job_id, exc, retry_s)
            await asyncio.sleep(retry_s)
            continue
        if tries > 1:
            log.warning("job %s: the store took its change at try %d: carrying on", event.job_id, tries)
        return status


class Books(Protocol):
    """Where a change goes: the store, the listeners, the recording (the daemon is one)."""

    async def store(self, event: JobEvent, *, sync: bool, error_kind: str | None,
                    checkpoint: Checkpoint | None) -> None:
        """Write the change; raise ``StoreError`` if the store cannot take it."""

    def publish(self, event: JobEvent) -> None:
        """Tell the job's listeners."""

    def record_event(self, job: Job, event: JobEvent) -> None:
        """Add the change to the job's recording (an end also closes it)."""


class JobHandle:
    """The job ``job``, changed only through :meth:`change` (and :meth:`request_cancel`)."""

    def __init__(self, job: Job, books: Books, clock: Callable[[], float]) -> None:
        self.job = job
        self._books = books
        self._clock = clock
        self._turn = asyncio.Lock()
        #: Set once the job's end is stored, told and recorded.
        self.ended = asyncio.Event()

    async def change(self, message: str, *, lifecycle: Lifecycle | None = None,
                     progress: Progress | None | bool = True, error_kind: str | None = None,
                     result: ScanResult | None = None, checkpoint: bool = False) -> JobEvent:
        """Change the job: to ``lifecycle`` (default: as it is), doing ``progress`` (``True``: what
        it does now; None: nothing). ``checkpoint``: store the job's plan and steps done with it.

        Raises
        ------
        IllegalTransition
            :data:`cell.job.TRANSITIONS` does not allow it; nothing is changed.
        StoreError
            The store cannot take it; nothing is changed, nobody told.
        """
        applied = asyncio.ensure_future(self._apply(message, lifecycle, progress, error_kind, result, checkpoint))
        applied.add_done_callback(_retrieved)  # a caller cancelled meanwhile no longer asks how it went
        return await asyncio.shield(applied)

    def accepted(self, event: JobEvent) -> None:
        """The job's first event, which the store wrote (and synced) as it took the job: told
        to the listeners, then recorded."""
        self._books.publish(event)
        self._books.record_event(self.job, event)

    async def request_cancel(self) -> JobEvent:
        """Cancel: a queued job is cancelled at once, a running one starts cancelling.

        Raises
        ------
        IllegalTransition
            The job has ended, or is cancelling already.
        """
        async def cancel() -> JobEvent:
            async with self._turn:
                if self.job.lifecycle is Lifecycle.QUEUED:
                    return await self._write("cancelled by request", Lifecycle.CANCELLED, None, None, None, False)
                if self.job.lifecycle is not Lifecycle.RUNNING:
                    raise IllegalTransition(self.job.job_id, self.job.lifecycle, Lifecycle.CANCELLING)
                return await self._write("cancelling by request", Lifecycle.CANCELLING, True, None, None, False)
        return await asyncio.shield(asyncio.ensure_future(cancel()))

    async def _apply(self, message: str, lifecycle: Lifecycle | None, progress: Progress | None | bool,
                     error_kind: str | None, result: ScanResult | None, checkpoint: bool) -> JobEvent:
        async with self._turn:
            return await self._write(message, lifecycle, progress, error_kind, result, checkpoint)

    async def _write(self, message: str, lifecycle: Lifecycle | None, progress: Progress | None | bool,
                     error_kind: str | None, result: ScanResult | None, checkpoint: bool) -> JobEvent:
        job = self.job
        to = job.lifecycle if lifecycle is None else lifecycle
        if to is not job.lifecycle:
            check_transition(job.job_id, job.lifecycle, to)
        elif to.finished:
            raise IllegalTransition(job.job_id, job.lifecycle, to)
        doing = job.progress if progress is True else (progress or None)
        if to.finished:
            doing = None
        event = JobEvent(job_id=job.job_id, state=wire_state(to, doing), kind=job.request.kind, lifecycle=to,
                         progress=doing, view=doing.view if doing is not None else None, message=message,
                         time=self._clock(), result=result)
        await self._books.store(event, sync=must_sync(job.progress, to, doing), error_kind=error_kind,
                                checkpoint=job.checkpoint(began=doing.step if doing else None) if checkpoint else None)
        job.lifecycle, job.progress = to, doing
        self._books.publish(event)
        self._books.record_event(job, event)
        if to.finished:
            self.ended.set()
        return event


def _retrieved(future: asyncio.Future[JobEvent]) -> None:
    if not future.cancelled():
        future.exception()
