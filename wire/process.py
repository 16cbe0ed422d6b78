"""What every robocell process shares: its Zenoh session, signals, and a clean stop."""

from __future__ import annotations

import asyncio
import logging
import signal
from collections.abc import Awaitable, Callable

from .config import CellConfig
from .errors import CellError
from .transport import Transport

__all__ = ["run_until_stopped", "open_transport"]

log = logging.getLogger(__name__)
# Short enough that the daemon notices a frozen worker within seconds, long enough
# to survive a busy machine.
WORKER_LEASE_MS = 3000


async def open_transport(config: CellConfig, *, lease_ms: int | None = WORKER_LEASE_MS,
                         connect_timeout_s: float = 10.0) -> Transport:
    """A client session to the cell's router, waiting for the router to come up."""
    return await Transport.open(config.zenoh.router, settings=config.zenoh.client_settings(), lease_ms=lease_ms,
                                connect_timeout_s=connect_timeout_s)


def run_until_stopped(main: Callable[[asyncio.Event], Awaitable[None]], name: str) -> int:
    """Run ``main(stop)`` until it returns or SIGINT/SIGTERM sets ``stop``; 0 on a clean stop.

    A fatal error is logged and gives exit status 1: it is reported, not swallowed. An error
    robocell expects (a ``CellError``: an unreachable router or robot, a bad setting) is one
    line that says what is wrong; anything else comes with its traceback.
    """

    async def runner() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)
        await main(stop)

    try:
        asyncio.run(runner())
    except CellError as exc:
        log.error("%s stopped: %s", name, exc)
        return 1
    except Exception:
        log.exception("%s stopped on an error", name)
        return 1
    log.info("%s stopped", name)
    return 0
