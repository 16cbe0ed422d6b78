"""A client of the OpenOPC gateway (Pyro5 on port 7766) in front of a KUKA OPC DA server.

The gateway (openopc2's ``gateway_server``, on a Windows machine) registers two
Pyro5 objects: ``OpenOpcGatewayServer`` and the class ``OpcDaClient``, one
instance per connection. A plain Pyro5 proxy of ``PYRO:OpcDaClient@host:port``
is all of openopc2's own client (``OpenOpcGatewayProxy``), so this module speaks
Pyro5 itself and needs no openopc2 (which caps Python below 3.13). On that
proxy we call ``connect(opc_server, opc_host)``, then ``read(items, sync=True)``
(rows of ``(item, value, quality, time)``) and ``write([(item, value), ...])``
(rows of ``(item, "Success" | "Error")``). The gateway sends its
``OPCError`` as ``{"__class__": "exceptions.OPCError", "custom_message": ...}``;
importing this module teaches Pyro5 to read that as a :class:`GatewayError`.

A Pyro5 proxy belongs to the thread that made it, so every proxy call runs on
one dedicated thread (a single-worker executor) and asyncio awaits it. A lost
connection also loses the gateway-side instance and its OPC connection: the
proxy is dropped, and the next call makes a new one and connects again.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import Pyro5.client
import Pyro5.errors
from Pyro5.api import register_dict_to_class

from .errors import KukaConnectionError, KukaError, KukaProtocolError, KukaTimeout, KukaVariableError
from .variables import BY_NAME, from_krl_text, krl_text

__all__ = ["OpcClient", "GatewayError"]

log = logging.getLogger(__name__)
T = TypeVar("T")


class GatewayError(Exception):
    """openopc2's ``OPCError``, raised on the gateway, as it arrives here; :class:`OpcClient` makes it a KukaError."""


def _gateway_error(classname: str, data: dict) -> GatewayError:
    # openopc2's OPCError.dict_to_class reads the same key, with the same fallback.
    return GatewayError(data.get("custom_message", "No message"))


# The name openopc2's OPCError.class_to_dict gives it on the wire, whatever module the gateway runs it from.
register_dict_to_class("exceptions.OPCError", _gateway_error)


