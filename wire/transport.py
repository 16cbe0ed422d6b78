"""An asyncio face for one Zenoh session: queries, queryables, publications, liveliness.

:class:`BaseTransport` is what the daemon, the pool and the workers use (after httpx's
``AsyncBaseTransport``); :class:`Transport` is Zenoh's, and ``wire.fake_transport`` an
in-memory one for tests (after httpx's ``MockTransport``).

Zenoh calls back on its own threads; everything here hands those calls over
to the event loop (``call_soon_threadsafe``), so the rest of robocell is plain
asyncio. Zenoh errors are translated into ``wire.errors.TransportError`` here
and nowhere else. An error a handler raises goes back as an ``ErrorReply`` with
its kind, and the querier raises the same class (``wire.errors.from_reply``).
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import json
import re
import logging
from collections.abc import Awaitable, Callable
from typing import Any, cast
from dataclasses import dataclass, field

import zenoh

from .errors import (CellError, CredentialsRefused, LinkDown, NoResponder, TransportError, TransportTimeout, from_reply,
                     wire_kind)
from .messages import ErrorReply

__all__ = ["BaseTransport", "Transport", "Request", "Response", "RequestError", "Reply", "Subscription",
           "session_config", "error_reply", "remote_error"]

log = logging.getLogger(__name__)
JSON = "application/json"
_WILDCARDS = re.compile(r"\*|\$\*")
_RECONNECT = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}
#: How long a query that ended with no reply waits to hear that the link went down meanwhile.
_LINK_GRACE_S = 0.1
# Zenoh answers a query that ran out of time with one error reply carrying this payload.
_ZENOH_TIMEOUT = b"Timeout"
# Zenoh ends an error's text with where in its Rust source it was raised: " at /root/.cargo/.../x.rs:447."
_RUST_SOURCE = re.compile(r"!?\s+at \S+\.rs:\d+\.?\s*$")


def _zenoh_message(exc: zenoh.ZError) -> str:
    """A Zenoh error's text for a person: without the Rust source location it ends with.

    >>> _zenoh_message(zenoh.ZError("Unable to connect to any of [Single(tcp/127.0.0.1:1)]!  at "
    ...                             "/root/.cargo/git/checkouts/zenoh/src/net/runtime/orchestrator.rs:447."))
    'Unable to connect to any of [Single(tcp/127.0.0.1:1)]'
    """
    return _RUST_SOURCE.sub("", str(exc))


def session_config(endpoint: str, *, mode: str = "client", settings: dict | None = None,
                   lease_ms: int | None = None, connect_timeout_ms: int = 0) -> zenoh.Config:
    """A Zenoh configuration: a router listening on ``endpoint``, or a client connecting to it.

    Scouting is off: robocell's processes find each other through the router only.
    ``lease_ms`` shortens how long a frozen process keeps its liveliness tokens.
    ``settings`` adds any Zenoh JSON5 key (TLS, credentials, ...).
    """
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("listen/endpoints" if mode == "router" else "connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    if mode != "router":
        # After an outage, a client tries the router again every second at most (Zenoh's default
        # backs off to 4 s): the cell goes on within a second of the router's return.
        config.insert_json5("connect/retry", json.dumps(_RECONNECT))
        if connect_timeout_ms:
            config.insert_json5("connect/timeout_ms", str(connect_timeout_ms))
    if lease_ms:
        config.insert_json5("transport/link/tx/lease", str(lease_ms))
    for key, value in (settings or {}).items():
        config.insert_json5(key, json.dumps(value))
    return config


@dataclass
class Request:
    """A query as a handler sees it."""

    key: str
    parameters: dict[str, str]
    payload: bytes | None
    attachment: bytes | None


@dataclass
class Response:
    payload: bytes | str
    encoding: str = JSON
    attachment: bytes | str | None = None


@dataclass
class Reply:
    key: str
    payload: bytes
    encoding: str
    attachment: bytes | None = field(default=None, repr=False)


class RequestError(Exception):
    """Raised by a handler: the request is wrong; the message goes back to the caller."""


Handler = Callable[[Request], Awaitable[Response]]


def _bytes(value) -> bytes | None:
    return None if value is None else value.to_bytes()


def _direct(callback: Callable, drop: Callable[[], None] | None = None) -> zenoh.handlers.Callback:
    """``callback`` run on the Zenoh thread that received the data.

    Zenoh's default runs every callback in a Python thread of its own: one more
    thread hop per message, and a thread started per query. Every callback here
    only copies the data and hands it to the event loop, so it cannot hold
    Zenoh's thread up.
    """
    return zenoh.handlers.Callback(callback, drop, indirect=False)


class Subscription:
    """Samples (or liveliness changes) of a key expression, as an async iterator."""

    def __init__(self) -> None:
        self._queue: asyncio.Queue = asyncio.Queue()
        self._undeclare: Callable[[], None] = lambda: None

    def __aiter__(self):
        return self

    async def __anext__(self):
        return await self._queue.get()

    async def get(self, timeout: float | None = None):
        async with asyncio.timeout(timeout):
            return await self._queue.get()

    def close(self) -> None:
        self._undeclare()
        self._undeclare = lambda: None


class BaseTransport(abc.ABC):
    """Queries, queryables, publications and liveliness, used from one asyncio event loop.

    The link to the router: :attr:`link_up`, :meth:`wait_link`, :attr:`link_losses` (how many
    times it went down so far). A query whose link drops before its answer raises
    :class:`~wire.errors.LinkDown`. A handler's error goes back as an ``ErrorReply`` with its
    kind (:func:`error_reply`), and the querier raises the same class (:func:`remote_error`).
    """

    endpoint: str
    link_losses: int
    #: The Zenoh user this session logged in as (None: no user), for errors that name it.
    user: str | None = None

    @property
    @abc.abstractmethod
    def link_up(self) -> bool:
        """Whether the link to the router is up."""

    @abc.abstractmethod
    async def wait_link(self, timeout: float) -> None:
        """Return once the link is up; ``LinkDown`` if it is not within ``timeout`` seconds."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Withdraw everything declared, and end the session."""

    async def __aenter__(self) -> "BaseTransport":
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.close()

    @abc.abstractmethod
    async def query(self, key: str, payload: bytes | str | None = None, *, timeout: float,
                    attachment: bytes | str | None = None, encoding: str = JSON,
                    parameters: str = "") -> Reply:
        """The first successful reply; ``LinkDown``, ``NoResponder``, ``TransportTimeout``, or the
        responder's own error (see :class:`Transport`)."""

    @abc.abstractmethod
    def start_query(self, key: str, payload: bytes | str | None = None, *, timeout: float,
                    attachment: bytes | str | None = None, encoding: str = JSON) -> asyncio.Future[Reply]:
        """:meth:`query`, sent before this returns: the future of its reply."""

    @abc.abstractmethod
    def serve(self, key: str, handler: Handler, *, complete: bool = True, limit: int | None = None) -> None:
        """Answer queries on ``key`` (none with wildcards) with ``handler``, on the event loop; a
        payload longer than ``limit`` bytes is answered with an error (:func:`oversized`) before it
        is copied or reaches the handler."""

    @abc.abstractmethod
    def put(self, key: str, payload: bytes | str, *, encoding: str = JSON,
            attachment: bytes | str | None = None) -> None:
        """Publish ``payload`` on ``key``."""

    @abc.abstractmethod
    def subscribe(self, key: str) -> Subscription:
        """Publications on ``key`` as :class:`Reply` objects."""

    @abc.abstractmethod
    def declare_token(self, key: str) -> Any:
        """Announce this process under ``key`` (the token's ``undeclare()`` withdraws it)."""

    @abc.abstractmethod
    def watch_liveliness(self, key_expr: str) -> Subscription:
        """``(key, alive)`` for every token matching ``key_expr``: those that exist now, then changes."""

    @abc.abstractmethod
    async def alive(self, key_expr: str, timeout: float = 2.0) -> list[str]:
        """Keys of the liveliness tokens matching ``key_expr`` now."""


