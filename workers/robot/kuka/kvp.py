"""An asyncio client of KukaVarProxy, the TCP server (port 7000) that reads and writes KRL variables.

Wire format (big-endian; from KukaVarProxy's own source, ``basMain.bas``)::

    request   id:u16  len:u16  fn:u8  name_len:u16 name  [value_len:u16 value]     fn 0 read, 1 write
    response  id:u16  len:u16  fn:u8  value_len:u16 value  status_len:u16 status   status 1 ok, 0 failed

``len`` counts the bytes after itself. A response is read by its inner length
fields, and ``len`` is then checked: some KukaVarProxy builds count it
differently (value length + 3), so both counts are accepted. A read of an
unknown variable comes back "ok" with an empty value: that is an error here.

One request is on the wire at a time. After a time-out or a broken message the
stream's state is unknown, so the connection is dropped and the next request
opens a new one.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
import time
from collections.abc import AsyncIterator, Sequence

from .errors import KukaConnectionError, KukaError, KukaProtocolError, KukaTimeout, KukaVariableError

__all__ = ["KvpClient", "READ", "WRITE", "encode_request", "decode_request", "encode_response"]

log = logging.getLogger(__name__)

READ, WRITE = 0, 1
_U16 = struct.Struct(">H")
_HEADER = struct.Struct(">HH")
_ENCODING = "latin-1"  # KRL text is ASCII; latin-1 maps every byte, so nothing fails to decode
# KukaVarProxy drops a client after 30 s without a request; reconnect before that rather than fail.
_IDLE_RECONNECT_S = 20.0


def _field(text: str) -> bytes:
    data = text.encode(_ENCODING)
    if len(data) > 0xFFFF:
        raise ValueError(f"{len(data)} bytes do not fit a KukaVarProxy length field")
    return _U16.pack(len(data)) + data


def encode_request(msg_id: int, function: int, name: str, value: str | None = None) -> bytes:
    """One KukaVarProxy request: a read (``value`` None) or a write of ``name``.

    Examples
    --------
    >>> encode_request(7, READ, "$OV_PRO")
    b'\\x00\\x07\\x00\\n\\x00\\x00\\x07$OV_PRO'
    """
    body = bytes([function]) + _field(name) + (b"" if value is None else _field(value))
    if len(body) > 0xFFFF:
        raise ValueError("request too long for KukaVarProxy")
    return _HEADER.pack(msg_id, len(body)) + body


def decode_request(body: bytes) -> tuple[int, str, str | None]:
    """(function, name, value or None) of a request's bytes after the header (the simulator's side).

    Raises
    ------
    ValueError
        If the lengths inside do not add up.
    """
    if len(body) < 3:
        raise ValueError("request shorter than its function and name length")
    function, fields, at = body[0], [], 1
    while at < len(body):
        if at + 2 > len(body):
            raise ValueError("request ends inside a length field")
        (size,) = _U16.unpack_from(body, at)
        if at + 2 + size > len(body):
            raise ValueError("request ends inside a field")
        fields.append(body[at + 2: at + 2 + size].decode(_ENCODING))
        at += 2 + size
    if not 1 <= len(fields) <= 2:
        raise ValueError(f"request has {len(fields)} fields, not a name and at most a value")
    return function, fields[0], fields[1] if len(fields) == 2 else None


def encode_response(msg_id: int, function: int, value: str, ok: bool) -> bytes:
    """One KukaVarProxy response, as KukaVarProxy builds it (the simulator's side)."""
    body = bytes([function]) + _field(value) + _U16.pack(1) + bytes([1 if ok else 0])
    return _HEADER.pack(msg_id, len(body)) + body


class KvpClient:
    """A connection to KukaVarProxy: read and write KRL variables as text.

    Connects on first use (or :meth:`open`), and again after a failure.
    Every wait is bounded: ``connect_timeout`` to connect, ``request_timeout``
    for each answer. Use ``async with KvpClient(...) as client``.
    """

    def __init__(self, host: str, port: int = 7000, *, connect_timeout: float = 3.0,
                 request_timeout: float = 2.0) -> None:
        self.host, self.port = host, port
        self.connect_timeout, self.request_timeout = connect_timeout, request_timeout
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._lock = asyncio.Lock()
        self._msg_id = 0
        self._last_used = 0.0

    @property
    def address(self) -> str:
        return f"KukaVarProxy at {self.host}:{self.port}"

    async def __aenter__(self) -> "KvpClient":
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def open(self) -> None:
        """Connect now (otherwise the first request does).

        Raises
        ------
        KukaConnectionError, KukaTimeout
        """
        async with self._lock:
            await self._connect()

    async def close(self) -> None:
        async with self._lock:
            await self._disconnect()

    async def read(self, names: Sequence[str]) -> dict[str, str]:
        """The KRL text of each variable, read one after the other in the order given."""
        return {name: await self.read_var(name) for name in names}

    async def write(self, values: Sequence[tuple[str, str]]) -> None:
        """Write each (name, KRL text) pair, one after the other in the order given."""
        for name, value in values:
            await self.write_var(name, value)

    async def read_var(self, name: str) -> str:
        """The KRL text of one variable.

        Raises
        ------
        KukaVariableError
            If KukaVarProxy reports a failure or returns no value (an unknown variable).
        KukaConnectionError, KukaTimeout, KukaProtocolError
        """
        value, ok = await self._request(READ, name, None)
        if not ok or not value.strip():
            raise KukaVariableError(f"{self.address} could not read {name} (unknown variable?)", name=name)
        return value.strip()

    async def write_var(self, name: str, value: str) -> None:
        """Set one variable to KRL text ``value``.

        Raises
        ------
        KukaVariableError
            If the controller refused the value or the name.
        KukaConnectionError, KukaTimeout, KukaProtocolError
        """
        _, ok = await self._request(WRITE, name, value)
        if not ok:
            raise KukaVariableError(f"{self.address} could not write {name} = {value}", name=name)

    async def ping(self) -> None:
        """Check the connection: KukaVarProxy answers a read of PING with PONG, without the controller."""
        value, ok = await self._request(READ, "PING", None)
        if not ok or value != "PONG":
            raise KukaProtocolError(f"{self.address} answered PING with {value!r}")

    async def _connect(self) -> None:
        if self._writer is not None:
            return
        async with self._translated("connecting", self.connect_timeout):
            self._reader, self._writer = await asyncio.open_connection(self.host, self.port)
        self._last_used = time.monotonic()
        log.debug("connected to %s", self.address)

    async def _disconnect(self) -> None:
        writer, self._reader, self._writer = self._writer, None, None
        if writer is not None:
            writer.close()
            with contextlib.suppress(OSError, TimeoutError):
                async with asyncio.timeout(1.0):
                    await writer.wait_closed()

    async def _request(self, function: int, name: str, value: str | None) -> tuple[str, bool]:
        what = f"{'reading' if function == READ else 'writing'} {name}"
        async with self._lock:
            self._msg_id = (self._msg_id + 1) % 0x10000
            msg_id = self._msg_id
            try:
                request = encode_request(msg_id, function, name, value)
            except ValueError as exc:
                raise KukaVariableError(f"{what}: {exc}", name=name) from None
            if self._writer is not None and time.monotonic() - self._last_used > _IDLE_RECONNECT_S:
                await self._disconnect()
            await self._connect()
            async with self._translated(what, self.request_timeout):
                assert self._writer is not None and self._reader is not None
                self._writer.write(request)
                await self._writer.drain()
                answer = await self._read_response(self._reader)
            self._last_used = time.monotonic()
        answer_id, answer_function, text, ok = answer
        if answer_id != msg_id or answer_function != function:
            await self.close()
            raise KukaProtocolError(f"{self.address} answered message {answer_id} (function {answer_function}) "
                                    f"to message {msg_id} (function {function}), {what}")
        return text, ok

    @staticmethod
    async def _read_response(reader: asyncio.StreamReader) -> tuple[int, int, str, bool]:
        msg_id, length = _HEADER.unpack(await reader.readexactly(_HEADER.size))
        function = (await reader.readexactly(1))[0]
        (value_length,) = _U16.unpack(await reader.readexactly(2))
        value = (await reader.readexactly(value_length)).decode(_ENCODING)
        (status_length,) = _U16.unpack(await reader.readexactly(2))
        status = await reader.readexactly(status_length)
        if length not in (5 + value_length + status_length, value_length + 3) or not status:
            raise KukaProtocolError(f"response length {length} does not match its fields "
                                    f"(value {value_length} bytes, status {status_length} bytes)")
        return msg_id, function, value, status[-1] == 1

    @contextlib.asynccontextmanager
    async def _translated(self, what: str, timeout: float) -> AsyncIterator[None]:
        """The one place where socket errors become KukaErrors; the connection is dropped on any."""
        try:
            async with asyncio.timeout(timeout):
                yield
        except KukaError:
            await self._disconnect()
            raise
        except TimeoutError:
            await self._disconnect()
            raise KukaTimeout(f"{what}: no answer from {self.address} within {timeout:g} s") from None
        except asyncio.IncompleteReadError as exc:
            await self._disconnect()
            raise KukaConnectionError(f"{what}: {self.address} closed the connection") from exc
        except OSError as exc:
            await self._disconnect()
            raise KukaConnectionError(f"{what}: no connection to {self.address}: {exc}") from exc
