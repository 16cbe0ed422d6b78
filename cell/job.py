"""A job as an explicit state machine, after rclpy's action server (``ServerGoalHandle``).

Every state, and every legal move between states, is written down once, in
:data:`TRANSITIONS`; a move the table does not allow raises
:class:`IllegalTransition` at once instead of corrupting the job. Cancelling
is a transition too: a waiting job is cancelled at once; a working job goes to
``cancelling``, its step is interrupted, and it ends ``cancelled``::

    queued ──▶ moving ⇄ capturing ──▶ reconstructing ──▶ (picking) ──▶ succeeded
      │            (working states)            │
      │                   ├──────────────────▶ failed
      │                   ╰──▶ cancelling ──▶ cancelled
      ╰──────────────────────────────────────▶ cancelled | failed

A working state may follow any working state: what a job does next is its
steps' business (``cell.steps``), not the table's. A restarted daemon puts a
job whose pictures were not all taken back to ``queued`` (its views are taken
again), and carries a ``cancelling`` job to ``cancelled``.

:class:`Job` holds a job's state and what its steps gather; it does no I/O.
The daemon stores, publishes and records each :class:`~wire.messages.JobEvent`
that :meth:`Job.transition` returns.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field

import numpy as np

from wire.errors import CellError
from wire.messages import JobEvent, JobState, ScanRequest, ScanResult

__all__ = ["TRANSITIONS", "WORKING", "IllegalTransition", "Job", "Picture"]

S = JobState
#: States in which a step runs.
WORKING = frozenset({S.MOVING, S.CAPTURING, S.RECONSTRUCTING, S.PICKING})
_ENDS = frozenset({S.SUCCEEDED, S.FAILED})

#: Every legal move: from a state, the states it may go to.
TRANSITIONS: dict[JobState, frozenset[JobState]] = {
    S.QUEUED: WORKING | {S.FAILED, S.CANCELLED},
    **{state: WORKING | _ENDS | {S.CANCELLING, S.QUEUED} for state in WORKING},
    S.CANCELLING: frozenset({S.CANCELLED}),
    S.SUCCEEDED: frozenset(),
    S.FAILED: frozenset(),
    S.CANCELLED: frozenset(),
}


class IllegalTransition(CellError):
    """A job was asked to move where the state machine does not allow: a bug, or a request
    that comes too late (cancelling a job that has ended)."""

    def __init__(self, job_id: str, state: JobState, to: JobState) -> None:
        super().__init__(f"job {job_id} is {state.value}: it cannot become {to.value}")
        self.state, self.to = state, to


@dataclass
class Picture:
    """One picture a job took, and where from."""

    jpeg: bytes
    T_base_flange: np.ndarray
    T_base_cam: np.ndarray


@dataclass
class Job:
    """One job: its state, and what its steps gathered on the way.

    ``poses`` are the flange poses of its views, planned at submit (or when a restarted daemon
    takes the job up again).
    """

    job_id: str
    request: ScanRequest
    poses: list[np.ndarray]
    state: JobState = JobState.QUEUED
    view: int | None = None
    started: float = field(default_factory=time.time)
    captures: list[Picture] = field(default_factory=list)
    #: Where the flange stands, as the robot last reported it.
    flange: np.ndarray | None = None
    #: What the job waited for, seconds: see ``ScanResult.durations_s``.
    durations_s: dict[str, float] = field(default_factory=dict)
    result: ScanResult | None = None
    #: The reconstruction worker's reply (attachment, payload), and the job time it came, for the recording.
    reconstruction: tuple[bytes, bytes, float] | None = None
    #: A pick's flange poses by name ("above", "grasp", "lift", ...), once a grasp is chosen.
    pick_poses: dict[str, np.ndarray] = field(default_factory=dict)
    #: Why the job's recording cannot be written, if it cannot.
    recording_error: str | None = None
    #: Done once the recording's file was tried (``recording_error`` then says how it went).
    recording_checked: asyncio.Future[None] | None = None
    #: The task that runs the job's steps, once it runs.
    task: asyncio.Task | None = None

    @property
    def finished(self) -> bool:
        return self.state.finished

    def can(self, to: JobState) -> bool:
        return to in TRANSITIONS[self.state]

    def transition(self, to: JobState, message: str, *, view: int | None = None, now: float,
                   result: ScanResult | None = None) -> JobEvent:
        """Move to ``to``; the event that says so.

        Raises
        ------
        IllegalTransition
            If :data:`TRANSITIONS` does not allow it.
        """
        if to not in TRANSITIONS[self.state]:
            raise IllegalTransition(self.job_id, self.state, to)
        self.state, self.view = to, view
        return JobEvent(job_id=self.job_id, state=to, view=view, message=message, time=now, result=result)

    def note(self, message: str, *, now: float) -> JobEvent:
        """An event that changes no state: a retry, say."""
        return JobEvent(job_id=self.job_id, state=self.state, view=self.view, message=message, time=now)

    def request_cancel(self, *, now: float) -> JobEvent:
        """Cancel: a job that waits is cancelled at once, a working one starts cancelling.

        Raises
        ------
        IllegalTransition
            If the job has ended, or is cancelling already.
        """
        if self.state is JobState.QUEUED:
            return self.transition(JobState.CANCELLED, "cancelled by request", now=now)
        return self.transition(JobState.CANCELLING, "cancelling by request", view=self.view, now=now)