class Transport(BaseTransport):
    """One Zenoh session, used from one asyncio event loop.

    A client session follows its link to the router: :attr:`link_up`, :meth:`wait_link`, and
    :attr:`link_losses` (how many times the link went down so far). A query whose link drops
    before its answer comes raises :class:`~wire.errors.LinkDown` at once: no query outlives
    its link. Zenoh reconnects by itself; what the caller makes of an outage (wait for the
    link, repeat the query) is its business.
    """

    def __init__(self, session: zenoh.Session, loop: asyncio.AbstractEventLoop, endpoint: str, *,
                 follow_link: bool = False) -> None:
        self._session = session
        self._loop = loop
        self.endpoint = endpoint
        self._declared: list = []
        self._closed = False
        self._routers: set[str] = set()
        self._link = asyncio.Event()
        self._link_lost = asyncio.Event()   # set when the link goes, replaced when it comes back
        self.link_losses = 0
        self._follows_link = follow_link
        if follow_link:
            # Known now, not only when the listener's first events reach the loop.
            self._routers.update(str(zid) for zid in session.info.routers_zid())
            listener = session.info.declare_transport_events_listener(_direct(self._on_transport), history=True)
            self._declared.append(listener)
        if self._routers or not follow_link:
            self._link.set()

    @property
    def link_up(self) -> bool:
        """Whether the session is connected to its router (a router's own session: always)."""
        return self._link.is_set()

    async def wait_link(self, timeout: float) -> None:
        """Return once the link to the router is up.

        Raises
        ------
        LinkDown
            If it is not up within ``timeout`` seconds.
        """
        if self._link.is_set():
            return
        try:
            async with asyncio.timeout(timeout):
                await self._link.wait()
        except TimeoutError:
            raise LinkDown(f"the link to the Zenoh router at {self.endpoint} is down "
                           f"(waited {timeout:g} s for it)") from None

    def _on_transport(self, event: zenoh.TransportEvent) -> None:
        if event.transport.whatami != zenoh.WhatAmI.ROUTER:
            return
        zid, up = str(event.transport.zid), event.kind == zenoh.SampleKind.PUT
        self._loop.call_soon_threadsafe(self._link_changed, zid, up)

    def _link_changed(self, zid: str, up: bool) -> None:
        was_up = bool(self._routers)
        (self._routers.add if up else self._routers.discard)(zid)
        if self._routers and not was_up:
            self._link.set()
            log.info("link to the Zenoh router at %s is up", self.endpoint)
        elif was_up and not self._routers:
            self._link.clear()
            self.link_losses += 1
            self._link_lost.set()
            self._link_lost = asyncio.Event()
            log.warning("link to the Zenoh router at %s is down", self.endpoint)

    @classmethod
    async def open(cls, endpoint: str, *, mode: str = "client", settings: dict | None = None,
                   lease_ms: int | None = None, connect_timeout_s: float = 0.0) -> "Transport":
        """Open a session; a client waits up to ``connect_timeout_s`` for the router.

        Raises
        ------
        CredentialsRefused
            If the router is there but refuses the session: its user name and password (or the
            router's certificate is not one this side trusts). Said at once, not retried.
        TransportError
            If the router cannot be reached (or, for a router, the endpoint cannot be bound).
        """
        if mode == "router":
            config = session_config(endpoint, mode=mode, settings=settings, lease_ms=lease_ms)
            try:
                session = await asyncio.to_thread(zenoh.open, config)
            except zenoh.ZError as exc:
                raise TransportError(f"cannot listen on {endpoint}: {_zenoh_message(exc)}") from exc
            return cls(session, asyncio.get_running_loop(), endpoint)
        session = await _connect(endpoint, mode, settings or {}, lease_ms, connect_timeout_s)
        transport = cls(session, asyncio.get_running_loop(), endpoint, follow_link=mode == "client")
        transport.user = cast(str | None, (settings or {}).get(_USER))
        return transport

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for declared in reversed(self._declared):
            try:
                declared.undeclare()
            except zenoh.ZError:  # already gone with the session
                pass
        await asyncio.to_thread(self._session.close)

    async def __aenter__(self) -> "Transport":
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.close()

    # --- queries ---------------------------------------------------------------------------

    async def query(self, key: str, payload: bytes | str | None = None, *, timeout: float,
                    attachment: bytes | str | None = None, encoding: str = JSON,
                    parameters: str = "") -> Reply:
        """Send a query and return the first successful reply.

        Raises
        ------
        LinkDown
            If the link to the router is down, or goes down before the answer comes.
        NoResponder
            If nobody serves ``key``.
        TransportTimeout
            If no reply came within ``timeout`` seconds.
        CellError
            If the responder answered with an error: the class it raised where this side knows
            it (``MoveRefused``, say), else ``RemoteError``; its message is the error's text.
        """
        sent = self._send(key, payload, timeout=timeout, attachment=attachment, encoding=encoding,
                          parameters=parameters)
        return await self._reply(sent)

    def start_query(self, key: str, payload: bytes | str | None = None, *, timeout: float,
                    attachment: bytes | str | None = None, encoding: str = JSON) -> asyncio.Future[Reply]:
        """:meth:`query`, sent before this returns (a task would send it only when the event loop
        next looks round, behind whatever else is ready): the future of its reply, or of its
        error, :meth:`query`'s errors."""
        try:
            sent = self._send(key, payload, timeout=timeout, attachment=attachment, encoding=encoding)
        except CellError as exc:
            failed: asyncio.Future[Reply] = self._loop.create_future()
            failed.set_exception(exc)
            return failed
        return asyncio.ensure_future(self._reply(sent))

    def _send(self, key: str, payload: bytes | str | None, *, timeout: float, attachment: bytes | str | None,
              encoding: str, parameters: str = "") -> _Sent:
        loop = self._loop
        done: asyncio.Future[None] = loop.create_future()
        replies: list[tuple[bool, Reply]] = []

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                sample = reply.ok
                replies.append((True, Reply(str(sample.key_expr), sample.payload.to_bytes(),
                                            str(sample.encoding), _bytes(sample.attachment))))
            else:
                error = reply.err
                assert error is not None  # a reply is either ok or an error
                replies.append((False, Reply(key, error.payload.to_bytes(), str(error.encoding))))

        def on_finished() -> None:
            loop.call_soon_threadsafe(_settle, done)

        if not self._link.is_set():
            raise LinkDown(f"the link to the Zenoh router at {self.endpoint} is down: nothing sent on {key}")
        selector = f"{key}?{parameters}" if parameters else key
        kwargs: dict[str, Any] = {"timeout": timeout, "encoding": zenoh.Encoding(encoding)}
        if payload is not None:
            kwargs["payload"] = payload
        if attachment is not None:
            kwargs["attachment"] = attachment
        try:
            self._session.get(selector, _direct(on_reply, on_finished), **kwargs)
        except zenoh.ZError as exc:
            raise TransportError(f"query on {key} failed: {_zenoh_message(exc)}") from exc
        # Watched from the moment it is sent: a link lost before the answer comes ends the wait.
        return _Sent(key, timeout, done, replies, asyncio.ensure_future(self._link_lost.wait()))

    async def _reply(self, sent: _Sent) -> Reply:
        key, timeout, done, lost, replies = sent.key, sent.timeout, sent.done, sent.lost, sent.replies
        try:
            # Zenoh finalises every query by its timeout; the margin only guards against a lost signal.
            # Not asyncio.wait_for: on Python 3.11 it swallows a cancel that comes with the answer.
            async with asyncio.timeout(timeout + 5.0):
                await asyncio.wait({done, lost}, return_when=asyncio.FIRST_COMPLETED)
        except asyncio.TimeoutError:
            lost.cancel()
            raise TransportTimeout(f"no answer on {key} within {timeout:g} s") from None
        except BaseException:
            lost.cancel()
            raise
        try:
            if not done.done():  # its answer, should it come, is dropped with the query
                raise LinkDown(f"the link to the Zenoh router at {self.endpoint} went down before the answer "
                               f"on {key}")
            for ok, reply in replies:
                if ok:
                    return reply
            if not replies:
                # Zenoh ends the queries of a link that closes a moment before it says the link is gone.
                await asyncio.wait({lost}, timeout=_LINK_GRACE_S if self._follows_link else 0)
                if lost.done():
                    raise LinkDown(f"the link to the Zenoh router at {self.endpoint} went down before the "
                                   f"answer on {key}")
                raise NoResponder(f"nobody answers on {key}")
        finally:
            lost.cancel()
        error = replies[0][1]
        if error.payload == _ZENOH_TIMEOUT:
            raise TransportTimeout(f"no answer on {key} within {timeout:g} s")
        raise remote_error(error.payload)

    def serve(self, key: str, handler: Handler, *, complete: bool = True, limit: int | None = None) -> None:
        """Answer queries on ``key`` with ``handler``, on the event loop, concurrently; a payload
        past ``limit`` bytes gets an error reply at once, unread (:func:`oversized`).

        Only a query on a key without wildcards is answered (``*``, ``**`` and ``$*`` would
        reach handlers it was not meant for); others are dropped unanswered. A ``RequestError``
        from the handler goes back as an error reply with its message, a
        ``CellError`` with its message, kind and details; any other exception as "internal
        error", and is logged.
        """
        loop = self._loop

        def on_query(query: zenoh.Query) -> None:
            asked = str(query.key_expr)
            if _WILDCARDS.search(asked):
                # A query such as robocell/cell1/** reaches every queryable under it: none of
                # them may act on a request that was not addressed to it.
                query.drop()
                return
            if limit is not None and query.payload is not None \
                    and (refused := oversized(len(query.payload), limit)) is not None:
                try:  # answered here, in Zenoh's thread: the payload is never copied nor parsed
                    query.reply_err(refused.model_dump_json(), encoding=zenoh.Encoding(JSON))
                except zenoh.ZError as exc:
                    log.warning("could not answer on %s: %s", asked, exc)
                finally:
                    query.drop()
                return
            parameters = dict(cast(Any, query.parameters))  # its pairs; the stubs do not say it iterates
            request = Request(asked, parameters, _bytes(query.payload), _bytes(query.attachment))
            try:
                asyncio.run_coroutine_threadsafe(self._answer(query, request, handler), loop)
            except RuntimeError:  # the loop is gone: we are shutting down
                query.drop()

        self._declared.append(self._session.declare_queryable(key, _direct(on_query), complete=complete))

    @staticmethod
    async def _answer(query: zenoh.Query, request: Request, handler: Handler) -> None:
        try:
            try:
                response = await handler(request)
            except Exception as exc:
                error = error_reply(request, exc)
            else:
                kwargs: dict[str, Any] = {"encoding": zenoh.Encoding(response.encoding)}
                if response.attachment is not None:
                    kwargs["attachment"] = response.attachment
                query.reply(query.key_expr, response.payload, **kwargs)
                return
            query.reply_err(error.model_dump_json(), encoding=zenoh.Encoding(JSON))
        except zenoh.ZError as exc:  # the querier went away
            log.warning("could not answer on %s: %s", request.key, exc)
        finally:
            # Until it is dropped, the querier keeps waiting for more replies.
            query.drop()

    # --- publications ----------------------------------------------------------------------

    def put(self, key: str, payload: bytes | str, *, encoding: str = JSON,
            attachment: bytes | str | None = None) -> None:
        kwargs: dict[str, Any] = {"encoding": zenoh.Encoding(encoding)}
        if attachment is not None:
            kwargs["attachment"] = attachment
        try:
            self._session.put(key, payload, **kwargs)
        except zenoh.ZError as exc:
            raise TransportError(f"publishing on {key} failed: {_zenoh_message(exc)}") from exc

    def subscribe(self, key: str) -> Subscription:
        """Publications on ``key`` as :class:`Reply` objects (key, payload, encoding, attachment)."""
        subscription = Subscription()
        queue, loop = subscription._queue, self._loop

        def on_sample(sample: zenoh.Sample) -> None:
            item = Reply(str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding),
                         _bytes(sample.attachment))
            loop.call_soon_threadsafe(queue.put_nowait, item)

        subscriber = self._session.declare_subscriber(key, _direct(on_sample))
        subscription._undeclare = subscriber.undeclare
        return subscription

    # --- liveliness ------------------------------------------------------------------------

    def declare_token(self, key: str):
        """Announce this process under ``key`` for as long as the session lives."""
        token = self._session.liveliness().declare_token(key)
        self._declared.append(token)
        return token

    def watch_liveliness(self, key_expr: str) -> Subscription:
        """``(key, alive)`` for every token matching ``key_expr``: those that exist now, then changes."""
        subscription = Subscription()
        queue, loop = subscription._queue, self._loop

        def on_change(sample: zenoh.Sample) -> None:
            alive = sample.kind == zenoh.SampleKind.PUT
            loop.call_soon_threadsafe(queue.put_nowait, (str(sample.key_expr), alive))

        subscriber = self._session.liveliness().declare_subscriber(key_expr, _direct(on_change), history=True)
        subscription._undeclare = subscriber.undeclare
        return subscription

    async def alive(self, key_expr: str, timeout: float = 2.0) -> list[str]:
        """Keys of the liveliness tokens matching ``key_expr`` now."""
        loop = self._loop
        done = loop.create_future()
        keys: list[str] = []

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                keys.append(str(reply.ok.key_expr))

        def on_finished() -> None:
            loop.call_soon_threadsafe(_settle, done)

        self._session.liveliness().get(key_expr, _direct(on_reply, on_finished), timeout=timeout)
        async with asyncio.timeout(timeout + 5.0):
            await done
        return sorted(keys)


