"""Which of a cell's own workers (robot, camera) are up, from their liveliness tokens."""

from __future__ import annotations

import asyncio
import logging

from robocell.wire import keys
from robocell.wire.transport import BaseTransport

__all__ = ["Presence", "Absent"]

log = logging.getLogger(__name__)


class Absent(Exception):
    """A worker did not come within the wait; the message says which and how long."""


class Presence:
    """Follows ``robocell/<cell>/alive/*``; :meth:`wait_for` a part before asking it."""

    def __init__(self, transport: BaseTransport, cell: str) -> None:
        self._transport, self._cell = transport, cell
        self._alive: set[str] = set()
        self._changed = asyncio.Condition()

    def __contains__(self, part: str) -> bool:
        return part in self._alive

    async def follow(self) -> None:
        """Keep up with the tokens until cancelled."""
        subscription = self._transport.watch_liveliness(keys.alive(self._cell))
        try:
            async for key, alive in subscription:
                part = key.rsplit("/", 1)[-1]
                if part == "daemon":
                    continue  # the daemon's own token, not a worker
                (self._alive.add if alive else self._alive.discard)(part)
                log.info("%s worker %s", part, "is up" if alive else "is gone")
                async with self._changed:
                    self._changed.notify_all()
        finally:
            subscription.close()

    async def wait_for(self, part: str, wait_s: float) -> None:
        """Return once ``part`` is up.

        Raises
        ------
        Absent
            If it is not up within ``wait_s`` seconds.
        """
        if part in self._alive:
            return
        try:
            async with asyncio.timeout(wait_s), self._changed:
                await self._changed.wait_for(lambda: part in self._alive)
        except TimeoutError:
            raise Absent(f"no {part} worker is running (waited {wait_s:g} s)") from None
