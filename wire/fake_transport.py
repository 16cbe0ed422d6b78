"""An in-memory network of transports, for tests (after httpx's ``MockTransport``).

:class:`MemoryNetwork` stands for a router and :class:`MemoryTransport` for a session on it;
everything happens on one asyncio event loop, on its clock, so that a test can run the
pool's and the daemon's decisions on a clock of its own. It behaves as Zenoh does where the
cell relies on it: a query goes to one queryable of its key (none: ``NoResponder``), a
handler's error comes back as the same class, a query on a key with wildcards reaches no
handler, a session that closes takes its tokens and its queryables with it (a query it was
answering ends with no reply), and liveliness subscribers hear the tokens there already.

What only a real router shows (liveliness across processes, access control, reconnection)
is tested against one. :meth:`MemoryNetwork.freeze` stands in for a process whose event
loop hangs: its tokens stay, but it publishes nothing and answers nothing until thawed.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import zenoh

from .errors import LinkDown, NoResponder, TransportTimeout
from .transport import (JSON, BaseTransport, Handler, Reply, Request, Subscription, error_reply, oversized,
                        remote_error)

__all__ = ["MemoryNetwork", "MemoryTransport"]


def _matches(expression: str, key: str) -> bool:
    return zenoh.KeyExpr(expression).intersects(zenoh.KeyExpr(key))


def _as_bytes(value: bytes | str | None) -> bytes | None:
    return value.encode() if isinstance(value, str) else value


@dataclass
class _Queryable:
    owner: MemoryTransport
    key: str
    handler: Handler
    limit: int | None = None
    answering: set[asyncio.Future[Any]] = field(default_factory=set)


class _Token:
    def __init__(self, owner: MemoryTransport, key: str) -> None:
        self.owner, self.key = owner, key

    def undeclare(self) -> None:
        self.owner.network._withdraw(self)


class MemoryNetwork:
    """The router of some :class:`MemoryTransport` sessions."""

    def __init__(self) -> None:
        self._queryables: list[_Queryable] = []
        self._subscriptions: list[tuple[MemoryTransport, str, Subscription]] = []
        self._watchers: list[tuple[MemoryTransport, str, Subscription]] = []
        self._tokens: list[_Token] = []
        self._frozen: dict[MemoryTransport, asyncio.Event] = {}
        self._names = itertools.count(1)

    def session(self) -> MemoryTransport:
        """A new session on this network."""
        return MemoryTransport(self, f"memory/{next(self._names)}")

    def freeze(self, transport: MemoryTransport) -> None:
        """``transport``'s process hangs: it answers and publishes nothing; its tokens stay."""
        self._frozen.setdefault(transport, asyncio.Event())

    def thaw(self, transport: MemoryTransport) -> None:
        """It wakes: the queries it was asked meanwhile are answered now."""
        woken = self._frozen.pop(transport, None)
        if woken is not None:
            woken.set()

    def _deliver(self, sender: MemoryTransport, key: str, item: Reply) -> None:
        if sender in self._frozen:
            return
        for owner, expression, subscription in self._subscriptions:
            if not owner.closed and _matches(expression, key):
                subscription._queue.put_nowait(item)

    def _declare(self, token: _Token) -> None:
        self._tokens.append(token)
        self._tell_watchers(token.key, True)

    def _withdraw(self, token: _Token) -> None:
        if token in self._tokens:
            self._tokens.remove(token)
            self._tell_watchers(token.key, False)

    def _tell_watchers(self, key: str, alive: bool) -> None:
        for owner, expression, subscription in self._watchers:
            if not owner.closed and _matches(expression, key):
                subscription._queue.put_nowait((key, alive))

    def _tokens_matching(self, expression: str) -> Iterator[_Token]:
        return (token for token in self._tokens if _matches(expression, token.key))

    async def _ask(self, queryable: _Queryable, request: Request) -> Reply:
        thawed = self._frozen.get(queryable.owner)
        if thawed is not None:
            await thawed.wait()
        if queryable.limit is not None and (refused := oversized(len(request.payload or b""), queryable.limit)):
            raise remote_error(refused.model_dump_json().encode())
        try:
            response = await queryable.handler(request)
        except Exception as exc:
            raise remote_error(error_reply(request, exc).model_dump_json().encode()) from None
        return Reply(request.key, _as_bytes(response.payload) or b"", response.encoding,
                     _as_bytes(response.attachment))

    def _forget(self, entry: tuple[MemoryTransport, str, Subscription]) -> None:
        for entries in (self._subscriptions, self._watchers):
            if entry in entries:
                entries.remove(entry)

    def _drop(self, transport: MemoryTransport) -> None:
        """A session closed: its tokens and queryables go, the queries it was answering end unanswered."""
        for token in [t for t in self._tokens if t.owner is transport]:
            self._withdraw(token)
        for queryable in [q for q in self._queryables if q.owner is transport]:
            self._queryables.remove(queryable)
            for answering in list(queryable.answering):
                answering.cancel()
        self._subscriptions = [s for s in self._subscriptions if s[0] is not transport]
        self._watchers = [w for w in self._watchers if w[0] is not transport]
        self._frozen.pop(transport, None)