_USER = "transport/auth/usrpwd/user"
_ROOT_CA = "transport/link/tls/root_ca_certificate"
_CLIENT_CERTIFICATE = ("transport/link/tls/connect_certificate", "transport/link/tls/connect_private_key")
#: Between two tries of a router that is not there yet, and how long a probe of its port may take.
_CONNECT_RETRY_S = 0.25
_PROBE_TIMEOUT_S = 1.0
#: Tries in a row that the router answered and refused, before that is its answer: one could
#: have met a router that was only beginning to listen.
_REFUSALS = 2


async def _connect(endpoint: str, mode: str, settings: dict, lease_ms: int | None, timeout_s: float) -> zenoh.Session:
    """A client session to the router at ``endpoint``, trying again until ``timeout_s`` has passed.

    Zenoh tells a session that the router refused (a wrong password, an untrusted certificate)
    only in its log, and then tries again until its time-out, as if the router were not there.
    So each try here is one attempt of Zenoh's; after one that failed, the router's port is
    probed: a router that listens, and still turned the session away twice, refused it, and
    that is said at once, with what it refused (:func:`_refusal`).
    """
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    config = session_config(endpoint, mode=mode, settings=settings, lease_ms=lease_ms)   # one attempt: no time-out
    refusals = 0
    while True:
        try:
            return await asyncio.to_thread(zenoh.open, config)
        except zenoh.ZError as exc:
            error = exc
        refusals = refusals + 1 if await _listening(endpoint) else 0
        if refusals >= _REFUSALS:
            raise await _refusal(endpoint, settings) from error
        if loop.time() >= deadline and refusals == 0:   # a router that listens is asked once more
            raise TransportError(f"cannot reach the Zenoh router at {endpoint}: {_zenoh_message(error)}") from error
        await asyncio.sleep(min(_CONNECT_RETRY_S, max(deadline - loop.time(), 0.0)) if refusals == 0 else 0.05)


