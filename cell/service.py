"""The long-running processes of the shell: the Zenoh router and the cell daemon."""

from __future__ import annotations

import asyncio
import logging

from robocell.wire.config import CellConfig
from robocell.wire.process import open_transport, run_until_stopped
from robocell.wire.transport import Transport

__all__ = ["run_router", "run_daemon"]

log = logging.getLogger(__name__)


def run_router(config: CellConfig, endpoint: str | None = None) -> int:
    """A Zenoh router (a session in router mode: Zenoh has no router binary on PyPI)."""
    endpoint = endpoint or config.zenoh.router

    async def run(stop: asyncio.Event) -> None:
        settings = config.zenoh.router_session_settings(config.cell_id)
        router = await Transport.open(endpoint, mode="router", settings=settings)
        log.info("Zenoh router listening on %s", endpoint)
        if "access_control" in settings:
            log.info("access by role: %s", _roles_summary(config))
        elif any(key.startswith("transport/auth/usrpwd") for key in settings):
            log.warning("zenoh.roles is empty: every user the router lets in may do everything")
        try:
            await stop.wait()
        finally:
            await router.close()

    return run_until_stopped(run, "router")


def _roles_summary(config: CellConfig) -> str:
    """``cell1: client alice, bob; daemon cell1`` and so on, one cell after another."""
    return "; ".join(f"{cell}: " + ", ".join(f"{role} {' '.join(names)}" for role, names in roles.items() if names)
                     for cell, roles in config.zenoh.users_by_role(config.cell_id).items())


def run_daemon(config: CellConfig, *, view: str | None = None) -> int:
    """The cell daemon, with its job store in the run directory; ``view``: a Rerun viewer's gRPC URL
    every job is streamed to as it happens."""
    # Here, not at the top: a router needs none of the daemon (its steps, the core it checks answers
    # with), and every cell start waits for the router.
    from .daemon import CellDaemon

    async def run(stop: asyncio.Event) -> None:
        transport = await open_transport(config, role="daemon")
        try:
            await CellDaemon(config, transport, view=view).run(stop)
        finally:
            await transport.close()

    return run_until_stopped(run, "cell daemon")
