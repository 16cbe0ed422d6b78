"""Work handed out of the event loop in order: :func:`later` and :class:`Serial`.

The daemon's event loop only decides, asks and publishes. What a step records
(store, event, recording) is done after the step's query is on its way, so the
worker starts at once and the bookkeeping overlaps its work; the job store runs
in a thread of its own (an SQLite connection belongs to one thread), in order.
Writes that nobody waits for can be deferred (:meth:`Serial.defer`) to a moment
when the cell waits for something slow: on a machine with few processors, the
thread's work would otherwise compete with the round trips of instant moves.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

__all__ = ["later", "Serial"]

log = logging.getLogger(__name__)
_T = TypeVar("_T")


def later(function: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
    """Call ``function`` when the event loop next looks round, in the order of these calls."""
    asyncio.get_running_loop().call_soon(functools.partial(function, *args, **kwargs))


class Serial:
    """One thread that runs the calls given to it, in order.

    A call is handed to the thread when the event loop next looks round (see
    :func:`later`), so calls and posts keep the order they were made in. Deferred
    calls keep their order too: they go to the thread at the next :meth:`flush`, or
    before anything that is posted or called after them.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self._executor = ThreadPoolExecutor(1, thread_name_prefix=name)
        self._deferred: list[tuple[Callable[[], Any], Callable[[], None] | None]] = []

    def call(self, function: Callable[..., _T], *args: Any, ahead: bool = False,
             **kwargs: Any) -> asyncio.Future[_T]:
        """Run ``function`` in the thread after everything posted before; the future of its result.

        The call is posted now, not when the future is awaited: what is posted after it runs
        after it, even while the caller does something else before awaiting the answer.
        ``ahead``: before what is deferred, for a call that none of it can concern.
        """
        if not ahead:
            self.flush()
        loop = asyncio.get_running_loop()
        answer: asyncio.Future[_T] = loop.create_future()
        later(self._hand, functools.partial(function, *args, **kwargs), answer, loop)
        return answer

    def _hand(self, call: Callable[[], _T], answer: asyncio.Future[_T], loop: asyncio.AbstractEventLoop) -> None:
        if answer.cancelled():  # the caller gave up before the call was handed over: skip it
            return
        self._executor.submit(call).add_done_callback(
            lambda done: loop.call_soon_threadsafe(_settle, answer, done))

    def post(self, function: Callable[..., Any], *args: Any, then: Callable[[], None] | None = None,
             **kwargs: Any) -> None:
        """Run ``function`` in the thread after everything posted before; a failure is logged.

        ``then`` is called on the event loop once ``function`` has returned (or failed).
        """
        self.flush()
        later(self._post, functools.partial(function, *args, **kwargs), then)

    def defer(self, function: Callable[..., Any], *args: Any, then: Callable[[], None] | None = None,
              **kwargs: Any) -> None:
        """:meth:`post` ``function``, at the next :meth:`flush` (or before the next post or call)."""
        self._deferred.append((functools.partial(function, *args, **kwargs), then))

    def flush(self) -> None:
        """Post what is deferred: now is a good time for the thread to work."""
        for call, then in self._deferred:
            later(self._post, call, then)
        self._deferred.clear()

    def _post(self, call: Callable[[], Any], then: Callable[[], None] | None = None) -> None:
        future = self._executor.submit(call)
        future.add_done_callback(self._log_failure)
        if then is not None:
            loop = asyncio.get_running_loop()
            future.add_done_callback(lambda _: loop.call_soon_threadsafe(then))

    def _log_failure(self, future: Future[Any]) -> None:
        exc = future.exception()
        if exc is not None:
            log.error("%s: %s: %s", self.name, type(exc).__name__, exc, exc_info=exc)

    def close(self) -> None:
        """Run what is posted, then end the thread (what is still deferred is dropped: flush first)."""
        self._executor.shutdown(wait=True)


def _settle(answer: asyncio.Future[_T], done: Future[_T]) -> None:
    if answer.cancelled():
        return
    exc = done.exception()
    if exc is None:
        answer.set_result(done.result())
    else:
        answer.set_exception(exc)