def _host_port(endpoint: str) -> tuple[str, str, int] | None:
    """``(protocol, host, port)`` of a ``tcp/`` or ``tls/`` endpoint; None for any other.

    >>> _host_port("tls/[::1]:7447#iface=lo"), _host_port("tcp/cellhost:7447"), _host_port("udp/h:1")
    (('tls', '::1', 7447), ('tcp', 'cellhost', 7447), None)
    """
    protocol, _, address = endpoint.partition("/")
    address = re.split(r"[?#]", address, maxsplit=1)[0]
    host, _, port = address.rpartition(":")
    if protocol not in ("tcp", "tls") or not host or not port.isdigit():
        return None
    return protocol, host.removeprefix("[").removesuffix("]"), int(port)


async def _listening(endpoint: str) -> bool:
    """Whether something takes TCP connections at the endpoint (False for a protocol not probed)."""
    address = _host_port(endpoint)
    if address is None:
        return False
    try:
        async with asyncio.timeout(_PROBE_TIMEOUT_S):
            _, writer = await asyncio.open_connection(address[1], address[2])
    except (OSError, TimeoutError):
        return False
    await _close(writer)
    return True


async def _refusal(endpoint: str, settings: dict) -> CredentialsRefused:
    """What a router that listens at ``endpoint`` refused: the router's certificate, which this side
    does not trust (a TLS handshake tells), or else the session's user name and password."""
    protocol, host, port = cast(tuple[str, str, int], _host_port(endpoint))
    if protocol == "tls":
        untrusted = await _untrusted_certificate(host, port, settings)
        if untrusted is not None:
            return CredentialsRefused(f"the router at {endpoint} was refused: its certificate is not trusted "
                                      f"({untrusted}); {_ROOT_CA} names the CA that signed it")
    user = settings.get(_USER)
    if user is None:
        return CredentialsRefused(f"the router at {endpoint} refused the session: it asks for a user and password "
                                  f"(set [zenoh] user, and ROBOCELL_ZENOH_PASSWORD), or it is no Zenoh router")
    return CredentialsRefused(f"the router refused the credentials: user {user!r} with that password is not in the "
                              f"users' dictionary of the router at {endpoint}")


