"""The KUKA bridge's configuration: which protocol, where, how long to wait, how fast to move.

The defaults reach the simulator (``robocell sim kuka``) on this machine; for
a real controller set ``host``, ``protocol`` and, for OPC, ``opc_server``.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["KukaConfig", "DEFAULT_PORTS", "SIM_OPC_SERVER"]

#: KukaVarProxy listens on 7000; the OpenOPC gateway (Pyro5) on 7766.
DEFAULT_PORTS = {"kvp": 7000, "opc": 7766}
#: The OPC server name the simulated gateway answers to.
SIM_OPC_SERVER = "robocell.KukaSim"


class KukaConfig(BaseModel):
    """How the robot worker reaches a KUKA controller and what it lets it do."""

    model_config = ConfigDict(extra="forbid")

    #: ``kvp``: KukaVarProxy on the controller; ``opc``: an OPC DA server behind an OpenOPC gateway.
    protocol: Literal["kvp", "opc"] = "kvp"
    #: The controller (kvp) or the gateway machine (opc).
    host: str = "127.0.0.1"
    #: None: the protocol's usual port (7000 for kvp, 7766 for opc).
    port: Annotated[int, Field(ge=1, le=65535)] | None = None

    #: Connecting, seconds.
    connect_timeout_s: Annotated[float, Field(gt=0, le=60)] = 3.0
    #: One read or write, seconds.
    request_timeout_s: Annotated[float, Field(gt=0, le=60)] = 2.0
    #: How long the KRL program may take to pick up a command before the bridge withdraws it, seconds.
    ack_timeout_s: Annotated[float, Field(gt=0, le=60)] = 2.0
    #: The longest a move may take, seconds.
    move_timeout_s: Annotated[float, Field(gt=0, le=600)] = 60.0
    #: Time between polls of the controller during a move, seconds (also the progress rate).
    poll_period_s: Annotated[float, Field(gt=0, le=5)] = 0.05

    #: Program override used for moves, percent.
    override: Annotated[int, Field(ge=1, le=100)] = 20
    #: The highest override the bridge will ever send, percent; a higher one is refused.
    max_override: Annotated[int, Field(ge=1, le=100)] = 30
    #: Motion type of a move unless the caller asks for another.
    motion: Literal["ptp", "lin"] = "ptp"
    #: How far the reached pose may be from the target before the move counts as failed, mm and degrees.
    reached_tolerance_mm: Annotated[float, Field(gt=0)] = 1.0
    reached_tolerance_deg: Annotated[float, Field(gt=0)] = 0.5

    #: OPC: the OPC DA server's ProgID on the gateway machine (as the gateway's ``servers()`` lists it).
    opc_server: str = SIM_OPC_SERVER
    #: OPC: the host of the OPC DA server, as the gateway sees it.
    opc_host: str = "localhost"
    #: OPC: put before every KRL variable name to make the OPC item id (server-specific, often empty).
    opc_item_prefix: str = ""

    @model_validator(mode="after")
    def _override_within_limit(self) -> "KukaConfig":
        if self.override > self.max_override:
            raise ValueError(f"override {self.override} % is above max_override {self.max_override} %")
        return self

    @property
    def resolved_port(self) -> int:
        return self.port if self.port is not None else DEFAULT_PORTS[self.protocol]
