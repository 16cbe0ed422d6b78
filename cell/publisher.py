"""The daemon's events, put on the network by a thread of their own, in order.

A Zenoh put costs the caller a few tens of microseconds on an idle machine, and
a third of a millisecond in the daemon while the cell works (it waits for the
session's threads, which wait for the interpreter): time the event loop would
otherwise take from the query of the job's next step.
"""

from __future__ import annotations

import logging
import queue
import threading

from robocell.wire.errors import TransportError
from robocell.wire.transport import BaseTransport

__all__ = ["Publisher"]

log = logging.getLogger(__name__)


class Publisher:
    """Puts ``(key, payload)`` on ``transport`` from its own thread, in the order given."""

    def __init__(self, transport: BaseTransport) -> None:
        self._transport = transport
        self._outbox: queue.SimpleQueue[tuple[str, str] | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="publisher", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def put(self, key: str, payload: str) -> None:
        """Put ``payload`` on ``key`` soon, after what was given before; returns at once."""
        self._outbox.put((key, payload))

    def close(self) -> None:
        """Put what is waiting, then end the thread (if it was started)."""
        self._outbox.put(None)
        if self._thread.is_alive():
            self._thread.join()

    def _run(self) -> None:
        while (item := self._outbox.get()) is not None:
            key, payload = item
            try:
                self._transport.put(key, payload)
            except TransportError as exc:  # the session is closing; a listener polls the status anyway
                log.warning("event on %s not published: %s", key, exc)
