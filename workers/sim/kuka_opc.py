"""The simulated OpenOPC gateway's Pyro5 objects, as openopc2's ``gateway_server.main`` registers them.

``OpenOpcGatewayServer`` (one object) and ``OpcDaClient`` (a class: one
instance per connection, like the real gateway's). Method names, signatures and
return shapes follow ``openopc2.da_client.OpcDaClient``: a single tag reads as
``(value, quality, time)``, a list as ``[(tag, value, quality, time), ...]``;
unknown tags read as ``(tag, None, "Error", None)`` and write as ``"Error"``.
Errors are :class:`OPCError`, on the wire as the gateway sends openopc2's own.
Nothing here imports openopc2: it caps Python below 3.13, and the wire is all
a client sees.
"""

from __future__ import annotations

import time
import uuid
from typing import TYPE_CHECKING

import Pyro5.callcontext
import Pyro5.server
from Pyro5.api import register_class_to_dict

from robocell.workers.robot.kuka.variables import ALL

if TYPE_CHECKING:
    from .kuka import OpcGateway

__all__ = ["make_daemon", "OPCError"]

_HANG_LIMIT_S = 30.0


class OPCError(Exception):
    """The gateway's error (``openopc2.exceptions.OPCError``): its message is ``custom_message``."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.custom_message = message

    def to_wire(self) -> dict:
        """openopc2 0.1.19's ``OPCError.class_to_dict``: the attributes (Pyro5 adds ``_pyroTraceback``) and a fixed
        class name, whatever module raised it."""
        return {**vars(self), "__class__": "exceptions.OPCError"}


# As the real gateway does, so that its errors reach a client as openopc2's OPCError.
register_class_to_dict(OPCError, OPCError.to_wire)


@Pyro5.server.expose
class SimGatewayServer:
    def __init__(self, gateway: "OpcGateway") -> None:
        self._gateway = gateway
        self.clients: dict[str, float] = {}

    def get_clients(self) -> list[dict]:
        return [{"client_id": client_id, "tx_time": None, "init_time": began}
                for client_id, began in self.clients.items()]


@Pyro5.server.expose
class SimOpcDaClient:
    def __init__(self, gateway: "OpcGateway", server: SimGatewayServer) -> None:
        self._gateway, self._controller = gateway, gateway.controller
        self.client_id = str(uuid.uuid4())
        self.connected = False
        server.clients[self.client_id] = time.time()

    def _serve(self, what: str) -> None:
        """Faults of the gateway itself; and openopc2 fails every call before connect()."""
        if self._controller.take("drop"):
            # The connection drops before the gateway acts on the call, as the KVP simulator's does:
            # the client sees EOF, and no write of the dropped call lands after the client's next one.
            Pyro5.callcontext.current_context.client.close()
            raise OPCError(f"{what}: the connection dropped")
        if "hang" in self._controller.faults:
            self._controller.unhung.wait(_HANG_LIMIT_S)
        if what != "connect" and not self.connected:
            raise OPCError(f"{what}: not connected to an OPC server")

    def _name(self, tag: str) -> str | None:
        prefix = self._gateway.item_prefix
        return tag[len(prefix):] if tag.startswith(prefix) else None

    def connect(self, opc_server: str | None = None, opc_host: str = "localhost") -> None:
        self._serve("connect")
        if opc_server != self._gateway.server_name:
            raise OPCError(f"Connect: Invalid class string ({opc_server})")
        self.connected = True

    def GUID(self) -> str:
        return self.client_id

    def close(self, del_object: bool = True) -> None:
        self.connected = False

    def read(self, tags=None, group=None, size=None, pause=0, source="hybrid", update=-1, timeout=5000,
             sync=False, include_error=False, rebuild=False):
        self._serve("read")
        single = isinstance(tags, str)
        rows = []
        for tag in [tags] if single else list(tags or []):
            name = self._name(tag)
            value = None if name is None else self._controller.read(name)
            quality, stamp = ("Error", None) if value is None else ("Good", time.strftime("%x %H:%M:%S"))
            rows.append((value, quality, stamp) if single else (tag, value, quality, stamp))
        return rows[0] if single else rows

    def write(self, tag_value_pairs, size=None, pause=0, include_error=False):
        self._serve("write")
        single = isinstance(tag_value_pairs[0], str)
        rows = []
        for tag, value in [tag_value_pairs] if single else tag_value_pairs:
            name = self._name(tag)
            status = "Success" if name is not None and self._controller.write(name, value) else "Error"
            rows.append(status if single else (tag, status))
        return rows

    def servers(self, opc_host: str = "localhost") -> list[str]:
        return [self._gateway.server_name]

    def info(self) -> list[tuple[str, str]]:
        return [("Protocol", "gateway"), ("OPC Server", self._gateway.server_name), ("State", "Running"),
                ("Vendor", "robocell simulator")]

    def ping(self) -> bool:
        return self.connected

    def groups(self) -> list[str]:
        return []

    def list(self, paths="*", recursive=False, flat=False, include_type=False, access_rights=None) -> list[str]:
        self._serve("list")
        return [self._gateway.item_prefix + var.name for var in ALL]


def make_daemon(gateway: "OpcGateway", host: str, port: int) -> Pyro5.server.Daemon:
    """A Pyro5 daemon with the gateway's two objects, not yet serving."""
    daemon = Pyro5.server.Daemon(host=host, port=port)
    server = SimGatewayServer(gateway)
    daemon.register(server, objectId="OpenOpcGatewayServer")
    client_class = type("OpcDaClient", (SimOpcDaClient,), {})
    client_class = Pyro5.server.behavior("session", lambda cls: cls(gateway, server))(client_class)
    daemon.register(client_class, objectId="OpcDaClient")
    return daemon