class MemoryTransport(BaseTransport):
    """A session on a :class:`MemoryNetwork` (made by :meth:`MemoryNetwork.session`)."""

    def __init__(self, network: MemoryNetwork, endpoint: str) -> None:
        self.network = network
        self.endpoint = endpoint
        self.link_losses = 0
        self.closed = False
        self._link = asyncio.Event()
        self._link.set()
        self._link_lost = asyncio.Event()

    # --- the link --------------------------------------------------------------------------

    @property
    def link_up(self) -> bool:
        return self._link.is_set()

    def set_link(self, up: bool) -> None:
        """The test cuts the link to the router, or mends it."""
        if up:
            self._link.set()
        elif self._link.is_set():
            self._link.clear()
            self.link_losses += 1
            self._link_lost.set()
            self._link_lost = asyncio.Event()

    async def wait_link(self, timeout: float) -> None:
        try:
            async with asyncio.timeout(timeout):
                await self._link.wait()
        except TimeoutError:
            raise LinkDown(f"the link to the router at {self.endpoint} is down (waited {timeout:g} s for it)") from None

    async def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.network._drop(self)

    # --- queries ---------------------------------------------------------------------------

    async def query(self, key: str, payload: bytes | str | None = None, *, timeout: float,
                    attachment: bytes | str | None = None, encoding: str = JSON,
                    parameters: str = "") -> Reply:
        return await self.start_query(key, payload, timeout=timeout, attachment=attachment, encoding=encoding,
                                      parameters=parameters)

    def start_query(self, key: str, payload: bytes | str | None = None, *, timeout: float,
                    attachment: bytes | str | None = None, encoding: str = JSON,
                    parameters: str = "") -> asyncio.Future[Reply]:
        loop = asyncio.get_running_loop()
        if not self.link_up:
            failed: asyncio.Future[Reply] = loop.create_future()
            failed.set_exception(LinkDown(f"the link to the router at {self.endpoint} is down: nothing sent on {key}"))
            return failed
        params = dict(pair.split("=", 1) for pair in parameters.split(";") if "=" in pair)
        request = Request(key, params, _as_bytes(payload), _as_bytes(attachment))
        return asyncio.ensure_future(self._wait_reply(key, request, timeout))

    async def _wait_reply(self, key: str, request: Request, timeout: float) -> Reply:
        wildcards = "*" in key or "$*" in key
        queryable = next((q for q in self.network._queryables if not wildcards and _matches(q.key, key)), None)
        if queryable is None:
            await asyncio.sleep(0)
            raise NoResponder(f"nobody answers on {key}")
        answer = asyncio.ensure_future(self.network._ask(queryable, request))
        queryable.answering.add(answer)
        lost = asyncio.ensure_future(self._link_lost.wait())
        try:
            done, _ = await asyncio.wait({answer, lost}, timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
        finally:
            lost.cancel()
            queryable.answering.discard(answer)
        if answer in done:
            if answer.cancelled():  # its session closed before it answered
                raise NoResponder(f"nobody answers on {key}")
            return answer.result()
        answer.cancel()
        if lost in done:
            raise LinkDown(f"the link to the router at {self.endpoint} went down before the answer on {key}")
        raise TransportTimeout(f"no answer on {key} within {timeout:g} s")

    def serve(self, key: str, handler: Handler, *, complete: bool = True, limit: int | None = None) -> None:
        self.network._queryables.append(_Queryable(self, key, handler, limit))

    # --- publications and liveliness ---------------------------------------------------------

    def put(self, key: str, payload: bytes | str, *, encoding: str = JSON,
            attachment: bytes | str | None = None) -> None:
        self.network._deliver(self, key, Reply(key, _as_bytes(payload) or b"", encoding, _as_bytes(attachment)))

    def subscribe(self, key: str) -> Subscription:
        subscription = Subscription()
        entry = (self, key, subscription)
        self.network._subscriptions.append(entry)
        subscription._undeclare = lambda: self.network._forget(entry)
        return subscription

    def declare_token(self, key: str) -> _Token:
        token = _Token(self, key)
        self.network._declare(token)
        return token

    def watch_liveliness(self, key_expr: str) -> Subscription:
        subscription = Subscription()
        for token in self.network._tokens_matching(key_expr):
            subscription._queue.put_nowait((token.key, True))
        entry = (self, key_expr, subscription)
        self.network._watchers.append(entry)
        subscription._undeclare = lambda: self.network._forget(entry)
        return subscription

    async def alive(self, key_expr: str, timeout: float = 2.0) -> list[str]:
        return sorted(token.key for token in self.network._tokens_matching(key_expr))
