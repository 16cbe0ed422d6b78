"""Asking the cell's workers: a query repeated while its part is away (the link to the router
down, the worker gone, its camera not answering), within the cell's outage allowance."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

from robocell.wire.errors import (CameraConnectionError, CameraError, CameraTimeout, CellError, LinkDown, NoResponder,
                         RemoteError, TransportError, TransportTimeout, wire_kind)
from robocell.wire.messages import Message
from robocell.wire.transport import Reply, BaseTransport

from .job import Job
from .presence import Absent, Presence
from .steps import StepFailed

__all__ = ["Asker"]

_RETRY_S = 0.5              # between two tries of a step whose part is away


class Asker:
    """Asks the workers of a cell through ``transport``; ``note`` tells a job's listeners why it waits."""

    def __init__(self, transport: BaseTransport, presence: Presence, outage_s: float,
                 note: Callable[[Job, str], Awaitable[None]]) -> None:
        self._transport, self._presence, self._outage_s, self._note = transport, presence, outage_s, note

    async def ask(self, job: Job, part: str, key: str, message: Message, timeout: float) -> Reply:
        loop = asyncio.get_running_loop()
        allowance = self._outage_s
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
                await self._note(job, f"{reason}: waiting up to {allowance:g} s, then trying again")
            await asyncio.sleep(min(_RETRY_S, max(0.0, deadline - loop.time())))

    async def wait_link(self, job: Job) -> None:
        allowance = self._outage_s
        if not self._transport.link_up:
            await self._note(job, f"the link to the Zenoh router is down: waiting up to {allowance:g} s")
        try:
            await self._transport.wait_link(allowance)
        except LinkDown as exc:
            raise StepFailed(str(exc), kind="LinkDown") from None


def _briefly_away(exc: CellError) -> bool:
    """Whether ``exc`` says a part is away for now (a camera that does not answer, or answers a
    server error), rather than that the request was wrong."""
    if isinstance(exc, (CameraConnectionError, CameraTimeout)):
        return True
    return isinstance(exc, CameraError) and exc.status is not None and exc.status >= 500
