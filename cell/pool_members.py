"""What :class:`cell.pool.ReconstructorPool` knows of its workers and callers, and the errors of
an attempt (``cell.pool``'s text says how they are used)."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

from robocell.wire.errors import CellError, NoResponder, RemoteError, TransportError, TransportTimeout
from robocell.wire.transport import Reply

__all__ = ["AttemptFailed", "NoReconstructor"]


class AttemptFailed(CellError):
    """One attempt failed in a way another worker might not: ``worker`` died, hung, ran out of time
    or answered an error (``reason``)."""

    def __init__(self, worker: str, reason: str) -> None:
        super().__init__(f"{worker}: {reason}")
        self.worker = worker
        self.reason = reason


class NoReconstructor(CellError):
    """No live, healthy reconstruction worker appeared within the wait."""


@dataclass
class _Worker:
    """What the pool knows of one worker."""

    worker: str
    joined: float                               # monotonic time its token appeared
    capacity: int = 1                           # until it says
    heard: float | None = None                  # monotonic time of its last heartbeat
    reported: frozenset[str] = frozenset()      # tickets in flight, by its last heartbeat
    reported_in_flight: int = 0                 # in flight, by its last heartbeat (ticketless included)
    mine: set[str] = field(default_factory=set)             # this pool's requests there, unanswered
    answered: dict[str, float] = field(default_factory=dict)  # this pool's answered tickets -> when
    hung: bool = False
    lost: asyncio.Event = field(default_factory=asyncio.Event)  # set when it dies or hangs
    lost_reason: str = ""
    last_sent: float = float("-inf")
    sent: int = 0
    failed: int = 0
    proven: bool = False                        # one of its answers was checked and found right
    refused: int = 0                            # answers the daemon checked and refused

    @property
    def load(self) -> int:
        """Requests in flight there, from every cell, as well as this pool can tell."""
        stale = sum(1 for ticket in self.answered if ticket in self.reported)
        return max(0, self.reported_in_flight - stale) + len(self.mine - self.reported)

    def silence(self, now: float) -> float:
        return now - (self.heard if self.heard is not None else self.joined)


@dataclass
class _Waiter:
    """A caller waiting for a worker: the pool hands it one by setting ``granted``."""

    ticket: str
    avoid: set[str]
    granted: asyncio.Future


def _attempt_error(exc: TransportError, timeout: float) -> str:
    if isinstance(exc, TransportTimeout):
        return f"no answer within {timeout:g} s"
    if isinstance(exc, NoResponder):
        return "nobody answers on its key (it went away)"
    if isinstance(exc, RemoteError):
        return f"answered with an error: {exc}"
    return str(exc)


def _exception(task: asyncio.Future[Reply]) -> BaseException | None:
    """The task's exception, if it ended with one (None if it is not done or was cancelled)."""
    return task.exception() if task.done() and not task.cancelled() else None
