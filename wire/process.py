"""What every robocell process shares: its Zenoh session, signals, and a clean stop."""

from __future__ import annotations

import asyncio
import logging
import signal
from collections.abc import Awaitable, Callable

from .access import part_refusal
from .config import CellConfig
from .errors import AccessDenied, CellError
from .transport import Transport

__all__ = ["run_until_stopped", "open_transport", "check_part"]

log = logging.getLogger(__name__)
# Short enough that the daemon notices a frozen worker within seconds, long enough
# to survive a busy machine.
WORKER_LEASE_MS = 3000


def check_part(config: CellConfig, role: str, worker_id: str | None = None) -> None:
    """Pass if the router's access control, as ``config``'s ``[zenoh.roles]`` makes it, lets
    this user be the part of ``role`` (and a reconstruction worker serve as ``worker_id``).

    Zenoh drops a denied declaration unseen: the part would wait, unanswered, for jobs that
    never come, and the daemon for a part that never appears. A configuration without roles
    (a client's, a reconstruction machine's) cannot tell: nothing is checked.

    Raises
    ------
    AccessDenied
        One line: which user may not be which part, and who may.
    """
    users = config.zenoh.users_by_role(config.cell_id)
    refusal = part_refusal(users, config.zenoh.user, role, config.cell_id)
    if refusal is not None:
        raise AccessDenied(refusal)
    if users and worker_id is not None and worker_id != config.zenoh.user:
        raise AccessDenied(f"user {config.zenoh.user!r} may serve the reconstruction pool only as worker "
                           f"{config.zenoh.user!r}, not {worker_id!r}: the router's access control would drop "
                           f"what it serves, announces and beats under another id")


async def open_transport(config: CellConfig, *, role: str | None = None, worker_id: str | None = None,
                         lease_ms: int | None = WORKER_LEASE_MS, connect_timeout_s: float = 10.0) -> Transport:
    """A client session to the cell's router, waiting for the router to come up; with ``role``,
    first :func:`check_part`."""
    if role is not None:
        check_part(config, role, worker_id)
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
