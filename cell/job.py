"""A job: its lifecycle as a table, after rclpy's action server (``ServerGoalHandle``), and its plan.

A job's life is a small table, :data:`TRANSITIONS`; a move it does not allow
raises :class:`IllegalTransition` at once instead of corrupting the job::

    queued ──▶ running ──────────────▶ succeeded
      │           ├──────────────────▶ failed
      │           ╰──▶ cancelling ──▶ cancelled | failed
      ╰──────────────────────────────▶ cancelled | failed

What a running job does (moving to view 2, reconstructing, picking) is not a
state of the table but its :class:`~wire.messages.Progress`: the step of its
plan that runs. The plan is a list of steps (``cell.steps``) that a step may
extend; what the job has done is its :class:`Checkpoint`, from which a
restarted daemon carries it on.

:class:`Job` holds what the steps gather and does no I/O; every change of a
job goes through its handle (``cell.handle``).
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from robocell.wire.errors import CellError
from robocell.wire.messages import Lifecycle, Progress, ScanRequest, ScanResult

if TYPE_CHECKING:
    from .steps import Step

__all__ = ["TRANSITIONS", "IllegalTransition", "Job", "Picture", "Checkpoint", "success_message"]

L = Lifecycle

#: Every legal move: from a state of a job's life, the states it may go to.
TRANSITIONS: dict[Lifecycle, frozenset[Lifecycle]] = {
    L.QUEUED: frozenset({L.RUNNING, L.FAILED, L.CANCELLED}),
    L.RUNNING: frozenset({L.CANCELLING, L.SUCCEEDED, L.FAILED}),
    L.CANCELLING: frozenset({L.CANCELLED, L.FAILED}),
    L.SUCCEEDED: frozenset(),
    L.FAILED: frozenset(),
    L.CANCELLED: frozenset(),
}


class IllegalTransition(CellError):
    """A job was asked to move where its table does not allow: a bug, or a request that comes too
    late (cancelling a job that has ended)."""

    def __init__(self, job_id: str, state: Lifecycle, to: Lifecycle) -> None:
        super().__init__(f"job {job_id} is {state.value}: it cannot become {to.value}")
        self.state, self.to = state, to


def check_transition(job_id: str, state: Lifecycle, to: Lifecycle) -> None:
    """Raise :class:`IllegalTransition` unless :data:`TRANSITIONS` allows ``state`` → ``to``."""
    if to not in TRANSITIONS[state]:
        raise IllegalTransition(job_id, state, to)


@dataclass
class Picture:
    """One picture a job took, and where from."""

    jpeg: bytes
    T_base_flange: np.ndarray
    T_base_cam: np.ndarray

    def poses(self) -> str:
        """Where it was taken from, as the store keeps it (JSON)."""
        return json.dumps({"T_base_flange": self.T_base_flange.tolist(), "T_base_cam": self.T_base_cam.tolist()})

    @classmethod
    def kept(cls, jpeg: bytes, poses: str) -> Picture:
        """The picture the store kept; ``ValueError`` if its poses cannot be read."""
        try:
            where = json.loads(poses)
            return cls(jpeg, np.asarray(where["T_base_flange"], dtype=np.float64),
                       np.asarray(where["T_base_cam"], dtype=np.float64))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"a kept picture's poses cannot be read: {exc}") from None


class Checkpoint(BaseModel):
    """What a job has done, on disk: its plan so far (each step as ``Step.spec()``), and how many
    of its steps are done. Its pictures are kept beside it (``cell.pictures``)."""

    model_config = ConfigDict(extra="forbid")
    plan: list[dict[str, Any]] = Field(min_length=1)
    done: int = Field(ge=0)
    #: The step that began last (``done`` while none runs): a restart knows what was under way.
    began: int | None = None


@dataclass
class Job:
    """One job: its lifecycle, its plan, and what its steps gathered on the way."""

    job_id: str
    request: ScanRequest
    plan: list[Step]
    lifecycle: Lifecycle = Lifecycle.QUEUED
    progress: Progress | None = None
    #: Steps of the plan done (the next to run is ``plan[done]``).
    done: int = 0
    started: float = 0.0
    captures: list[Picture] = field(default_factory=list)
    #: Where the flange stands, as the robot last reported it.
    flange: np.ndarray | None = None
    #: What the job waited for, seconds: see ``ScanResult.durations_s``.
    durations_s: dict[str, float] = field(default_factory=dict)
    result: ScanResult | None = None
    #: A pick's flange poses by name ("above", "grasp", "lift", ...), once a grasp is chosen.
    pick_poses: dict[str, np.ndarray] = field(default_factory=dict)
    #: Why the job's recording cannot be written, if it cannot.
    recording_error: str | None = None
    #: The task that runs the job's steps, once it runs.
    task: asyncio.Task | None = None

    def checkpoint(self, *, began: int | None = None) -> Checkpoint:
        return Checkpoint(plan=[step.spec() for step in self.plan], done=self.done, began=began)


def success_message(result: ScanResult) -> str:
    """What a success says: who reconstructed it, how long it took, and how its pick went."""
    total = result.timings_ms.get("total", float("nan"))
    attempt = f" (attempt {result.attempts})" if result.attempts > 1 else ""
    message = f"reconstructed by {result.worker} in {total:.1f} ms{attempt}"
    if result.pick is not None:
        held = {True: "held", False: "missed", None: "closed on it"}[result.pick.held]
        message += f"; picked with grasp {result.pick.grasp}: {held}" + (", placed" if result.pick.placed else "")
    return message
