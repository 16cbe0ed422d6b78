"""Clients of a cell: :class:`AsyncCellClient` for asyncio programs, :class:`CellClient` for scripts.

Both speak only the documented Zenoh keys (``wire/keys.py``); a program in any
language can do the same. From a script::

    with CellClient("tcp/127.0.0.1:7447", "cell1") as client:
        result = client.scan(ScanRequest(target=[0.6, 0.0, 0.03]), timeout=60)
        print(result.superquadric)
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable

from . import keys
from .access import roles_that_may, what_a_query_asks
from .errors import AccessDenied, CellError, LinkDown, NoResponder, RemoteError, TransportError
from .messages import CancelRequest, CellStatus, JobEvent, JobState, JobStatus, ScanRequest, ScanResult, parse
from .transport import Reply, Subscription, Transport

__all__ = ["AsyncCellClient", "CellClient", "JobFailed"]

log = logging.getLogger(__name__)
#: Events of jobs nobody waits for yet, kept for that many jobs: a job's first events can
#: arrive before the answer to its submit says which job it is.
_EARLY_JOBS = 256
_ALL_JOBS = "*"
_KEPT_TOKENS = 1024        # the tokens of this many of the jobs it submitted, for its cancels
_DAEMON_SEEN_S = 1.0       # how long a query that nobody answered waits to hear whether the daemon is up
_ANSWER_GRACE_S = 1.0      # how long a success heard waits for the answer to the result asked at the submit


class JobFailed(CellError):
    """The job ended failed or cancelled; the message says why, ``status`` is the job's last
    status and ``kind`` the class of the error that failed it (``EmergencyStop``, say), if any."""

    def __init__(self, message: str, *, status: JobStatus) -> None:
        super().__init__(message)
        self.status = status
        self.kind = status.error_kind


class AsyncCellClient:
    """Submit, watch, cancel and list the jobs of one cell, over its router."""

    def __init__(self, transport: Transport, cell_id: str, *, timeout: float = 5.0) -> None:
        self._transport = transport
        self.cell = cell_id
        self.timeout = timeout
        # One subscription to all the cell's events, opened by the first wait or watch, shared by all.
        self._events: Subscription | None = None
        self._dispatcher: asyncio.Task | None = None
        self._listeners: dict[str, list[asyncio.Queue]] = {}    # job id (or _ALL_JOBS): its watchers
        self._early: OrderedDict[str, list[JobEvent]] = OrderedDict()
        # The tokens of the jobs this client submitted (the newest few): its cancels show them.
        self._tokens: OrderedDict[str, str] = OrderedDict()

    @classmethod
    async def connect(cls, endpoint: str, cell_id: str, *, settings: dict | None = None,
                      timeout: float = 5.0) -> "AsyncCellClient":
        return cls(await Transport.open(endpoint, settings=settings), cell_id, timeout=timeout)

    async def close(self) -> None:
        if self._dispatcher is not None:
            self._dispatcher.cancel()
            await asyncio.gather(self._dispatcher, return_exceptions=True)
        if self._events is not None:
            self._events.close()
        await self._transport.close()

    async def __aenter__(self) -> "AsyncCellClient":
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.close()

    async def _ask(self, key: str, payload: str | None = None, parameters: str = "") -> bytes:
        try:
            reply = await self._transport.query(key, payload, timeout=self.timeout, parameters=parameters)
        except NoResponder:
            raise await self._unanswered(key) from None
        return reply.payload

    async def _unanswered(self, key: str) -> NoResponder:
        """Why nobody answered on one of the daemon's keys. Zenoh's access control drops a denied
        query as if nobody served it: a daemon whose liveliness token this user sees, and which
        still does not answer, was not asked, and the error says which roles may ask."""
        what = what_a_query_asks(key, self.cell)
        roles = roles_that_may("query", key, self.cell)
        may = f"only the {' and '.join(roles)} role{'s' if len(roles) > 1 else ''} may" if roles else "no role may"
        user = self._transport.user
        who = f"user {user!r}" if user is not None else "this session"
        try:
            daemon_up = bool(await self._transport.alive(keys.alive(self.cell, "daemon"), timeout=_DAEMON_SEEN_S))
        except (CellError, TimeoutError):
            daemon_up = False
        if daemon_up:
            return AccessDenied(f"{who} may not {what} in cell {self.cell} ({may}): the router's access control "
                                f"drops its query, though the cell's daemon is up")
        return NoResponder(f"nobody answers on {key}: no cell daemon is running for cell {self.cell}"
                           + (f", or {who} may not {what} there ({may})" if user is not None else ""))

    async def submit(self, request: ScanRequest, *, retry_s: float = 0.0) -> JobStatus:
        """Queue a scan; with ``request.request_id`` set, submitting again returns the same job.

        With a ``request_id``, ``retry_s`` > 0 sends the request again, for up to that
        many seconds, while no daemon answers (it is restarting, say) or its answer is
        lost: the daemon has stored the job at most once, whichever attempt reached it.

        Raises
        ------
        ValueError
            ``retry_s`` without a ``request_id``: a retry could make a second job.
        RemoteError
            The daemon refused the request (invalid, or the queue is full): not retried.
        TransportError
            No answer, after the retries.
        """
        if retry_s > 0 and request.request_id is None:
            raise ValueError("retrying a submit needs a request_id: without one a retry may make a second job")
        payload = request.model_dump_json()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + retry_s
        while True:
            try:
                status = parse(JobStatus, await self._ask(keys.submit(self.cell), payload))
            except RemoteError:
                raise
            except TransportError:
                if loop.time() >= deadline:
                    raise
            else:
                if status.token is not None:
                    self._tokens[status.job_id] = status.token
                    while len(self._tokens) > _KEPT_TOKENS:
                        self._tokens.popitem(last=False)
                return status
            await asyncio.sleep(0.1)

    async def cell_status(self, *, failures: int = 10) -> CellStatus:
        """The cell at a glance: its workers, each reconstructor's load, the queue, jobs by state,
        and the ``failures`` most recent failed jobs."""
        return parse(CellStatus, await self._ask(keys.status(self.cell), parameters=f"failures={failures}"))

    async def status(self, job_id: str) -> JobStatus:
        return parse(JobStatus, await self._ask(keys.job(self.cell, job_id)))

    async def result(self, job_id: str) -> ScanResult:
        return parse(ScanResult, await self._ask(keys.result(self.cell, job_id)))

    async def cancel(self, job_id: str, token: str | None = None) -> JobStatus:
        """Cancel the job; ``token`` is its submit's ``JobStatus.token`` (a daemon that issues
        tokens cancels only for it), by default the one this client got when it submitted the job."""
        token = token or self._tokens.get(job_id)
        payload = None if token is None else CancelRequest(token=token).model_dump_json()
        return parse(JobStatus, await self._ask(keys.cancel(self.cell, job_id), payload))

    async def list(self, states: set[JobState] | None = None, limit: int = 50) -> list[JobStatus]:
        parameters = f"limit={limit}"
        if states:
            parameters += ";state=" + ",".join(sorted(s.value for s in states))
        payload = await self._ask(keys.jobs(self.cell), parameters=parameters)
        return [JobStatus.model_validate(item) for item in json.loads(payload)]

    def listen(self) -> None:
        """Hear the cell's events from now on, so that a wait or watch begun after a submit
        still gets the job's first events. :meth:`scan` does this itself."""
        self._subscribe_events()

    async def events(self, job_id: str = "*") -> AsyncIterator[JobEvent]:
        """Events of one job (or, with ``"*"``, of every job of the cell), as they happen, until the
        caller stops iterating.

        Listening begins at the first iteration, or earlier with :meth:`listen`: a job's events
        that came between then and this call come first.
        """
        self.listen()
        queue = self._listen(job_id)
        try:
            while True:
                yield await queue.get()
        finally:
            self._unlisten(job_id, queue)

    async def wait(self, job_id: str, *, timeout: float, on_event: Callable[[JobEvent], None] | None = None,
                   poll_s: float = 1.0) -> JobStatus:
        """Wait until the job is finished and return its final status.

        Events go to ``on_event`` as they arrive; the status is polled too, so a
        missed event cannot make this wait forever.

        Raises
        ------
        TimeoutError
            If the job is not finished within ``timeout`` seconds.
        """
        final = await self._wait_finished(job_id, timeout=timeout, on_event=on_event, poll_s=poll_s)
        assert isinstance(final, JobStatus), "a result only when asked for"
        return final

    def _subscribe_events(self) -> bool:
        """Make sure this client hears every event of the cell; whether it already did."""
        if self._events is not None:
            return True
        self._events = self._transport.subscribe(keys.events(self.cell, "*"))
        self._dispatcher = asyncio.create_task(self._dispatch(self._events))
        return False

    async def _dispatch(self, subscription: Subscription) -> None:
        async for sample in subscription:
            try:
                event = parse(JobEvent, sample.payload)
            except ValueError as exc:
                log.warning("ignoring an event on %s: %s", sample.key, exc)
                continue
            for queue in self._listeners.get(_ALL_JOBS, ()):
                queue.put_nowait(event)
            queues = self._listeners.get(event.job_id)
            if queues:
                for queue in queues:
                    queue.put_nowait(event)
                continue
            self._early.setdefault(event.job_id, []).append(event)
            while len(self._early) > _EARLY_JOBS:
                self._early.popitem(last=False)

    def _listen(self, job_id: str) -> asyncio.Queue[JobEvent]:
        """A queue that gets the job's events (every job's, for ``"*"``), those heard early first."""
        queue: asyncio.Queue[JobEvent] = asyncio.Queue()
        if job_id != _ALL_JOBS:
            for early in self._early.pop(job_id, []):
                queue.put_nowait(early)
        self._listeners.setdefault(job_id, []).append(queue)
        return queue

    def _unlisten(self, job_id: str, queue: asyncio.Queue) -> None:
        queues = self._listeners[job_id]
        queues.remove(queue)
        if not queues:
            del self._listeners[job_id]

    async def _state_unless_away(self, job_id: str, known: JobState) -> JobState:
        """The job's state as the daemon tells it; ``known`` while the link to the router is down (restarting):
        the job goes on without this client, and a wait goes on and asks again once the link is back."""
        try:
            return (await self.status(job_id)).state
        except LinkDown:
            return known

    async def _wait_finished(self, job_id: str, *, timeout: float, on_event: Callable[[JobEvent], None] | None,
                             poll_s: float, heard_from_start: bool = False, want_result: bool = False,
                             answer: asyncio.Future[Reply] | None = None) -> JobStatus | ScanResult:
        """The daemon's word on the job's end, heard from its events (or, should one be lost, from
        polling its status): its final status, or with ``want_result`` the result of a success.

        ``heard_from_start``: this client was listening before the job was submitted, so no
        event of it can have been missed and the status need not be asked first. ``answer``: a
        result query already asked, that the daemon answers as the job ends (see :meth:`_ended`).
        """
        heard_from_start = self._subscribe_events() and heard_from_start
        queue = self._listen(job_id)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        try:
            # Asked after subscribing: an end in between is not missed.
            state = JobState.QUEUED if heard_from_start else await self._state_unless_away(job_id, JobState.QUEUED)
            ended = await self._ended_unless_away(job_id, state, want_result, answer) if state.finished else None
            if ended is not None:
                return ended
            while True:
                remaining = deadline - loop.time()
                if remaining <= 0:
                    raise TimeoutError(f"job {job_id} is still {state.value} after {timeout:g} s")
                try:
                    async with asyncio.timeout(min(poll_s, remaining)):
                        event = await queue.get()
                except TimeoutError:
                    state = await self._state_unless_away(job_id, state)  # a lost event cannot make this wait for ever
                    ended = await self._ended_unless_away(job_id, state, want_result, answer) if state.finished else None
                    if ended is not None:
                        return ended
                    continue
                if event.state.finished:
                    # An event is anyone's to publish on an open router: an end is believed only
                    # once the daemon confirms it (a forged one is dropped, and the wait goes on),
                    # and while the link is down it cannot: the polling asks again once it is back.
                    final = await self._ended_unless_away(job_id, event.state, want_result, answer)
                    if final is None:
                        continue
                    confirmed = final.state if isinstance(final, JobStatus) else JobState.SUCCEEDED
                    if confirmed is not event.state:
                        log.warning("ignoring a %s event for job %s, which the daemon says is %s",
                                    event.state.value, job_id, confirmed.value)
                        state = confirmed
                        if state.finished:
                            return final
                        continue
                    if on_event is not None:
                        on_event(event)
                    return final
                if on_event is not None:
                    on_event(event)
                state = event.state
        finally:
            self._unlisten(job_id, queue)

    async def _ended_unless_away(self, job_id: str, state: JobState, want_result: bool,
                                 answer: asyncio.Future[Reply] | None = None) -> JobStatus | ScanResult | None:
        """:meth:`_ended`, or None while the link to the router is down: the wait goes on, and asks again."""
        try:
            return await self._ended(job_id, state, want_result, answer)
        except LinkDown:
            return None

    async def _ended(self, job_id: str, state: JobState, want_result: bool,
                     answer: asyncio.Future[Reply] | None = None) -> JobStatus | ScanResult:
        """The daemon's word on a job that ``state`` says has ended: its status, or with ``want_result``
        and a success, its result. Only a job that succeeded has a result, so asking for it both
        confirms the success and fetches it, in one question: the question ``answer`` asked already,
        if the daemon answers it within a moment (it answers as it tells the end), else asked again."""
        if want_result and state is JobState.SUCCEEDED:
            if answer is not None:
                await asyncio.wait({answer}, timeout=_ANSWER_GRACE_S)
                if answer.done() and not answer.cancelled() and answer.exception() is None:
                    with contextlib.suppress(ValueError):
                        return parse(ScanResult, answer.result().payload)
            try:
                return await self.result(job_id)
            except RemoteError:  # no result: it did not succeed after all
                pass
        return await self.status(job_id)

    async def scan(self, request: ScanRequest, *, timeout: float = 120.0,
                   on_event: Callable[[JobEvent], None] | None = None, poll_s: float = 1.0) -> ScanResult:
        """Submit, wait, and return the result.

        Raises
        ------
        JobFailed
            If the job failed or was cancelled.
        TimeoutError
            If the job is not finished within ``timeout`` seconds.
        """
        self.listen()  # before submitting: every event of the job is heard
        status = await self.submit(request)
        # The result is asked of the daemon, not taken from the event: anyone may publish an event.
        # It is asked at once, and the daemon answers as the job ends: the answer is on its way when
        # the job's end is heard (a daemon that does not wait answers at once, and is asked again).
        answer = asyncio.ensure_future(self._transport.query(
            keys.result(self.cell, status.job_id), timeout=timeout + self.timeout, parameters=f"wait={timeout:g}"))
        answer.add_done_callback(lambda asked: asked.cancelled() or asked.exception())  # a failure is no news
        try:
            final = await self._wait_finished(status.job_id, timeout=timeout, on_event=on_event, poll_s=poll_s,
                                              heard_from_start=True, want_result=True, answer=answer)
        finally:
            answer.cancel()
        if isinstance(final, ScanResult):
            return final
        if final.state is JobState.SUCCEEDED:  # and no result to be had: the daemon's answer says why
            return await self.result(final.job_id)
        raise JobFailed(f"job {final.job_id} {final.state.value}: {final.error or 'no reason given'}", status=final)