async def _untrusted_certificate(host: str, port: int, settings: dict) -> str | None:
    """Why the router's TLS certificate fails this side's checks, as Zenoh's own would; None if it
    passes (or the handshake cannot be tried the way Zenoh would make it)."""
    import ssl

    try:
        context = ssl.create_default_context(cafile=cast(str | None, settings.get(_ROOT_CA)))
        # Python 3.13 turns on strict X.509 checks (a CA without an Authority Key Identifier fails
        # them); Zenoh's rustls does not ask for that, so neither does this check of it.
        context.verify_flags &= ~ssl.VERIFY_X509_STRICT
        certificate, key = (settings.get(name) for name in _CLIENT_CERTIFICATE)
        if certificate and key:
            context.load_cert_chain(str(certificate), str(key))
    except (OSError, ssl.SSLError, TypeError):
        return None
    try:
        async with asyncio.timeout(_PROBE_TIMEOUT_S):
            _, writer = await asyncio.open_connection(host, port, ssl=context, server_hostname=host,
                                                      ssl_shutdown_timeout=_PROBE_TIMEOUT_S)
    except ssl.SSLCertVerificationError as exc:
        return exc.verify_message or str(exc)
    except (OSError, TimeoutError):
        return None
    await _close(writer)
    return None


async def _close(writer: asyncio.StreamWriter) -> None:
    """Close a probe's connection and wait until its socket is closed. A TLS connection's socket
    closes only once the router has answered the close: left to a loop that ends first (as
    ``asyncio.run`` does), it stays open until the garbage collector finds it."""
    writer.close()
    with contextlib.suppress(OSError, TimeoutError):   # ssl.SSLError is an OSError
        async with asyncio.timeout(2 * _PROBE_TIMEOUT_S):   # the TLS close's own time-out ends it first
            await writer.wait_closed()


