"""The shared pool of reconstruction workers, as one cell daemon sees and uses it.

Every worker announces itself (liveliness token), its health and its load
(heartbeat: capacity, requests in flight and their tickets); the contract is
in ``wire/keys.py``. :class:`ReconstructorPool` follows them and runs one
*attempt* at a reconstruction at a time for its caller::

    pool = ReconstructorPool(transport, heartbeat_s=5.0)
    pool.start()
    worker, reply = await pool.run(ticket, payload, attachment, timeout=60, wait_s=10)

``run`` waits for a live, healthy worker with a free slot, sends the request
to the one with the lowest ``in_flight / capacity``, and returns its reply;
should the worker die (its token goes), hang (its heartbeat falls silent for
``heartbeat_s``), run out of time or answer an error, ``run`` raises
:class:`AttemptFailed` naming the worker and why. Deciding whether to try
again, and where not to, is the caller's (the daemon's).

Load is counted across cells: a worker's ``in_flight`` comes from its own
heartbeat, so it includes the requests of every daemon on the network; to it
the pool adds what it sent since that heartbeat, and takes off what was
answered since. A worker is sent at most ``capacity`` requests at a time by
this reckoning; when every worker is full, callers wait in a queue, and each
free slot goes to the caller that has waited longest.

No worker is trusted on its word (issue 23: a token and a heartbeat are all a
fake worker needs to take jobs):

- A heartbeat counts only for the worker whose key it came on: a
  ``WorkerLoad`` naming worker ``a`` published under ``heartbeat/b`` is
  ignored, and so is an info answer from another key. Under the router's
  access control each worker may publish only under its own id
  (``wire/access.py``), so nobody can make a worker look busy or idle.
- A worker is sent work only once it has said what it is (a heartbeat or an
  info answer): a bare liveliness token takes no job.
- A worker is *proven* once the daemon has checked one of its answers and
  found it right (:meth:`ReconstructorPool.confirm`). A free proven worker is
  always chosen before a new one; a new one gets work only when no proven
  worker has a free slot. A worker whose answer was refused
  (:meth:`ReconstructorPool.refuse`) is proven no more.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import time
from collections.abc import Callable, Collection
from typing import Any

from robocell.wire import keys
from robocell.wire.errors import LinkDown, NoResponder, TransportError
from robocell.wire.messages import ReconstructorStatus, WorkerLoad, parse
from robocell.wire.transport import Reply, BaseTransport

from .pool_members import AttemptFailed, NoReconstructor, _attempt_error, _exception, _Waiter, _Worker

__all__ = ["ReconstructorPool", "AttemptFailed", "NoReconstructor"]

log = logging.getLogger(__name__)
_INFO_TIMEOUT_S = 2.0
_GONE_GRACE_S = 0.5         # after "nobody answers", how long to wait for the token's withdrawal
_ANSWERED_MEMORY_S = 5.0    # how long an answered ticket may still show in a late heartbeat


class ReconstructorPool:
    """The reconstruction workers of the network, from one Zenoh session; see the module's text.

    ``heartbeat_s``: a worker silent this long is taken for hung. ``clock`` is
    monotonic seconds (for tests). Use from one event loop; :meth:`start`
    subscribes, :meth:`close` undoes it.
    """

    def __init__(self, transport: BaseTransport, *, heartbeat_s: float, clock=time.monotonic) -> None:
        self._transport = transport
        self.heartbeat_s = heartbeat_s
        self._clock = clock
        self._workers: dict[str, _Worker] = {}
        self._waiters: collections.deque[_Waiter] = collections.deque()   # oldest first
        self._membership = asyncio.Event()      # set (and replaced) when workers come, go, hang or recover
        self._tasks: set[asyncio.Task] = set()

    # --- lifecycle -------------------------------------------------------------------------

    def start(self) -> None:
        self._spawn(self._follow(self._transport.watch_liveliness(keys.RECONSTRUCTORS_ALIVE),
                                 lambda change: self._on_token(*change)))
        self._spawn(self._follow(self._transport.subscribe(keys.RECONSTRUCTORS_HEARTBEAT),
                                 lambda sample: self._on_heartbeat(sample.payload, sample.key,
                                                                   keys.reconstructor_heartbeat)))
        self._spawn(self._check_heartbeats())

    async def close(self) -> None:
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    def _spawn(self, coroutine) -> asyncio.Task:
        task = asyncio.create_task(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    async def _follow(self, subscription, handle) -> None:
        try:
            async for item in subscription:
                handle(item)
        finally:
            subscription.close()

    # --- what the workers say ---------------------------------------------------------------

    @property
    def waiting(self) -> int:
        """Callers waiting for a worker, or for a free slot."""
        return len(self._waiters)

    def _notify(self) -> None:
        """Something changed that may free a slot: hand free slots to the waiting callers, oldest first."""
        if not self._waiters:
            return
        healthy = [r for r in self._workers.values() if not r.hung]
        for waiter in list(self._waiters):
            if waiter.granted.done():       # its caller gave up
                self._waiters.remove(waiter)
                continue
            record = self._choose(healthy, waiter.avoid)
            if record is None:
                if not any(r.load < r.capacity for r in healthy):
                    break                   # nothing free for anyone
                continue                    # what is free, this caller would rather avoid
            self._grant(record, waiter.ticket)
            waiter.granted.set_result(record)
            self._waiters.remove(waiter)

    def _members_changed(self) -> None:
        """Wake the waiting callers to look again whether any worker is there at all."""
        self._membership.set()
        self._membership = asyncio.Event()
        self._notify()

    def _grant(self, record: _Worker, ticket: str) -> None:
        record.mine.add(ticket)             # its slot is taken from now on
        record.sent += 1
        record.last_sent = self._clock()

    def _on_token(self, key: str, alive: bool) -> None:
        worker = key.rsplit("/", 1)[-1]
        if alive:
            if worker not in self._workers:
                self._workers[worker] = _Worker(worker, joined=self._clock())
                log.info("reconstructor %s joined", worker)
                self._spawn(self._ask_info(worker))
        else:
            record = self._workers.pop(worker, None)
            if record is not None:
                self._lose(record, "the worker is gone (its liveliness token was withdrawn)")
                log.warning("reconstructor %s left", worker)
        self._members_changed()

    async def _ask_info(self, worker: str) -> None:
        """Capacity and load at once, rather than at the next heartbeat."""
        try:
            reply = await self._transport.query(keys.reconstructor_info(worker), timeout=_INFO_TIMEOUT_S)
        except TransportError as exc:
            log.debug("no info from reconstructor %s: %s", worker, exc)
            return
        self._on_heartbeat(reply.payload, reply.key, keys.reconstructor_info)

    def _on_heartbeat(self, payload: bytes, key: str, key_of: Callable[[str], str]) -> None:
        """A worker's load, from its heartbeat or its info answer, which came on ``key``: counted
        only if ``key`` is that worker's own (``key_of(worker)``)."""
        try:
            load = parse(WorkerLoad, payload)
        except ValueError as exc:
            log.warning("ignoring a bad heartbeat: %s", exc)
            return
        if key != key_of(load.worker):
            # Debug only: whoever forges them can send thousands a second, and would fill the log.
            log.debug("ignoring a heartbeat for %s that came on %s, not on its own key", load.worker, key)
            return
        record = self._workers.get(load.worker)
        if record is None:
            return  # no token (yet, or any more): not a member
        now = self._clock()
        record.capacity = load.capacity
        record.heard = now
        record.reported = frozenset(load.tickets)
        record.reported_in_flight = load.in_flight
        record.answered = {t: at for t, at in record.answered.items()
                           if t in record.reported and now - at < _ANSWERED_MEMORY_S}
        if record.hung:
            record.hung = False
            record.lost = asyncio.Event()
            log.warning("reconstructor %s is answering again", load.worker)
            self._members_changed()
        else:
            self._notify()

    def _lose(self, record: _Worker, reason: str) -> None:
        record.lost_reason = reason
        record.lost.set()

    async def _check_heartbeats(self) -> None:
        period = min(0.25, self.heartbeat_s / 4)
        expected = self._clock() + period
        while True:
            await asyncio.sleep(period)
            now = self._clock()
            # After a stall of this loop, heartbeats that came meanwhile may not be counted yet.
            stalled = now - expected > self.heartbeat_s / 2
            expected = now + period
            if stalled:
                continue
            for record in self._workers.values():
                silence = record.silence(now)
                if not record.hung and silence > self.heartbeat_s:
                    record.hung = True
                    heard = "no heartbeat" if record.heard is not None else "no heartbeat ever"
                    self._lose(record, f"{heard} for {silence:.1f} s (hung, or its host or network is)")
                    log.warning("reconstructor %s: %s", record.worker, record.lost_reason)
                    self._members_changed()

    # --- sending work -----------------------------------------------------------------------

    async def run(self, ticket: str, payload: bytes, attachment: str, *, timeout: float, wait_s: float,
                  avoid: Collection[str] = frozenset()) -> tuple[str, Reply]:
        """One attempt: the worker that answered and its reply.

        Waits for a live, healthy worker with a free slot (preferring those not in
        ``avoid``); gives up if there is no live, healthy worker at all for ``wait_s``
        seconds. ``timeout`` bounds the worker's answer.

        Raises
        ------
        NoReconstructor
            No live, healthy worker within ``wait_s``.
        AttemptFailed
            The worker died, hung, did not answer within ``timeout``, or answered an error.
        LinkDown
            The link to the router went down during the attempt: not the worker's failure.
        """
        record = await self._acquire(ticket, avoid, wait_s)
        losses = self._transport.link_losses
        lost = record.lost
        query = self._transport.start_query(keys.reconstructor(record.worker), payload, attachment=attachment,
                                            timeout=timeout)
        gone: asyncio.Future[Any] = asyncio.ensure_future(lost.wait())
        try:
            await asyncio.wait({query, gone}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            gone.cancel()
            abandoned = not query.done()
            if abandoned:
                query.cancel()  # its answer, should it come, is dropped with the query
            record.mine.discard(ticket)
            if not abandoned:
                record.answered[ticket] = self._clock()
            self._notify()
        if self._transport.link_losses != losses or isinstance(_exception(query), LinkDown):
            raise LinkDown(f"the link to the Zenoh router went down while {record.worker} worked on {ticket}")
        if abandoned:
            record.failed += 1
            raise AttemptFailed(record.worker, record.lost_reason)
        try:
            return record.worker, query.result()
        except TransportError as exc:
            record.failed += 1
            reason = _attempt_error(exc, timeout)
        if isinstance(query.exception(), NoResponder):
            # A worker killed outright drops its queries a moment before its token: say why.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(_GONE_GRACE_S):
                    await lost.wait()
            if lost.is_set():
                reason = record.lost_reason
        raise AttemptFailed(record.worker, reason)

    async def _acquire(self, ticket: str, avoid: Collection[str], wait_s: float) -> _Worker:
        """The worker to send ``ticket`` to, its slot taken; once there is one with a free slot."""
        if not self._waiters:  # nobody waits before this caller
            record = self._choose([r for r in self._workers.values() if not r.hung], avoid)
            if record is not None:
                self._grant(record, ticket)
                return record
        waiter = _Waiter(ticket, set(avoid), asyncio.get_running_loop().create_future())
        self._waiters.append(waiter)
        self._notify()      # a slot that those before it would rather avoid may suit this caller
        try:
            deadline = None     # while no healthy worker is there at all: when to give up
            while True:
                if any(not r.hung for r in self._workers.values()):
                    deadline, delay = None, None
                else:
                    now = self._clock()
                    deadline = deadline if deadline is not None else now + wait_s
                    if now >= deadline:
                        raise NoReconstructor(self._none_message(wait_s))
                    delay = deadline - now
                members = asyncio.ensure_future(self._membership.wait())
                try:
                    await asyncio.wait({waiter.granted, members}, timeout=delay,
                                       return_when=asyncio.FIRST_COMPLETED)
                finally:
                    members.cancel()
                if waiter.granted.done():
                    return waiter.granted.result()
        except BaseException:
            if waiter.granted.done() and not waiter.granted.cancelled():
                waiter.granted.result().mine.discard(ticket)     # granted, but nobody will send: free it
                self._notify()
            else:
                waiter.granted.cancel()
            raise
        finally:
            if waiter in self._waiters:
                self._waiters.remove(waiter)

    def _choose(self, healthy: list[_Worker], avoid: Collection[str]) -> _Worker | None:
        """The least loaded worker with a free slot, not one to avoid if another will do, a proven
        one before a new one; None: wait. A worker not heard from yet gets nothing."""
        heard = [r for r in healthy if r.heard is not None]
        preferred = [r for r in heard if r.worker not in avoid] or heard
        free = [r for r in preferred if r.load < r.capacity]
        if not free:
            return None
        return min(free, key=lambda r: (not r.proven, r.load / r.capacity, r.last_sent))

    # --- what the daemon found of their answers --------------------------------------------

    def confirm(self, worker: str) -> None:
        """``worker``'s answer was checked (``cell.verify``) and found right: it is proven."""
        record = self._workers.get(worker)
        if record is not None and not record.proven:
            record.proven = True
            log.info("reconstructor %s is proven: its answer agreed with the pictures", worker)

    def refuse(self, worker: str, reason: str) -> None:
        """``worker``'s answer was checked and refused: it is proven no more, and the attempt counts
        as failed."""
        record = self._workers.get(worker)
        if record is not None:
            record.proven = False
            record.refused += 1
            record.failed += 1
            log.warning("reconstructor %s answered what the pictures refute: %s", worker, reason)

    def _none_message(self, wait_s: float) -> str:
        if not self._workers:
            return f"no reconstruction worker is running (waited {wait_s:g} s)"
        silent = ", ".join(f"{r.worker}: {r.lost_reason}" for r in self._workers.values())
        return f"no reconstruction worker is answering (waited {wait_s:g} s): {silent}"

    # --- looking on -------------------------------------------------------------------------

    def snapshot(self) -> list[ReconstructorStatus]:
        """Every live worker, by id."""
        now = self._clock()
        return [ReconstructorStatus(worker=r.worker, capacity=r.capacity, in_flight=r.load,
                                    in_flight_here=len(r.mine), tickets_here=sorted(r.mine), healthy=not r.hung,
                                    heartbeat_age_s=None if r.heard is None else round(now - r.heard, 3),
                                    sent=r.sent, failed=r.failed, proven=r.proven, refused=r.refused)
                for r in sorted(self._workers.values(), key=lambda r: r.worker)]