class CellClient:
    """The blocking face of :class:`AsyncCellClient`, for scripts: runs its own event loop thread."""

    def __init__(self, endpoint: str, cell_id: str, *, settings: dict | None = None, timeout: float = 5.0) -> None:
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="robocell-client", daemon=True)
        self._thread.start()
        try:
            self._client = self._call(AsyncCellClient.connect(endpoint, cell_id, settings=settings,
                                                               timeout=timeout))
        except BaseException:
            self._stop_loop()
            raise

    def _call(self, coroutine, timeout: float | None = None):
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop).result(timeout)

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)
        self._loop.close()

    def close(self) -> None:
        try:
            self._call(self._client.close(), timeout=10)
        finally:
            self._stop_loop()

    def __enter__(self) -> "CellClient":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def submit(self, request: ScanRequest, *, retry_s: float = 0.0) -> JobStatus:
        return self._call(self._client.submit(request, retry_s=retry_s))

    def cell_status(self, *, failures: int = 10) -> CellStatus:
        return self._call(self._client.cell_status(failures=failures))

    def status(self, job_id: str) -> JobStatus:
        return self._call(self._client.status(job_id))

    def result(self, job_id: str) -> ScanResult:
        return self._call(self._client.result(job_id))

    def cancel(self, job_id: str, token: str | None = None) -> JobStatus:
        return self._call(self._client.cancel(job_id, token))

    def list(self, states: set[JobState] | None = None, limit: int = 50) -> list[JobStatus]:
        return self._call(self._client.list(states, limit))

    def wait(self, job_id: str, *, timeout: float, on_event: Callable[[JobEvent], None] | None = None) -> JobStatus:
        return self._call(self._client.wait(job_id, timeout=timeout, on_event=on_event))

    def scan(self, request: ScanRequest, *, timeout: float = 120.0,
             on_event: Callable[[JobEvent], None] | None = None) -> ScanResult:
        return self._call(self._client.scan(request, timeout=timeout, on_event=on_event))