class OpcClient:
    """KRL variables as OPC items through an OpenOPC gateway; same interface as ``KvpClient``.

    ``item_prefix`` is put before each KRL name to make the OPC item id.
    Values travel as the OPC server's types (BOOL, INT, REAL) and structures
    as KRL text; :meth:`read` returns KRL text either way.
    """

    def __init__(self, host: str, port: int = 7766, *, opc_server: str, opc_host: str = "localhost",
                 item_prefix: str = "", connect_timeout: float = 3.0, request_timeout: float = 2.0) -> None:
        self.host, self.port = host, port
        self.opc_server, self.opc_host, self.item_prefix = opc_server, opc_host, item_prefix
        self.connect_timeout, self.request_timeout = connect_timeout, request_timeout
        self._executor: ThreadPoolExecutor | None = None
        self._proxy = None  # touched only on the executor's thread

    @property
    def address(self) -> str:
        return f"OPC server {self.opc_server!r} through the OpenOPC gateway at {self.host}:{self.port}"

    async def __aenter__(self) -> "OpcClient":
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def open(self) -> None:
        """Connect to the gateway and through it to the OPC server now (otherwise the first call does).

        Raises
        ------
        KukaConnectionError, KukaTimeout
        """
        await self._call(self._ensure, "connecting")

    async def close(self) -> None:
        """Disconnect from the OPC server and stop the thread; waits at most the request time-out."""
        if self._executor is None:
            return
        try:
            await self._call(self._release, "closing")
        except KukaError as exc:
            log.debug("closing %s: %s", self.address, exc)
        finally:
            self._executor.shutdown(wait=False)
            self._executor = None

    async def read(self, names: Sequence[str]) -> dict[str, str]:
        """The KRL text of each variable, read in one request.

        Raises
        ------
        KukaVariableError
            If an item is unknown or its quality is not Good.
        KukaConnectionError, KukaTimeout, KukaProtocolError
        """
        names = list(names)
        return await self._call(lambda: self._read(names), f"reading {', '.join(names)}")

    async def write(self, values: Sequence[tuple[str, str]]) -> None:
        """Write (name, KRL text) pairs in one request (an OPC server may apply them in any order).

        Raises
        ------
        KukaVariableError
            If a value does not fit its variable's type, or the server refused an item.
        KukaConnectionError, KukaTimeout, KukaProtocolError
        """
        pairs = []
        for name, text in values:
            var = BY_NAME.get(name)
            try:
                pairs.append((self.item_prefix + name, from_krl_text(var.type, text) if var else text))
            except ValueError as exc:
                raise KukaVariableError(f"{name}: {exc}", name=name) from None
        await self._call(lambda: self._write(pairs), f"writing {', '.join(name for name, _ in values)}")

    # --- on the executor's thread -------------------------------------------------------------

    def _ensure(self):
        if self._proxy is None:
            host = f"[{self.host}]" if ":" in self.host else self.host  # an IPv6 address
            proxy = Pyro5.client.Proxy(f"PYRO:OpcDaClient@{host}:{self.port}")
            proxy._pyroTimeout = self.connect_timeout
            try:
                proxy.connect(self.opc_server, self.opc_host)
            except BaseException:
                proxy._pyroRelease()
                raise
            proxy._pyroTimeout = self.request_timeout
            self._proxy = proxy
        return self._proxy

    def _release(self) -> None:
        proxy, self._proxy = self._proxy, None
        if proxy is not None:
            try:
                proxy.close()
            finally:
                proxy._pyroRelease()

    def _read(self, names: list[str]) -> dict[str, str]:
        items = [self.item_prefix + name for name in names]
        rows = self._ensure().read(items, sync=True, timeout=int(self.request_timeout * 1000))
        if not isinstance(rows, (list, tuple)) or len(rows) != len(items):
            raise KukaProtocolError(f"the gateway answered a read of {len(items)} items with {rows!r}")
        values = {}
        for name, item, row in zip(names, items, rows):
            if not isinstance(row, (list, tuple)) or len(row) != 4 or row[0] != item:
                raise KukaProtocolError(f"the gateway answered {row!r} for item {item}")
            _, value, quality, _ = row
            if quality != "Good" or value is None:
                raise KukaVariableError(f"{self.address} could not read {item}: quality {quality}", name=name)
            values[name] = krl_text(value)
        return values

    def _write(self, pairs: list[tuple[str, object]]) -> None:
        rows = self._ensure().write(pairs)
        if not isinstance(rows, (list, tuple)) or len(rows) != len(pairs):
            raise KukaProtocolError(f"the gateway answered a write of {len(pairs)} items with {rows!r}")
        for (item, value), row in zip(pairs, rows):
            if not isinstance(row, (list, tuple)) or len(row) < 2 or row[0] != item:
                raise KukaProtocolError(f"the gateway answered {row!r} for item {item}")
            if row[1] != "Success":
                name = item[len(self.item_prefix):]
                raise KukaVariableError(f"{self.address} refused to write {item} = {value!r}", name=name)

    def _translated(self, function: Callable[[], T], what: str) -> Callable[[], T]:
        """The one place where Pyro5 and gateway errors become KukaErrors (runs on the thread)."""

        def run() -> T:
            try:
                return function()
            except KukaError:
                raise
            except Pyro5.errors.TimeoutError:
                self._drop()
                raise KukaTimeout(f"{what}: no answer from {self.address} within the time-out") from None
            except Pyro5.errors.ProtocolError as exc:
                self._drop()
                raise KukaProtocolError(f"{what}: {self.address}: {exc}") from exc
            except (Pyro5.errors.CommunicationError, OSError) as exc:
                self._drop()
                raise KukaConnectionError(f"{what}: no connection to {self.address}: {exc}") from exc
            except (Pyro5.errors.DaemonError, Pyro5.errors.NamingError, Pyro5.errors.SecurityError) as exc:
                self._drop()
                raise KukaConnectionError(f"{what}: {self.host}:{self.port} is not an OpenOPC gateway "
                                          f"that serves OpcDaClient: {exc}") from exc
            except GatewayError as exc:
                message = str(exc)
                if self._proxy is None:  # failed inside connect(): the OPC server is the problem
                    raise KukaConnectionError(f"{what}: the gateway could not connect to {self.address}: "
                                              f"{message}") from exc
                raise KukaVariableError(f"{what}: {self.address}: {message}") from exc
            except Exception as exc:
                if hasattr(exc, "_pyroTraceback"):  # raised on the gateway, not here
                    raise KukaProtocolError(f"{what}: the gateway failed: {exc!r}") from exc
                raise

        return run

    def _drop(self) -> None:
        proxy, self._proxy = self._proxy, None
        if proxy is not None:
            proxy._pyroRelease()

    # --- on the event loop ----------------------------------------------------------------------

    async def _call(self, function: Callable[[], T], what: str) -> T:
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="kuka-opc")
        future = asyncio.get_running_loop().run_in_executor(self._executor, self._translated(function, what))
        # Pyro5's own time-outs bound the thread; this bound is for the caller, should they not.
        limit = self.connect_timeout + 2 * self.request_timeout + 1.0
        try:
            async with asyncio.timeout(limit):
                return await future
        except TimeoutError:
            raise KukaTimeout(f"{what}: {self.address} did not answer within {limit:g} s") from None