@dataclass
class _Sent:
    """A query on its way: what :meth:`Transport._reply` waits on."""

    key: str
    timeout: float
    done: asyncio.Future[None]          # Zenoh has finalised the query
    replies: list[tuple[bool, Reply]]   # as Zenoh's thread hands them over
    lost: asyncio.Future[Any]           # the link went down


def _settle(done: asyncio.Future[None]) -> None:
    if not done.done():
        done.set_result(None)


def oversized(size: int, limit: int) -> ErrorReply | None:
    """The error reply to a request of ``size`` bytes past ``limit``; None within it."""
    if size <= limit:
        return None
    return ErrorReply(error=f"the request is {size} bytes: at most {limit} are taken")


def error_reply(request: Request, exc: Exception) -> ErrorReply:
    """What a handler's error says to the querier: a ``RequestError``'s message, a ``CellError``'s
    message, kind and details; anything else is an internal error, and is logged."""
    if isinstance(exc, RequestError):
        return ErrorReply(error=str(exc))
    if isinstance(exc, CellError):
        kind, details = wire_kind(exc)
        return ErrorReply(error=str(exc), kind=kind, details=details)
    log.error("handler for %s failed", request.key, exc_info=exc)
    return ErrorReply(error=f"internal error: {type(exc).__name__}: {exc}", kind="InternalError")


def remote_error(payload: bytes) -> CellError:
    try:
        reply = ErrorReply.model_validate_json(payload)
    except ValueError:
        return from_reply(payload.decode("utf-8", errors="replace") or "error without a message", "RemoteError", {})
    return from_reply(reply.error, reply.kind, reply.details)
